/* The tracker's confident walls (clusters.chained_walls): segments longer than any vessel
 * alone or as a chain of pieces whose ends meet closely at a small angle. C because the
 * numpy version is two dozen calls on a handful of segments, every scan (see
 * controller/kernels); the same arithmetic as the twin (its cos and sin given, numpy's), and
 * a union-find giving the same chains, whose lengths are summed in the segments' order. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

static double py_mod(double x, double m) /* numpy's float remainder */
{
    double r = fmod(x, m);
    if (r != 0.0) {
        if ((m < 0) != (r < 0))
            r += m;
    } else {
        r = copysign(0.0, m);
    }
    return r;
}

static int64_t root_of(int64_t *chain, int64_t k)
{
    while (chain[k] != k) {
        chain[k] = chain[chain[k]];
        k = chain[k];
    }
    return k;
}

/* m segments (rows x_c, y_c, theta, length), cos and sin of theta. wall[k] = 1 where segment
 * k, or the chain it is in, is longer than max_len: pieces are chained where an end of one
 * lies within gap2 (squared) of an end of the other and their lines differ by at most
 * max_angle (rad, either way round). Returns 0, or -1 when out of memory. */
int chained_walls(int64_t m, const double *s, const double *cs, const double *sn, double gap2,
                  double max_angle, double max_len, uint8_t *wall)
{
    const double pi = 3.141592653589793, half_pi = 1.5707963267948966;
    double *ends = malloc(sizeof(double) * (size_t)(4 * m + 1));
    int64_t *chain = malloc(sizeof(int64_t) * (size_t)(m + 1));
    double *total = malloc(sizeof(double) * (size_t)(m + 1));
    if (!ends || !chain || !total) {
        free(ends);
        free(chain);
        free(total);
        return -1;
    }
    for (int64_t k = 0; k < m; k++) {
        double h = 0.5 * s[4 * k + 3], hx = h * cs[k], hy = h * sn[k];
        ends[2 * k] = s[4 * k] - hx;
        ends[2 * k + 1] = s[4 * k + 1] - hy;
        ends[2 * (m + k)] = s[4 * k] + hx;
        ends[2 * (m + k) + 1] = s[4 * k + 1] + hy;
        chain[k] = k;
        total[k] = 0.0;
    }
    for (int64_t i = 0; i < 2 * m; i++) {
        int64_t a = i % m;
        for (int64_t j = 0; j < 2 * m; j++) {
            int64_t b = j % m;
            if (a >= b)
                continue;
            double dx = ends[2 * i] - ends[2 * j], dy = ends[2 * i + 1] - ends[2 * j + 1];
            if (!(dx * dx + dy * dy <= gap2))
                continue;
            double ang = fabs(py_mod(s[4 * a + 2] - s[4 * b + 2] + half_pi, pi) - half_pi);
            if (ang <= max_angle) {
                int64_t ra = root_of(chain, a), rb = root_of(chain, b);
                chain[ra] = rb;
            }
        }
    }
    for (int64_t k = 0; k < m; k++)
        total[root_of(chain, k)] += s[4 * k + 3];
    for (int64_t k = 0; k < m; k++)
        wall[k] = s[4 * k + 3] > max_len || total[root_of(chain, k)] > max_len;
    free(ends);
    free(chain);
    free(total);
    return 0;
}
