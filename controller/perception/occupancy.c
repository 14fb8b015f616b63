/* The detector's occupancy grid (detection._occupancy): the n x n grid (255 where a point
 * falls) and, per occupied cell in row-major order, the centroid of its points, summed in
 * the points' order as numpy's bincount sums them, so the two agree bit for bit. `lookup`
 * (n * n) is scratch; only its occupied cells' entries are written and read. Points outside
 * the grid are left out. Returns the number of occupied cells. */
#include <math.h>
#include <stdint.h>
#include <string.h>

int64_t occupancy(int64_t m, const double *x, const double *y, int64_t n, double range,
                  double inv_cell, uint8_t *grid, int64_t *flat, int64_t *lookup,
                  double *sx, double *sy, double *count)
{
    memset(grid, 0, (size_t)(n * n));
    int64_t k = 0;
    for (int64_t p = 0; p < m; p++) {
        int64_t i = (int64_t)floor((x[p] + range) * inv_cell);
        int64_t j = (int64_t)floor((y[p] + range) * inv_cell);
        if (i < 0 || i >= n || j < 0 || j >= n) {
            flat[p] = -1;
            continue;
        }
        flat[p] = i * n + j;
        grid[i * n + j] = 255;
    }
    /* The occupied cells in row-major order, eight cells at a time: most are empty. */
    int64_t total = n * n, c = 0;
    for (; c + 8 <= total; c += 8) {
        uint64_t word;
        memcpy(&word, grid + c, sizeof word);
        if (!word)
            continue;
        for (int64_t q = c; q < c + 8; q++)
            if (grid[q])
                lookup[q] = k++;
    }
    for (; c < total; c++)
        if (grid[c])
            lookup[c] = k++;
    for (int64_t c = 0; c < k; c++)
        sx[c] = sy[c] = count[c] = 0.0;
    for (int64_t p = 0; p < m; p++) {
        if (flat[p] < 0)
            continue;
        int64_t c = lookup[flat[p]];
        sx[c] += x[p];
        sy[c] += y[p];
        count[c] += 1.0;
    }
    for (int64_t c = 0; c < k; c++) {
        sx[c] /= count[c];
        sy[c] /= count[c];
    }
    return k;
}

/* The value of an n x n grid (rows along x, columns along y, cells 1 / inv_cell wide, the
 * grid's corner at (-range, -range)) at the cell of each of m points (x, y rows of xy),
 * cells clipped into the grid: the tracker's lookup of where walls were drawn
 * (clusters._on_walls), as its numpy twin computes it. */
void grid_at(int64_t m, const double *xy, int64_t n, double range, double inv_cell,
             const uint8_t *grid, uint8_t *out)
{
    double top = (double)(n - 1);
    for (int64_t p = 0; p < m; p++) {
        double i = floor((xy[2 * p] + range) * inv_cell);
        double j = floor((xy[2 * p + 1] + range) * inv_cell);
        i = i < 0.0 ? 0.0 : (i > top ? top : i);
        j = j < 0.0 ? 0.0 : (j > top ? top : j);
        out[p] = grid[(int64_t)i * n + (int64_t)j];
    }
}
