/* First hits against the height profile of every azimuth column: the compiled twin of
 * LidarSimulator._profile in lidar.py (whose docstring explains the method). Per column,
 * the crossings sorted by distance cut the ray into segments; the highest solid present on
 * each gives the profile; beams, sorted by tan(elevation) within a column, then fall into
 * runs (face of segment i, top of segment i, ..., sky) by the same float32 thresholds as the
 * numpy version, so the two agree bit for bit. Beside it, the scan's other per-beam and
 * per-crossing passes (the 2-D cast, the crossings' order by column, the returns), each the
 * twin of a numpy method there; C because each replaces a few dozen numpy calls per scan
 * (see controller/kernels). Only arctan2 stays with numpy, whose SIMD version rounds
 * differently from libm's. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#define SOLID_BITS 24
#define LAND 0
#define BACK 1
#define STANDING 2
#define WATER_KIND 4

static void sort_keys(int64_t *k, int64_t n)
{
    for (int64_t i = 1; i < n; i++) { /* insertion sort: columns hold few crossings */
        int64_t v = k[i], j = i - 1;
        while (j >= 0 && k[j] > v) {
            k[j + 1] = k[j];
            j--;
        }
        k[j + 1] = v;
    }
}

static int cmp_keys(const void *a, const void *b)
{
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* n_cols columns; column c's crossings are first[c] .. first[c + 1] of t, owner, enter,
 * sorted by distance (ties as given). Per solid: kind, top height, profile key. Per column:
 * the sensor's height and its beams bin_first[c] .. bin_first[c + 1] (sorted by tan).
 * face_label and top_label map a kind (0-4) to a label; water_label is the sky's. Writes
 * every beam's horizontal distance t_all (inf: sky) and label. Returns 0, or -1 when out of
 * memory. */
int lidar_profile(int64_t n_cols, const int64_t *first, const double *t, const int64_t *owner,
                  const uint8_t *enter, const int8_t *kind, const double *top,
                  const int64_t *profile_key, const double *bin_height,
                  const int64_t *bin_first, const float *tan_el, const float *inv_drop,
                  const int8_t *face_label, const int8_t *top_label, int8_t water_label,
                  float *t_all, int8_t *label)
{
    int64_t most = 0;
    for (int64_t c = 0; c < n_cols; c++)
        if (first[c + 1] - first[c] > most)
            most = first[c + 1] - first[c];
    int64_t *by_solid = malloc(sizeof(int64_t) * (most + 1));
    int64_t *seg_key = malloc(sizeof(int64_t) * (most + 1));
    uint8_t *kept = malloc(most + 1);
    if (!by_solid || !seg_key || !kept) {
        free(by_solid);
        free(seg_key);
        free(kept);
        return -1;
    }
    const int64_t mask = ((int64_t)1 << SOLID_BITS) - 1;
    for (int64_t c = 0; c < n_cols; c++) {
        int64_t e0 = first[c], n = first[c + 1] - e0;
        const double *tc = t + e0;
        const int64_t *oc = owner + e0;
        const uint8_t *ec = enter + e0;
        /* Which solid is highest on each segment (0: before the first crossing; i: after
         * crossing i - 1): each solid's crossings in distance order, less the pairs where
         * a ray only touches it (in and out at one point). */
        for (int64_t i = 0; i < n; i++)
            by_solid[i] = (oc[i] << 32) | i;
        if (n <= 32)
            sort_keys(by_solid, n);
        else
            qsort(by_solid, n, sizeof(int64_t), cmp_keys);
        for (int64_t i = 0; i <= n; i++)
            seg_key[i] = 0;
        for (int64_t i = 0; i < n; i++)
            kept[i] = 1;
        for (int64_t i = 0; i + 1 < n; i++) {
            int64_t p = by_solid[i] & 0xFFFFFFFF, q = by_solid[i + 1] & 0xFFFFFFFF;
            if (oc[p] == oc[q] && ec[p] != ec[q] && fabs(tc[q] - tc[p]) <= 1e-7)
                kept[i] = kept[i + 1] = 0;
        }
        int64_t prev_owner = -1;
        for (int64_t i = 0; i < n; i++) {
            if (!kept[i])
                continue;
            int64_t p = by_solid[i] & 0xFFFFFFFF, s = oc[p];
            int is_new = s != prev_owner;
            prev_owner = s;
            int64_t nxt = n; /* the solid's next kept crossing, or the column's end */
            for (int64_t j = i + 1; j < n; j++) {
                if (!kept[j])
                    continue;
                if (oc[by_solid[j] & 0xFFFFFFFF] == s)
                    nxt = by_solid[j] & 0xFFFFFFFF;
                break;
            }
            int64_t lo, hi;
            if (ec[p]) {
                lo = p + 1;
                hi = nxt + 1;
            } else if (is_new && kind[s] == STANDING) {
                lo = 0; /* the sensor is inside it */
                hi = p + 1;
            } else {
                continue;
            }
            for (int64_t k = lo; k < hi; k++)
                if (profile_key[s] > seg_key[k])
                    seg_key[k] = profile_key[s];
        }
        /* The beams of this column, by tan(elevation), through the pieces in turn. */
        double h = bin_height[c];
        int64_t b = bin_first[c], b_end = bin_first[c + 1];
        float C = -INFINITY;
        for (int64_t i = 0; i <= n && b < b_end; i++) {
            int64_t top_of = (seg_key[i] & mask) - 1;
            double height = top_of >= 0 ? top[top_of] : 0.0;
            int seg_kind = top_of >= 0 ? kind[top_of] : WATER_KIND;
            double fin = 0.0;
            int fin_kind = WATER_KIND;
            if (i > 0 && kind[oc[i - 1]] <= BACK) { /* faces stand at every crossing */
                fin = top[oc[i - 1]];
                fin_kind = kind[oc[i - 1]];
            }
            double face_height = height > fin ? height : fin;
            int face_kind = fin > height ? fin_kind : seg_kind;
            double start = i > 0 ? tc[i - 1] : 0.0;
            double end = i < n ? tc[i] : INFINITY;
            double f = (face_height - h) / start;
            double clear = height < h ? (height - h) / end : (height - h) / start;
            if (isnan(f))
                f = -INFINITY;
            if (isnan(clear))
                clear = INFINITY;
            float F = (float)f, CL = (float)clear;
            float Fp = C > F ? C : F;
            float Cn = Fp > CL ? Fp : CL;
            float a = (float)start;
            int8_t lf = face_label[face_kind], lt = top_label[seg_kind];
            while (b < b_end && tan_el[b] <= Fp) {
                t_all[b] = a;
                label[b] = lf;
                b++;
            }
            float drop = (float)(h - height);
            while (b < b_end && tan_el[b] <= Cn) {
                t_all[b] = 0.0f + drop * inv_drop[b];
                label[b] = lt;
                b++;
            }
            C = Cn;
        }
        for (; b < b_end; b++) {
            t_all[b] = INFINITY;
            label[b] = water_label;
        }
    }
    free(by_solid);
    free(seg_key);
    free(kept);
    return 0;
}

/* The 2-D cast, first part (LidarSimulator._cast): the edges near enough to matter
 * (min(|a - centre|, |b - centre|) < reach + length, with hypot as numpy's), one row per
 * (sensor, such edge), sensors outermost: the row's edge, and for the caller's arctan2 the
 * offsets from the sensor of the edge's ends: with N rows, dy of end a in d[0 .. N), of
 * end b in d[N .. 2N), and dx likewise from d + 2 room. Returns N, or -1 when more than
 * `room`. */
int64_t lidar_edge_rows(int64_t n_edges, const double *a, const double *b,
                        const double *reach_len, double cx, double cy, int64_t n_sensors,
                        const double *origins, int64_t room, int64_t *row_edge, double *d)
{
    int64_t n = 0;
    for (int64_t e = 0; e < n_edges; e++) {
        double r = reach_len[e];
        double ax = a[2 * e] - cx, ay = a[2 * e + 1] - cy;
        double bx = b[2 * e] - cx, by = b[2 * e + 1] - cy;
        /* hypot only near the threshold: elsewhere the squares decide (hypot is within
         * an ulp, far inside the margin) */
        double qa = ax * ax + ay * ay, qb = bx * bx + by * by, q = qa < qb ? qa : qb;
        double r2 = r * r;
        int near;
        if (q < r2 * (1.0 - 1e-9))
            near = 1;
        else if (q > r2 * (1.0 + 1e-9))
            near = 0;
        else {
            double ha = hypot(ax, ay), hb = hypot(bx, by);
            near = (ha < hb ? ha : hb) < r;
        }
        if (near)
            row_edge[n++] = e;
    }
    if (n * n_sensors > room)
        return -1;
    for (int64_t s = 1; s < n_sensors; s++)
        for (int64_t i = 0; i < n; i++)
            row_edge[s * n + i] = row_edge[i];
    int64_t rows = n * n_sensors;
    for (int64_t s = 0; s < n_sensors; s++) {
        double ox = origins[2 * s], oy = origins[2 * s + 1];
        for (int64_t i = 0; i < n; i++) {
            int64_t e = row_edge[i], r = s * n + i;
            d[r] = a[2 * e + 1] - oy;
            d[rows + r] = b[2 * e + 1] - oy;
            d[2 * room + r] = a[2 * e] - ox;
            d[2 * room + rows + r] = b[2 * e] - ox;
        }
    }
    return rows;
}

/* numpy's float remainder (the sign of the divisor). */
static double py_mod(double x, double m)
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

/* Second part: the crossings. Row r (of n_rows, sensor r / rows_per_sensor) pairs edge
 * row_edge[r] with the bins between its ends' angles ang_a[r] - psi, ang_b[r] - psi (each
 * end's bin from its own angle, and whole turns, so two legs meeting at a vertex agree);
 * bins wrap modulo the sensor's count. For each, the crossing of the bin's ray from the
 * sensor's origin (heading: cos cp, sin sp) with the edge a -> b, kept when
 * 1e-6 < t <= reach; written in row and bin order: the bin (numbered across sensors),
 * distance, solid, and whether the ray enters it. Returns how many were written, or
 * -(how many there are) - 1 when more than `room` (nothing useful written then). */
int64_t lidar_cast(int64_t n_rows, int64_t rows_per_sensor, const int64_t *row_edge,
                   const double *ang_a, const double *ang_b, double psi, const double *a,
                   const double *b, const int64_t *edge_owner, const double *edge_side,
                   const double *origins, const int64_t *bin_offset, const int64_t *bin_count,
                   const double *bin_step, const double *bin_cos, const double *bin_sin,
                   double cp, double sp, double reach, int64_t room, int64_t *gbin, double *t,
                   int64_t *owner, uint8_t *enter)
{
    const double pi = 3.141592653589793, two_pi = 6.283185307179586;
    int64_t n = 0, need = 0;
    for (int64_t r = 0; r < n_rows; r++) {
        int64_t e = row_edge[r], s = r / rows_per_sensor, nb = bin_count[s];
        double step = bin_step[s];
        double aa = ang_a[r] - psi, ab = ang_b[r] - psi;
        double span = py_mod(ab - aa + pi, two_pi) - pi;
        double lo = span < 0 ? ab : aa, hi = span < 0 ? aa : ab;
        int64_t k0 = (int64_t)ceil(lo / step);
        int64_t turns = (int64_t)nearbyint((lo + fabs(span) - hi) / two_pi);
        int64_t k1 = (int64_t)floor(hi / step) + turns * nb;
        int64_t count = k1 - k0 + 1;
        if (count <= 0)
            continue;
        need += count;
        if (need > room)
            continue;
        double ax = a[2 * e], ay = a[2 * e + 1];
        double ex = b[2 * e] - ax, ey = b[2 * e + 1] - ay;
        double rx = ax - origins[2 * s], ry = ay - origins[2 * s + 1];
        double num = rx * ey - ry * ex;
        for (int64_t j = 0; j < count; j++) {
            int64_t k = k0 + j, m = k % nb;
            if (m < 0)
                m += nb;
            int64_t g = bin_offset[s] + m;
            double cb = bin_cos[g], sb = bin_sin[g];
            double dx = cp * cb - sp * sb, dy = sp * cb + cp * sb;
            double den = dx * ey - dy * ex;
            double tt = num / den;
            if (tt > 1e-6 && tt <= reach) {
                gbin[n] = g;
                t[n] = tt;
                owner[n] = edge_owner[e];
                enter[n] = edge_side[e] * den < 0.0;
                n++;
            }
        }
    }
    return need > room ? -need - 1 : n;
}

/* Third part: the crossings by column, for lidar_profile: ordered as numpy's stable
 * argsort of gbin * t_scale + t (that rounded key; ties in the given order), into t_out,
 * owner_out, enter_out, with first[c] .. first[c + 1] the crossings of column c. Returns
 * 0, or -1 when out of memory. */
int lidar_columns(int64_t n, const int64_t *gbin, const double *t, const int64_t *owner,
                  const uint8_t *enter, int64_t n_bins, double t_scale, int64_t *first,
                  double *t_out, int64_t *owner_out, uint8_t *enter_out)
{
    int64_t *at = malloc(sizeof(int64_t) * (n_bins + 1));
    if (!at)
        return -1;
    for (int64_t c = 0; c <= n_bins; c++)
        first[c] = 0;
    for (int64_t i = 0; i < n; i++)
        first[gbin[i] + 1]++;
    for (int64_t c = 0; c < n_bins; c++)
        first[c + 1] += first[c];
    for (int64_t c = 0; c < n_bins; c++)
        at[c] = first[c];
    for (int64_t i = 0; i < n; i++) {
        int64_t j = at[gbin[i]]++;
        t_out[j] = t[i];
        owner_out[j] = owner[i];
        enter_out[j] = enter[i];
    }
    free(at);
    for (int64_t c = 0; c < n_bins; c++) { /* within a column, a stable insertion sort */
        double base = (double)c * t_scale;
        for (int64_t i = first[c] + 1; i < first[c + 1]; i++) {
            double tv = t_out[i], kv = base + tv;
            int64_t ov = owner_out[i];
            uint8_t ev = enter_out[i];
            int64_t j = i - 1;
            while (j >= first[c] && base + t_out[j] > kv) {
                t_out[j + 1] = t_out[j];
                owner_out[j + 1] = owner_out[j];
                enter_out[j + 1] = enter_out[j];
                j--;
            }
            t_out[j + 1] = tv;
            owner_out[j + 1] = ov;
            enter_out[j + 1] = ev;
        }
    }
    return 0;
}

/* The scan's returns, first part: the beams within range (min_h <= t <= max_h), as
 * indices. Returns how many. */
int64_t lidar_in_range(int64_t n, const float *t_all, const float *min_h, const float *max_h,
                       int64_t *idx)
{
    int64_t m = 0;
    for (int64_t i = 0; i < n; i++)
        if (t_all[i] >= min_h[i] && t_all[i] <= max_h[i])
            idx[m++] = i;
    return m;
}

/* Second part: of those, the ones a 16-bit draw u keeps (u >= drop; a water return only if
 * u < speckle), compacted in place with their labels. Returns how many; *n_water: how many
 * of them are water. */
int64_t lidar_keep(int64_t n, int64_t *idx, const int8_t *label, const uint16_t *u,
                   int drop, int speckle, int8_t water, int8_t *lab, int64_t *n_water)
{
    int64_t m = 0, w = 0;
    for (int64_t i = 0; i < n; i++) {
        int8_t l = label[idx[i]];
        if (u[i] >= drop && (l != water || u[i] < speckle)) {
            idx[m] = idx[i];
            lab[m] = l;
            w += l == water;
            m++;
        }
    }
    *n_water = w;
    return m;
}

/* Third part: the points (3 rows of stride `stride` in out) of the kept beams: range noise
 * (normal * sigma * cos_el), along the beam's body-frame vector per horizontal metre, from
 * its sensor's origin (sensor k's beams start at beam_start[k]); water points moved up by
 * ripple[j] (j-th water point). */
void lidar_points(int64_t n, const int64_t *idx, const int8_t *lab, const float *t_all,
                  const float *normal, float sigma, const float *cos_el, const float *vec,
                  int64_t n_beams, int64_t n_sensors, const int64_t *beam_start,
                  const float *origin, const float *ripple, int8_t water, float *out,
                  int64_t stride)
{
    int64_t k = 0, w = 0;
    for (int64_t j = 0; j < n; j++) {
        int64_t i = idx[j];
        while (k + 1 < n_sensors && i >= beam_start[k + 1])
            k++;
        float t = t_all[i] + normal[j] * (sigma * cos_el[i]);
        float x = vec[i] * t, y = vec[n_beams + i] * t, z = vec[2 * n_beams + i] * t;
        x += origin[3 * k];
        y += origin[3 * k + 1];
        z += origin[3 * k + 2];
        if (lab[j] == water)
            z -= ripple[w++];
        out[j] = x;
        out[stride + j] = y;
        out[2 * stride + j] = z;
    }
}

/* Fourth part: the own hull's kept returns (indices keep, m of them) of the nh noiseless
 * ones (pts, rows x, y, z of stride nh), moved along their beams (unit, the same layout) by
 * range noise normal * sigma, into the 3 rows of out (stride `stride`). */
void lidar_hull(int64_t m, const int64_t *keep, const float *pts, const float *unit,
                int64_t nh, const float *normal, float sigma, float *out, int64_t stride)
{
    for (int64_t j = 0; j < m; j++) {
        int64_t i = keep[j];
        float s = normal[j] * sigma;
        for (int c = 0; c < 3; c++)
            out[c * stride + j] = pts[c * nh + i] + unit[c * nh + i] * s;
    }
}
