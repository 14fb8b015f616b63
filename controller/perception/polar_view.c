/* The polar images `clusters.free_space` reads, per viewpoint (a LiDAR on the boat): the
 * squared range of the nearest return in each bearing bin, and the steepest rise of the own
 * hull's returns. Two passes around numpy's float32 arctan2 (so the bins are numpy's, bit for
 * bit, whichever SIMD arctan2 this machine's numpy uses):
 *   polar_offsets_*: each point's offset from each viewpoint as float32 (the arctan2's input)
 *                    and the value kept per bin (squared range, or rise over range);
 *   polar_scatter:   bin of each arctan2 and the least (or, negated, the greatest) value per
 *                    bin, as np.minimum.at / np.maximum.at do (a NaN stays).
 * The numpy twins are `polar_view.nearest_numpy` and `polar_view.hull_slope_numpy`. */
#include <math.h>
#include <stdint.h>

/* Returns (N, 2) of type T with strides rs, cs (in elements) seen from V viewpoints (vx, vy):
 * fx, fy (V * N) the float32 offsets; r2 (V * N) the squared range. A viewpoint at the origin
 * (flag at_origin[v]) takes the points as they are, its squared range in T's precision (numpy
 * squares the cloud's own dtype there); elsewhere the offsets and squares are double. */
#define OFFSETS(NAME, T)                                                                      \
    void NAME(int64_t n, const T *p, int64_t rs, int64_t cs, int64_t nv, const double *vx,   \
              const double *vy, const uint8_t *at_origin, float *fx, float *fy, double *r2) \
    {                                                                                         \
        for (int64_t v = 0; v < nv; v++) {                                                    \
            float *ox = fx + v * n, *oy = fy + v * n;                                         \
            double *orr = r2 + v * n;                                                         \
            for (int64_t i = 0; i < n; i++) {                                                 \
                T x = p[i * rs], y = p[i * rs + cs];                                          \
                if (at_origin[v]) {                                                           \
                    T s = x * x + y * y;                                                      \
                    ox[i] = (float)x;                                                         \
                    oy[i] = (float)y;                                                         \
                    orr[i] = (double)s;                                                       \
                } else {                                                                      \
                    double dx = (double)x - vx[v], dy = (double)y - vy[v];                    \
                    ox[i] = (float)dx;                                                        \
                    oy[i] = (float)dy;                                                        \
                    orr[i] = dx * dx + dy * dy;                                               \
                }                                                                             \
            }                                                                                 \
        }                                                                                     \
    }

OFFSETS(polar_offsets_f32, float)
OFFSETS(polar_offsets_f64, double)

/* The own hull's returns h (H, 3: x, y, height up; double, contiguous) seen from V
 * viewpoints (vx, vy): their float32 offsets, the arctan2's input. */
void polar_hull_offsets(int64_t n, const double *h, int64_t nv, const double *vx,
                        const double *vy, float *fx, float *fy)
{
    for (int64_t v = 0; v < nv; v++)
        for (int64_t i = 0; i < n; i++) {
            fx[v * n + i] = (float)(h[3 * i] - vx[v]);
            fy[v * n + i] = (float)(h[3 * i + 1] - vy[v]);
        }
}

static inline int64_t bin_of(float angle, float scale, float half, int64_t bins)
{
    float a = angle * scale;
    a += half;
    int64_t b = (int64_t)a;
    return b > bins - 1 ? bins - 1 : b;
}

/* Bins (int16) of m float32 bearings; -1 for a NaN (no bearing). */
void polar_bins(int64_t m, const float *angle, float scale, float half, int64_t bins,
                int16_t *out)
{
    for (int64_t i = 0; i < m; i++)
        out[i] = isnan(angle[i]) ? -1 : (int16_t)bin_of(angle[i], scale, half, bins);
}

/* The steepest rise (h_z - vz) / hypot(offset) of the hull's returns (bins of each: hbin)
 * seen from one viewpoint in each of q asked bins (-inf: none); a return within 1 mm of the
 * viewpoint's axis has none. Only the returns in an asked bin are measured. */
void polar_hull_slope_at(int64_t n, const double *h, const int16_t *hbin, double vx,
                         double vy, double vz, int64_t q, const int64_t *asked, int64_t bins,
                         double *out)
{
    int32_t slot[4096];
    if (bins > 4096)
        return;
    for (int64_t b = 0; b < bins; b++)
        slot[b] = -1;
    for (int64_t j = 0; j < q; j++) {
        out[j] = -INFINITY;
        if (asked[j] >= 0 && asked[j] < bins && slot[asked[j]] < 0)
            slot[asked[j]] = (int32_t)j;
    }
    for (int64_t i = 0; i < n; i++) {
        int16_t b = hbin[i];
        if (b < 0 || slot[b] < 0)
            continue;
        double dx = h[3 * i] - vx, dy = h[3 * i + 1] - vy;
        double r = hypot(dx, dy);
        if (!(r > 1e-3))
            continue;
        double x = (h[3 * i + 2] - vz) / r, *best = out + slot[b];
        if (!isnan(*best) && !(*best >= x))
            *best = x;
    }
    for (int64_t j = 0; j < q; j++)
        if (asked[j] >= 0 && asked[j] < bins)
            out[j] = out[slot[asked[j]]];
}

/* Bins of V rows of N float32 bearings (numpy's arctan2, radians), as
 * min(int(a * (bins / 2 pi) + bins / 2), bins - 1) in float32 (`bin_of`), and per bin the
 * least value of each row: img (V, bins) holds the start values on entry. */
void polar_scatter(int64_t nv, int64_t n, const float *angle, const double *value,
                   int64_t bins, float scale, float half, double *img)
{
    /* A scan's returns come in bearing order, so most follow one in the same bin: the
     * least is kept in a register along a run and stored when the bin changes. */
    for (int64_t v = 0; v < nv; v++) {
        double *row = img + v * bins, best = 0.0;
        int64_t cur = -1;
        for (int64_t i = 0; i < n; i++) {
            int64_t k = v * n + i;
            if (isnan(angle[k]))
                continue; /* (no bearing: an unclean point; numpy would refuse it) */
            int64_t b = bin_of(angle[k], scale, half, bins);
            if (b != cur) {
                if (cur >= 0)
                    row[cur] = best;
                cur = b;
                best = row[b];
            }
            double x = value[k];
            if (!isnan(best) && !(best <= x))
                best = x;
        }
        if (cur >= 0)
            row[cur] = best;
    }
}
