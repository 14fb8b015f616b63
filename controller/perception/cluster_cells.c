/* The tracker's clustering grid (clusters.find_clusters), per point: C because each pass is
 * a dozen numpy calls over every point of every scan (see controller/kernels). Both passes
 * do integer work on the same floor((x + r) * inv_cell) cells as their numpy twins in
 * clusters.py, so the two agree exactly. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* The points (m, 2 row-major) in the n x n grid of cells inv_cell^-1 wide with its corner at
 * (-r, -r), less lone returns: those with fewer than two points (themselves included) in
 * the 3 x 3 cells around their own, and, when `walls` is given, less the points on it (a
 * wall_n x wall_n grid of cells wall_inv_cell^-1 wide, corner at (-r, -r), each point's
 * cell clipped into it: clusters.grid_at). Writes the kept points, in order, to xy_out with
 * their cells (i, j), and grid (n * n) 1 at their cells, 0 elsewhere. Returns how many are
 * kept, or -1 when out of memory. */
int64_t sociable_points(int64_t m, const double *xy, double r, double inv_cell, int64_t n,
                        const uint8_t *walls, int64_t wall_n, double wall_inv_cell,
                        double *xy_out, int64_t *i_out, int64_t *j_out, uint8_t *grid)
{
    double wall_top = (double)(wall_n - 1);
    int32_t *count = calloc((size_t)(n * n), sizeof(int32_t));
    if (!count && n > 0)
        return -1;
    memset(grid, 0, (size_t)(n * n));
    int64_t k = 0;
    for (int64_t p = 0; p < m; p++) {
        if (walls) {
            double wi = floor((xy[2 * p] + r) * wall_inv_cell);
            double wj = floor((xy[2 * p + 1] + r) * wall_inv_cell);
            wi = wi < 0.0 ? 0.0 : (wi > wall_top ? wall_top : wi);
            wj = wj < 0.0 ? 0.0 : (wj > wall_top ? wall_top : wj);
            if (walls[(int64_t)wi * wall_n + (int64_t)wj])
                continue;
        }
        double fi = floor((xy[2 * p] + r) * inv_cell), fj = floor((xy[2 * p + 1] + r) * inv_cell);
        if (!(fi >= 0.0 && fi < (double)n && fj >= 0.0 && fj < (double)n))
            continue; /* (NaN too) */
        int64_t i = (int64_t)fi, j = (int64_t)fj;
        count[i * n + j]++;
        xy_out[2 * k] = xy[2 * p];
        xy_out[2 * k + 1] = xy[2 * p + 1];
        i_out[k] = i;
        j_out[k] = j;
        k++;
    }
    int64_t kept = 0;
    for (int64_t p = 0; p < k; p++) {
        int64_t i = i_out[p], j = j_out[p], company = 0;
        for (int64_t a = i > 0 ? i - 1 : 0; a <= i + 1 && a < n; a++)
            for (int64_t b = j > 0 ? j - 1 : 0; b <= j + 1 && b < n; b++)
                company += count[a * n + b];
        if (company < 2)
            continue;
        xy_out[2 * kept] = xy_out[2 * p];
        xy_out[2 * kept + 1] = xy_out[2 * p + 1];
        i_out[kept] = i;
        j_out[kept] = j;
        grid[i * n + j] = 1;
        kept++;
    }
    free(count);
    return kept;
}

/* The members of each component: label[p] = labels[i[p] * n + j[p]] (through root when
 * given), count[l] the points of label l (count[0] = 0: the background), and order the
 * points whose label has at least min_points, grouped by label in ascending order, each
 * group in the points' order; start[l] where label l's group begins. Returns how many
 * points are in order, or -1 when out of memory. */
int64_t cluster_members(int64_t m, const int64_t *i, const int64_t *j, const int32_t *labels,
                        int64_t n, const int64_t *root, int64_t n_labels, int64_t min_points,
                        int64_t *count, int64_t *start, int64_t *order)
{
    int64_t *label = malloc(sizeof(int64_t) * (size_t)(m > 0 ? m : 1));
    if (!label)
        return -1;
    for (int64_t l = 0; l < n_labels; l++)
        count[l] = 0;
    for (int64_t p = 0; p < m; p++) {
        int64_t l = labels[i[p] * n + j[p]];
        if (root)
            l = root[l];
        label[p] = l;
        count[l]++;
    }
    if (n_labels > 0)
        count[0] = 0;
    int64_t total = 0;
    for (int64_t l = 0; l < n_labels; l++) {
        start[l] = total;
        if (count[l] >= min_points)
            total += count[l];
    }
    int64_t *at = malloc(sizeof(int64_t) * (size_t)(n_labels > 0 ? n_labels : 1));
    if (!at) {
        free(label);
        return -1;
    }
    memcpy(at, start, sizeof(int64_t) * (size_t)n_labels);
    for (int64_t p = 0; p < m; p++) {
        int64_t l = label[p];
        if (count[l] >= min_points)
            order[at[l]++] = p;
    }
    free(at);
    free(label);
    return total;
}
