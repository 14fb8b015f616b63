/* The detector's crop of a body-frame cloud (detection._crop), in one pass: the points in
 * the height band (z down: -max_h <= z <= -min_h), within `range` of the boat in x and y,
 * outside the own hull's box and the wake's box behind it. The cloud is read through its
 * strides (in elements), so row- and column-major clouds need no copy; the thresholds are
 * compared in the cloud's own precision, as numpy compares them. Returns how many points
 * are kept. */
#include <stdint.h>

/* Whether a point is kept: in the band, within range, outside the hull's and the wake's
 * boxes (the thresholds as the macros below declare them). */
#define KEEP(x, y, z, ay)                                                                   \
    ((z) <= hi && (z) >= lo && (x) >= nr && (x) <= r && (ay) <= r                           \
     && !((x) >= x0 && (x) <= x1 && (ay) <= hw) && !((x) >= wx0 && (x) < x0 && (ay) <= ww))

#define THRESHOLDS(T)                                                                       \
    T lo = (T)(-max_h_d), hi = (T)(-min_h_d), r = (T)range_d, nr = (T)(-range_d);           \
    T x0 = (T)x0_d, x1 = (T)x1_d, hw = (T)hull_w_d, wx0 = (T)wake_x0_d, ww = (T)wake_w_d;

#define CROP(NAME, T)                                                                       \
    int64_t NAME(int64_t n, const T *p, int64_t row, int64_t col, double min_h_d,          \
                 double max_h_d, double range_d, double x0_d, double x1_d, double hull_w_d, \
                 double wake_x0_d, double wake_w_d, int64_t *idx, T *xo, T *yo, T *rows)   \
    {                                                                                       \
        THRESHOLDS(T)                                                                       \
        int64_t m = 0;                                                                      \
        for (int64_t i = 0; i < n; i++) {                                                   \
            T x = p[i * row], y = p[i * row + col], z = p[i * row + 2 * col];               \
            T ay = y < 0 ? -y : y;                                                          \
            if (!KEEP(x, y, z, ay))                                                         \
                continue;                                                                   \
            if (idx) {                                                                      \
                idx[m] = i;                                                                 \
                xo[m] = x;                                                                  \
                yo[m] = y;                                                                  \
            }                                                                               \
            if (rows) {                                                                     \
                rows[3 * m] = x;                                                            \
                rows[3 * m + 1] = y;                                                        \
                rows[3 * m + 2] = z;                                                        \
            }                                                                               \
            m++;                                                                            \
        }                                                                                   \
        return m;                                                                           \
    }

/* Writes, of the kept points, the indices (ascending), x and y when `idx` is given, and the
 * rows x, y, z (m x 3: what `cloud[idx]` gives, without the gather through a column-major
 * view) when `rows` is; either may be NULL. */
CROP(crop_f32, float)
CROP(crop_f64, double)

/* The tracker's split of its crop (n points x, y, z, strides in elements): the occluders
 * (x, y of every point not in the own hull's box when `hull_box`, in the cloud's precision),
 * which of them lie in the detection band (band_xy, float64), and the hull's own returns
 * (hull: x, y, height up, float64). counts: occluders, band points, hull points. */
#define SPLIT(NAME, T)                                                                      \
    void NAME(int64_t n, const T *p, int64_t row, int64_t col, double min_h_d,             \
              double max_h_d, int hull_box, double x0_d, double x1_d, double hull_w_d,      \
              T *occluders, double *band_xy, double *hull, int64_t *counts)                \
    {                                                                                       \
        T lo = (T)(-max_h_d), hi = (T)(-min_h_d);                                           \
        T x0 = (T)x0_d, x1 = (T)x1_d, hw = (T)hull_w_d;                                     \
        int64_t n_occ = 0, n_band = 0, n_hull = 0;                                          \
        for (int64_t i = 0; i < n; i++) {                                                   \
            T x = p[i * row], y = p[i * row + col], z = p[i * row + 2 * col];               \
            T ay = y < 0 ? -y : y;                                                          \
            if (hull_box && x >= x0 && x <= x1 && ay <= hw) {                               \
                hull[3 * n_hull] = x;                                                       \
                hull[3 * n_hull + 1] = y;                                                   \
                hull[3 * n_hull + 2] = -z;                                                  \
                n_hull++;                                                                   \
                continue;                                                                   \
            }                                                                               \
            occluders[2 * n_occ] = x;                                                       \
            occluders[2 * n_occ + 1] = y;                                                   \
            n_occ++;                                                                        \
            if (z <= hi && z >= lo) {                                                       \
                band_xy[2 * n_band] = x;                                                    \
                band_xy[2 * n_band + 1] = y;                                                \
                n_band++;                                                                   \
            }                                                                               \
        }                                                                                   \
        counts[0] = n_occ;                                                                  \
        counts[1] = n_band;                                                                 \
        counts[2] = n_hull;                                                                 \
    }

SPLIT(split_f32, float)
SPLIT(split_f64, double)
