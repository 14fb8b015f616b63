/* The NMPC's per-step geometry along the path, as numpy computes it (`reference.py`,
 * `slack_reference.py`), in the same operations and order; only the sines and cosines may
 * round differently from numpy's (its vectorised ones), by an ulp.
 *
 * path_points, path_project: WaypointPath.at and .project.
 * path_frame: arc length s and signed offset d (> 0 to starboard) of n points against the
 *   legs of a waypoint path whose extent overlaps [s_min, s_max] (WaypointPath.frame).
 * forced_slack_at: the slack each point's hull circle needs midway between the walls abeam
 *   (slack_reference.forced_slack_at), for M segments (x_c, y_c, theta, length) rows.
 * walls_abeam: the distance from n points to the nearest wall abeam to port and to starboard
 *   (slack_reference._Frames.walls_abeam), the sines and cosines handed in from numpy.
 * slot_distances: each of m segments' distance from the boat (the first of k points) and
 *   from the nearest of all k (the boat and its plan): segment_slots.select_checked's ranking.
 * walk_slabs: the passage sweep's walk over slabs (passage.walk_slabs): the first slab with
 *   no free interval reached from the slab before, and where the path's line must shift.
 * rays_crossing: which of n sight lines p -> q cross any of m walls a -> b
 *   (geometry.segments_cross(...).any(axis=1)), `closed` counting touches too; a p stride
 *   of 0 casts every line from the one point p.
 * forced_slack_stages: per stage, the least forced slack over its stretch of the path
 *   (slack_reference.forced_slack), the samples taken and moved across the path here.
 * keep_slots: the segment slots rearranged so that a segment kept from the last step keeps
 *   its slot (segment_slots.kept_in_place).
 * side_rays: the blind-opening rule's rays across the path (blind_openings.side_rays): at n
 *   arc lengths, the far ends of rays `depth` to starboard and to port, and which of them
 *   lie within `reach` of the boat and meet no wall (touching counts). */
#include <math.h>
#include <stdint.h>

void path_frame(int64_t n, const double *px, const double *py, int64_t legs,
                const double *start, const double *delta, const double *length,
                const double *cum, double s_min, double s_max, double *s_out, double *d_out)
{
    if (s_max > cum[legs]) s_max = cum[legs];
    if (s_min > s_max) s_min = s_max;
    for (int64_t i = 0; i < n; i++) {
        double best = INFINITY, best_s = 0.0, best_d = 0.0;
        int found = 0;
        for (int64_t k = 0; k < legs; k++) {
            if (!(cum[k] <= s_max && cum[k + 1] >= s_min)) continue;
            double dx = delta[2 * k], dy = delta[2 * k + 1], L = length[k], at = cum[k];
            double qx = px[i] - start[2 * k], qy = py[i] - start[2 * k + 1];
            double along = (qx * dx + qy * dy) / L;
            double lo = at > s_min ? at : s_min;
            double hi = cum[k + 1] < s_max ? cum[k + 1] : s_max;
            double s = at + along;
            s = s > lo ? s : lo;  /* np.maximum(at + along, lo), then np.minimum(., hi) */
            s = s < hi ? s : hi;
            double t = (s - at) / L;
            double rx = qx - t * dx, ry = qy - t * dy;
            double r2 = rx * rx + ry * ry;
            if (!found || r2 < best) {  /* np.argmin: the first of equal ones */
                found = 1;
                best = r2;
                best_s = s;
                double side = (dx * ry - dy * rx) / L;
                double offset = hypot(rx, ry);
                best_d = side >= 0.0 ? offset : -offset;
            }
        }
        s_out[i] = best_s;
        d_out[i] = best_d;
    }
}

/* WaypointPath.at for one arc length: the point and the leg's index (searchsorted right, less
 * one, on s clamped to the path). */
static int64_t path_at(double s, int64_t legs, const double *start, const double *delta,
                       const double *length, const double *cum, double *x, double *y)
{
    s = s < 0.0 ? 0.0 : s;  /* (a NaN stays NaN, and on the last leg, as in numpy) */
    s = s > cum[legs] ? cum[legs] : s;
    int64_t lo = 0, hi = legs + 1;  /* the first index with cum > s */
    while (lo < hi) {
        int64_t mid = (lo + hi) / 2;
        if (cum[mid] > s) hi = mid; else lo = mid + 1;
    }
    int64_t k = lo - 1 < legs - 1 ? lo - 1 : legs - 1;
    double t = (s - cum[k]) / length[k];
    *x = start[2 * k] + t * delta[2 * k];
    *y = start[2 * k + 1] + t * delta[2 * k + 1];
    return k;
}

static double pow4(double x)
{
    double x2 = x * x;
    return x2 * x2;
}

/* The largest separation m' <= margin with which a point at (a, b) along and across
 * segments of half lengths `half` is outside every super-ellipse (slack_reference.
 * separation_allowed for one point). */
static double separation_allowed(int64_t M, const double *along, const double *across,
                                 const double *half, double margin, double margin4)
{
    double out = INFINITY;
    for (int64_t j = 0; j < M; j++) {
        double a = fabs(along[j]), b = fabs(across[j]);
        double a2 = a * a, b2 = b * b;
        double a4 = a2 * a2, b4 = b2 * b2;
        double value = margin;
        if (a4 / pow4(half[j] + margin) + b4 / margin4 < 1.0) {
            double m = b > a - half[j] ? b : a - half[j];
            m = m > 1e-6 ? m : 1e-6;
            for (int it = 0; it < 4; it++) {
                double big = half[j] + m;
                double ua = a4 / pow4(big), ub = b4 / pow4(m);
                m += (ua + ub - 1.0) / (4.0 * (ua / big + ub / m));
            }
            value = m < margin ? m : margin;
        }
        if (value < out) out = value;
    }
    return out;
}

/* scratch: 6 * M doubles. Returns 1 when a point needs a slack, else 0 (all out zero). */
int64_t forced_slack_at(int64_t n, const double *px, const double *py, const double *heading,
                        int64_t M, const double *seg, double margin, double slack_min,
                        double *out, double *scratch)
{
    double *ex = scratch, *ey = scratch + M, *half = scratch + 2 * M;
    double *along = scratch + 3 * M, *across = scratch + 4 * M;
    double far2 = (1.25 * margin) * (1.25 * margin) * (1.0 + 1e-9);
    double margin4 = pow(margin, 4.0);
    for (int64_t i = 0; i < n; i++) out[i] = 0.0;
    if (M == 0) return 0;
    for (int64_t j = 0; j < M; j++) {
        ex[j] = cos(seg[4 * j + 2]);
        ey[j] = sin(seg[4 * j + 2]);
        half[j] = 0.5 * seg[4 * j + 3];
    }
    /* every point at least 1.25 margin from every segment: no slack anywhere */
    double nearest2 = INFINITY;
    for (int64_t i = 0; i < n; i++)
        for (int64_t j = 0; j < M; j++) {
            double dx = px[i] - seg[4 * j], dy = py[i] - seg[4 * j + 1];
            double al = dx * ex[j] + dy * ey[j], ac = dy * ex[j] - dx * ey[j];
            double cl = al > -half[j] ? al : -half[j];
            cl = cl < half[j] ? cl : half[j];
            double va = cl - al, vc = -ac;
            double r2 = va * va + vc * vc;
            if (r2 < nearest2) nearest2 = r2;
        }
    if (nearest2 >= far2) return 0;
    int64_t any = 0;
    for (int64_t i = 0; i < n; i++) {
        double nx = -sin(heading[i]), ny = cos(heading[i]);
        double port = INFINITY, starboard = INFINITY;
        double *na = scratch + 5 * M;  /* the normal along each segment, for the shift */
        for (int64_t j = 0; j < M; j++) {
            double dx = px[i] - seg[4 * j], dy = py[i] - seg[4 * j + 1];
            double al = dx * ex[j] + dy * ey[j], ac = dy * ex[j] - dx * ey[j];
            along[j] = al;
            across[j] = ac;
            double cl = al > -half[j] ? al : -half[j];
            cl = cl < half[j] ? cl : half[j];
            double va = cl - al, vc = -ac;
            double dist = hypot(va, vc);
            double n_along = nx * ex[j] + ny * ey[j], n_across = ny * ex[j] - nx * ey[j];
            na[j] = n_along;
            double side = va * n_along + vc * n_across;
            if (fabs(side) >= 0.5 * dist) {
                if (side < 0 && dist < port) port = dist;
                if (side > 0 && dist < starboard) starboard = dist;
            }
        }
        if (!(port + starboard < 2.5 * margin)) continue;
        double shift = 0.5 * (starboard - port);
        for (int64_t j = 0; j < M; j++) {
            double n_across = ny * ex[j] - nx * ey[j];
            along[j] = along[j] + shift * na[j];
            across[j] = across[j] + shift * n_across;
        }
        double allowed = separation_allowed(M, along, across, half, margin, margin4);
        double v = allowed - margin;
        v = v < 0.0 ? v : 0.0;
        out[i] = v > slack_min ? v : slack_min;
        any = 1;
    }
    return any;
}

static double cross3(double ox, double oy, double px, double py, double qx, double qy)
{
    return (px - ox) * (qy - oy) - (py - oy) * (qx - ox);
}

void rays_crossing(int64_t n, const double *p, int64_t p_stride, const double *q, int64_t m,
                   const double *a, const double *b, int closed, uint8_t *out)
{
    for (int64_t i = 0; i < n; i++) {
        double p0 = p[i * p_stride], p1 = p[i * p_stride + 1], q0 = q[2 * i], q1 = q[2 * i + 1];
        uint8_t hit = 0;
        for (int64_t j = 0; j < m && !hit; j++) {
            double a0 = a[2 * j], a1 = a[2 * j + 1], b0 = b[2 * j], b1 = b[2 * j + 1];
            double d1 = cross3(a0, a1, b0, b1, p0, p1), d2 = cross3(a0, a1, b0, b1, q0, q1);
            double d3 = cross3(p0, p1, q0, q1, a0, a1), d4 = cross3(p0, p1, q0, q1, b0, b1);
            hit = closed ? (d1 * d2 <= 0 && d3 * d4 <= 0) : (d1 * d2 < 0 && d3 * d4 < 0);
        }
        out[i] = hit;
    }
}

void walls_abeam(int64_t n, const double *px, const double *py, const double *nx,
                 const double *ny, int64_t m, const double *sx, const double *sy,
                 const double *ex, const double *ey, const double *half, double abeam_cos,
                 double *port, double *starboard)
{
    for (int64_t i = 0; i < n; i++) {
        double p = INFINITY, s = INFINITY;
        for (int64_t j = 0; j < m; j++) {
            double dx = px[i] - sx[j], dy = py[i] - sy[j];
            double along = dx * ex[j] + dy * ey[j], across = dy * ex[j] - dx * ey[j];
            double cl = along > -half[j] ? along : -half[j];
            cl = cl < half[j] ? cl : half[j];
            double va = cl - along, vc = -across;
            double dist = hypot(va, vc);
            double n_along = nx[i] * ex[j] + ny[i] * ey[j];
            double n_across = ny[i] * ex[j] - nx[i] * ey[j];
            double side = va * n_along + vc * n_across;
            if (fabs(side) >= abeam_cos * dist) {
                if (side < 0 && dist < p) p = dist;
                if (side > 0 && dist < s) s = dist;
            }
        }
        port[i] = p;
        starboard[i] = s;
    }
}

void slot_distances(int64_t k, const double *p, int64_t m, const double *seg, const double *c,
                    const double *s, double *to_boat, double *to_plan)
{
    for (int64_t j = 0; j < m; j++) {
        const double *g = seg + 4 * j;
        double best = INFINITY;
        for (int64_t i = 0; i < k; i++) {
            double dx = p[2 * i] - g[0], dy = p[2 * i + 1] - g[1];
            double along = fabs(dx * c[j] + dy * s[j]), across = (-dx) * s[j] + dy * c[j];
            double off = along - g[3] / 2;
            double d = hypot(off > 0.0 ? off : 0.0, across);
            if (i == 0)
                to_boat[j] = d;
            if (d < best || i == 0)
                best = d;
        }
        to_plan[j] = best;
    }
}

int64_t walk_slabs(int64_t n, const int64_t *slab, const double *d, int64_t n_slabs,
                   double lateral, double min_passage, double overlap, double keep,
                   double offset, double *scratch, int64_t *shift_at, double *shift_d,
                   int64_t *n_shifts)
{
    /* intervals as (lo, hi) pairs: those reached so far, and those reached in this slab */
    double *reach = scratch, *reached = scratch + 2 * (n + 2);
    int64_t n_reach = 1, pos = 0, ns = 0;
    reach[0] = offset - overlap;
    reach[1] = offset + overlap;
    for (int64_t j = 0; j < n_slabs; j++) {
        while (pos < n && slab[pos] < j)
            pos++;
        if (pos >= n || slab[pos] != j) {  /* nothing in this slab: all of it is open */
            reach[0] = -lateral;
            reach[1] = lateral;
            n_reach = 1;
            continue;
        }
        int64_t end = pos, n_reached = 0;
        while (end < n && slab[end] == j)
            end++;
        /* the free intervals in order: from -lateral to the first point, between
         * neighbours, from the last point to lateral; the wide enough ones */
        for (int64_t q = pos - 1; q < end; q++) {
            double g0 = q < pos ? -lateral : d[q];
            double g1 = q + 1 < end ? d[q + 1] : lateral;
            if (!(g1 - g0 >= min_passage))
                continue;
            for (int64_t r = 0; r < n_reach; r++) {
                double r0 = reach[2 * r], r1 = reach[2 * r + 1];
                double hi = r1 < g1 ? r1 : g1, lo = r0 > g0 ? r0 : g0;
                if (hi - lo >= overlap) {
                    reached[2 * n_reached] = g0;
                    reached[2 * n_reached + 1] = g1;
                    n_reached++;
                    break;
                }
            }
        }
        pos = end;
        if (!n_reached) {
            *n_shifts = ns;
            return j;
        }
        double *t = reach;
        reach = reached;
        reached = t;
        n_reach = n_reached;
        int line_ok = 0;
        for (int64_t r = 0; r < n_reach; r++)
            if (reach[2 * r] <= -overlap && reach[2 * r + 1] >= overlap)
                line_ok = 1;
        if (!line_ok) {  /* into the reached interval nearest the line d = 0 */
            double best = 0.0;
            for (int64_t r = 0; r < n_reach; r++) {
                double g0 = reach[2 * r], g1 = reach[2 * r + 1], target;
                if (g1 - g0 < 2 * keep) {
                    target = (g0 + g1) / 2;
                } else {
                    target = g0 + keep > 0.0 ? g0 + keep : 0.0;
                    target = g1 - keep < target ? g1 - keep : target;
                }
                if (r == 0 || fabs(target) < fabs(best))
                    best = target;
            }
            shift_at[ns] = j;
            shift_d[ns] = best;
            ns++;
        }
    }
    *n_shifts = ns;
    return -1;
}

void side_rays(int64_t n, const double *s, int64_t legs, const double *start,
               const double *delta, const double *length, const double *cum,
               const double *heading, double depth, double reach, double bx, double by,
               int64_t m, const double *a, const double *b, double *far, uint8_t *open)
{
    for (int64_t i = 0; i < n; i++) {
        double x, y;
        int64_t k = path_at(s[i], legs, start, delta, length, cum, &x, &y);
        double nx = -sin(heading[k]), ny = cos(heading[k]);  /* to starboard */
        for (int side = 0; side < 2; side++) {
            double w = (side == 0 ? 1.0 : -1.0) * depth;
            double fx = x + w * nx, fy = y + w * ny;
            double *f = far + 2 * (side * n + i);
            f[0] = fx;
            f[1] = fy;
            uint8_t ok = hypot(fx - bx, fy - by) <= reach;
            if (ok) {
                double p[2] = {x, y};
                rays_crossing(1, p, 0, f, m, a, b, 1, &ok);
                ok = !ok;
            }
            open[side * n + i] = ok;
        }
    }
}

/* forced_slack's stages: the path sampled every `spacing` from `start` (count samples), moved
 * across it by d (NULL: on the path), each sample's forced slack (forced_slack_at), and per
 * stage the least over its samples [lo, hi]. scratch: 4 count + 6 M doubles. */
void forced_slack_stages(int64_t n, const double *lo, const double *hi, double start,
                         double spacing, int64_t count, const double *d, int64_t legs,
                         const double *path_start, const double *delta, const double *length,
                         const double *cum, const double *heading, int64_t M,
                         const double *seg, double margin, double slack_min, double *out,
                         double *scratch)
{
    double *px = scratch, *py = scratch + count, *h = scratch + 2 * count;
    double *forced = scratch + 3 * count;
    for (int64_t i = 0; i < n; i++) out[i] = 0.0;
    for (int64_t i = 0; i < count; i++) {
        int64_t k = path_at(start + spacing * (double)i, legs, path_start, delta, length, cum,
                            px + i, py + i);
        h[i] = heading[k];
        if (d && d[i] != 0.0) {
            px[i] = px[i] + d[i] * -sin(h[i]);
            py[i] = py[i] + d[i] * cos(h[i]);
        }
    }
    if (!forced_slack_at(count, px, py, h, M, seg, margin, slack_min, forced,
                         scratch + 4 * count))
        return;
    for (int64_t i = 0; i < n; i++) {
        int64_t first = (int64_t)ceil((lo[i] - start) / spacing - 1e-9);
        first = first < count - 1 ? first : count - 1;
        int64_t last = (int64_t)floor((hi[i] - start) / spacing + 1e-9);
        last = last < count - 1 ? last : count - 1;
        last = last > first ? last : first;
        double v = forced[first];
        for (int64_t j = first + 1; j <= last; j++) v = forced[j] < v ? forced[j] : v;
        out[i] = v;
    }
}

/* WaypointPath.at for n arc lengths: points (n, 2) and leg headings. */
void path_points(int64_t n, const double *s, int64_t legs, const double *start,
                 const double *delta, const double *length, const double *cum,
                 const double *heading, double *xy, double *psi)
{
    for (int64_t i = 0; i < n; i++)
        psi[i] = heading[path_at(s[i], legs, start, delta, length, cum, xy + 2 * i,
                                 xy + 2 * i + 1)];
}

/* WaypointPath.project: the arc length in [s_min, s_max] of the path's point closest to
 * (px, py), and the distance to it, in project's operations (the first of equal ones). */
double path_project(double px, double py, int64_t legs, const double *start,
                    const double *delta, const double *length, const double *cum,
                    double s_min, double s_max, double *s_out)
{
    s_max = s_max < cum[legs] ? s_max : cum[legs];
    s_min = s_min < s_max ? s_min : s_max;
    double best = INFINITY, best_s = 0.0;
    int found = 0;
    for (int64_t k = 0; k < legs; k++) {
        double lo = cum[k] > s_min ? cum[k] : s_min;
        double hi = cum[k + 1] < s_max ? cum[k + 1] : s_max;
        if (!(lo <= hi)) continue;
        double dx = px - start[2 * k], dy = py - start[2 * k + 1];
        double along = (dx * delta[2 * k] + dy * delta[2 * k + 1]) / length[k];
        double s = cum[k] + along;
        s = s > lo ? s : lo;
        s = s < hi ? s : hi;
        double t = (s - cum[k]) / length[k];
        double x = start[2 * k] + t * delta[2 * k], y = start[2 * k + 1] + t * delta[2 * k + 1];
        double dist = hypot(x - px, y - py);
        if (!found || dist < best) {
            found = 1;
            best = dist;
            best_s = s;
        }
    }
    *s_out = best_s;
    return best;
}

/* segment_slots.kept_in_place: `slots` (n rows x_c, y_c, theta, length, active) rearranged
 * into `out` so that each active row also active in `prev` (the first such there, compared
 * exactly) keeps prev's slot and the other active rows fill the free slots in order. Returns
 * 0, `out` not written, when no row is kept or two would take one slot. scratch: 2 n. */
int64_t keep_slots(int64_t n, const double *slots, const double *prev, int64_t *scratch,
                   double *out)
{
    int64_t *slot_of = scratch, *owner = scratch + n, kept = 0;
    for (int64_t j = 0; j < n; j++) owner[j] = -1;
    for (int64_t i = 0; i < n; i++) {
        const double *r = slots + 5 * i;
        slot_of[i] = -2;  /* inactive: dropped */
        if (!(r[4] > 0)) continue;
        slot_of[i] = -1;  /* active, new */
        for (int64_t j = 0; j < n; j++) {
            const double *q = prev + 5 * j;
            if (q[4] > 0 && q[0] == r[0] && q[1] == r[1] && q[2] == r[2] && q[3] == r[3]) {
                if (owner[j] >= 0) return 0;  /* two rows for one slot */
                owner[j] = i;
                slot_of[i] = j;
                kept++;
                break;
            }
        }
    }
    if (!kept) return 0;
    for (int64_t k = 0; k < 5 * n; k++) out[k] = 0.0;
    int64_t free_slot = 0;
    for (int64_t i = 0; i < n; i++) {
        int64_t j = slot_of[i];
        if (j == -1) {  /* the next slot nobody keeps */
            while (owner[free_slot] >= 0) free_slot++;
            j = free_slot++;
        }
        if (j >= 0)
            for (int k = 0; k < 5; k++) out[5 * j + k] = slots[5 * i + k];
    }
    return 1;
}
