/* What `clusters.free_space` reads of a scan, per viewpoint (a LiDAR on the boat): the
 * squared range of the nearest return in a bearing bin, and the steepest rise of the own
 * hull's returns there, for the few bins it asks about. Around numpy's float32 arctan2, so the
 * bins are numpy's bit for bit (whichever SIMD arctan2 this machine's numpy uses):
 *   polar_offsets_*, polar_hull_offsets: each point's offset from each viewpoint as float32
 *                    (the arctan2's input);
 *   polar_bins:      the bin of each arctan2;
 *   polar_nearest_at_*, polar_hull_slope_at: the least squared range, the greatest rise, of
 *                    the points in each bin asked, as np.minimum.at / np.maximum.at over all
 *                    of them would leave it (a NaN stays).
 * The numpy twins are `polar_view.nearest_numpy` and `polar_view.hull_slope_numpy`. */
#include <math.h>
#include <stdint.h>

/* Points (N, 2) of type T with strides rs, cs (in elements) seen from V viewpoints (vx, vy):
 * fx, fy (V * N) their float32 offsets (numpy: the offset in double, then to float32; from
 * the origin that is the point itself). */
#define OFFSETS(NAME, T)                                                                      \
    void NAME(int64_t n, const T *p, int64_t rs, int64_t cs, int64_t nv, const double *vx,   \
              const double *vy, float *fx, float *fy)                                        \
    {                                                                                         \
        for (int64_t v = 0; v < nv; v++)                                                      \
            for (int64_t i = 0; i < n; i++) {                                                 \
                fx[v * n + i] = (float)((double)p[i * rs] - vx[v]);                           \
                fy[v * n + i] = (float)((double)p[i * rs + cs] - vy[v]);                      \
            }                                                                                 \
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

/* The least squared range of the returns (as polar_offsets_* measure it, from one viewpoint)
 * in each of q asked bins (inf: none), given every return's bin (pbin, -1: none). */
#define NEAREST_AT(NAME, T)                                                                   \
    void NAME(int64_t n, const T *p, int64_t rs, int64_t cs, const int16_t *pbin, double vx,  \
              double vy, int at_origin, int64_t q, const int64_t *asked, int64_t bins,        \
              double *out)                                                                    \
    {                                                                                         \
        int32_t slot[4096];                                                                   \
        if (bins > 4096)                                                                      \
            return;                                                                           \
        for (int64_t b = 0; b < bins; b++)                                                    \
            slot[b] = -1;                                                                     \
        for (int64_t j = 0; j < q; j++) {                                                     \
            out[j] = INFINITY;                                                                \
            if (asked[j] >= 0 && asked[j] < bins && slot[asked[j]] < 0)                       \
                slot[asked[j]] = (int32_t)j;                                                  \
        }                                                                                     \
        for (int64_t i = 0; i < n; i++) {                                                     \
            int16_t b = pbin[i];                                                              \
            if (b < 0 || slot[b] < 0)                                                         \
                continue;                                                                     \
            T x = p[i * rs], y = p[i * rs + cs];                                              \
            double r2;                                                                        \
            if (at_origin) {                                                                  \
                T s = x * x + y * y;                                                          \
                r2 = (double)s;                                                               \
            } else {                                                                          \
                double dx = (double)x - vx, dy = (double)y - vy;                              \
                r2 = dx * dx + dy * dy;                                                       \
            }                                                                                 \
            double *best = out + slot[b];                                                     \
            if (!isnan(*best) && !(*best <= r2))                                              \
                *best = r2;                                                                   \
        }                                                                                     \
        for (int64_t j = 0; j < q; j++)                                                       \
            if (asked[j] >= 0 && asked[j] < bins)                                             \
                out[j] = out[slot[asked[j]]];                                                 \
    }

NEAREST_AT(polar_nearest_at_f32, float)
NEAREST_AT(polar_nearest_at_f64, double)
