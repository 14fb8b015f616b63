/* The detector's refit (detection._refit and _chords, their numpy twins): each merged
 * Hough line, longest first, is fitted to the free occupied cells near it (total least
 * squares, twice: select, fit, select again around the fit), split where the cells leave a
 * gap wider than the range allows, each run cut into chords where the wall bends (bins two
 * cells long, Douglas-Peucker), each chord fitted to its own cells; the cells on a chord are
 * then taken. The same steps in the same order as the numpy version; sums run in the cells'
 * order, so results agree with numpy's (whose products go through BLAS) to rounding.
 *
 * Returns the number of chords written to `chords` (4 doubles each: ax, ay, bx, by), or -1
 * when more than `capacity` would be needed (the caller retries with more room), -2 when
 * out of memory. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    double inlier, reach, max_gap, gap_per_range, min_length, cell, chord_tol, fit_band;
    int64_t min_points;
} fit_cfg;

typedef struct {
    double *chords;
    int64_t n, capacity;
} chord_out;

/* Centre and unit direction of the total-least-squares line through pts[idx[0..n)]. */
static void principal(const double *xy, const int64_t *idx, int64_t n, double out[4])
{
    double sx = 0, sy = 0, mxx = 0, mxy = 0, myy = 0;
    for (int64_t k = 0; k < n; k++) {
        double x = xy[2 * idx[k]], y = xy[2 * idx[k] + 1];
        sx += x;
        sy += y;
        mxx += x * x;
        mxy += x * y;
        myy += y * y;
    }
    double cx = sx / n, cy = sy / n;
    double angle = 0.5 * atan2(2.0 * (mxy / n - cx * cy), (mxx / n - cx * cx) - (myy / n - cy * cy));
    out[0] = cx;
    out[1] = cy;
    out[2] = cos(angle);
    out[3] = sin(angle);
}

/* Sort idx[0..n) by key (ascending; ties keep their order: insertion into runs + merge). */
static int by_key(int64_t *idx, double *key, int64_t n, int64_t *tmp_i, double *tmp_k)
{
    for (int64_t width = 1; width < n; width *= 2) {
        for (int64_t lo = 0; lo < n; lo += 2 * width) {
            int64_t mid = lo + width < n ? lo + width : n;
            int64_t hi = lo + 2 * width < n ? lo + 2 * width : n;
            int64_t a = lo, b = mid, o = lo;
            while (a < mid && b < hi) {
                if (key[b] < key[a]) {
                    tmp_k[o] = key[b];
                    tmp_i[o++] = idx[b++];
                } else {
                    tmp_k[o] = key[a];
                    tmp_i[o++] = idx[a++];
                }
            }
            while (a < mid) {
                tmp_k[o] = key[a];
                tmp_i[o++] = idx[a++];
            }
            while (b < hi) {
                tmp_k[o] = key[b];
                tmp_i[o++] = idx[b++];
            }
        }
        memcpy(idx, tmp_i, (size_t)n * sizeof *idx);
        memcpy(key, tmp_k, (size_t)n * sizeof *key);
    }
    return 0;
}

static int push_chord(chord_out *out, double ax, double ay, double bx, double by)
{
    if (out->n >= out->capacity)
        return -1;
    double *c = out->chords + 4 * out->n++;
    c[0] = ax;
    c[1] = ay;
    c[2] = bx;
    c[3] = by;
    return 0;
}

/* Indices of path (px, py, pt) strictly between i and j where it must be split, appended
 * to cuts in the order the numpy version's recursion lists them. */
static void douglas_peucker(const double *px, const double *py, const double *pt, int64_t i,
                            int64_t j, const fit_cfg *cfg, int64_t *cuts, int64_t *n_cuts)
{
    if (j - i < 2)
        return;
    double ax = px[i], ay = py[i], dx = px[j] - ax, dy = py[j] - ay;
    double length = hypot(dx, dy);
    if (length <= 0)
        return;
    double c0 = ay * dx - ax * dy, best = -1.0;
    int64_t k = -1;
    for (int64_t q = i + 1; q < j; q++) {
        double off = fabs((px[q] * -dy + py[q] * dx) - c0);
        if (off > best) {
            best = off;
            k = q;
        }
    }
    if (best / length <= cfg->chord_tol)
        return;
    if (pt[k] - pt[i] < cfg->min_length || pt[j] - pt[k] < cfg->min_length)
        return;
    douglas_peucker(px, py, pt, i, k, cfg, cuts, n_cuts);
    cuts[(*n_cuts)++] = k;
    douglas_peucker(px, py, pt, k, j, cfg, cuts, n_cuts);
}

typedef struct {
    int64_t *sel, *tmp_i, *cuts, *close;
    double *t, *tmp_k, *px, *py, *pt;
} scratch;

/* One chord from the cells idx[0..n) (fit: their line, or NULL to fit it here). */
static int piece_chord(const double *xy, const int64_t *idx, int64_t n, const double *fit,
                       const fit_cfg *cfg, scratch *w, chord_out *out)
{
    double line[4];
    if (fit)
        memcpy(line, fit, sizeof line);
    else
        principal(xy, idx, n, line);
    double cx = line[0], cy = line[1], vx = line[2], vy = line[3];
    double c0 = cy * vx - cx * vy;
    int64_t n_close = 0;
    for (int64_t k = 0; k < n; k++) {
        double off = (xy[2 * idx[k]] * -vy + xy[2 * idx[k] + 1] * vx) - c0;
        if (fabs(off) <= cfg->fit_band)
            w->close[n_close++] = idx[k];
    }
    int64_t need = cfg->min_points > 2 ? cfg->min_points : 2;
    if (n_close >= need && n_close < n) {
        principal(xy, w->close, n_close, line);
        cx = line[0], cy = line[1], vx = line[2], vy = line[3];
    }
    double smin = INFINITY, smax = -INFINITY;
    for (int64_t k = 0; k < n; k++) {
        double s = xy[2 * idx[k]] * vx + xy[2 * idx[k] + 1] * vy;
        smin = s < smin ? s : smin;
        smax = s > smax ? s : smax;
    }
    double s0 = smin - (cx * vx + cy * vy), s1 = smax - (cx * vx + cy * vy);
    return push_chord(out, cx + s0 * vx, cy + s0 * vy, cx + s1 * vx, cy + s1 * vy);
}

/* _chords: the run's cells idx[0..n) with positions t along `line`, both ascending in t
 * (line NULL: fit the line and order the cells here, in w->sel / w->t). */
static int chords_of_run(const double *xy, int64_t *idx, double *t, int64_t n,
                         const double *line_in, const fit_cfg *cfg, scratch *w,
                         chord_out *out)
{
    double line[4];
    if (!line_in) {
        principal(xy, idx, n, line);
        double base = line[0] * line[2] + line[1] * line[3];
        for (int64_t k = 0; k < n; k++)
            t[k] = (xy[2 * idx[k]] * line[2] + xy[2 * idx[k] + 1] * line[3]) - base;
        by_key(idx, t, n, w->tmp_i, w->tmp_k);
    } else {
        memcpy(line, line_in, sizeof line);
    }
    double cx = line[0], cy = line[1], wx = line[2], wy = line[3];
    double t0 = t[0], t1 = t[n - 1];
    if (t1 - t0 < 2 * cfg->min_length)
        return push_chord(out, cx + t0 * wx, cy + t0 * wy, cx + t1 * wx, cy + t1 * wy);
    /* the path: means of the cells in bins two cells long */
    int64_t m = 0;
    double scale = 0.5 / cfg->cell;
    for (int64_t a = 0; a < n;) {
        int64_t bin = (int64_t)((t[a] - t0) * scale), b = a;
        double sx = 0, sy = 0, st = 0;
        while (b < n && (int64_t)((t[b] - t0) * scale) == bin) {
            sx += xy[2 * idx[b]];
            sy += xy[2 * idx[b] + 1];
            st += t[b];
            b++;
        }
        w->px[m] = sx / (double)(b - a);
        w->py[m] = sy / (double)(b - a);
        w->pt[m++] = st / (double)(b - a);
        a = b;
    }
    int64_t n_cuts = 0;
    douglas_peucker(w->px, w->py, w->pt, 0, m - 1, cfg, w->cuts, &n_cuts);
    if (!n_cuts)
        return piece_chord(xy, idx, n, line, cfg, w, out);
    /* the cuts come in order along the path (left, cut, right) */
    for (int64_t p = 0; p <= n_cuts; p++) {
        double lo = p == 0 ? t0 - 1.0 : w->pt[w->cuts[p - 1]];
        double hi = p == n_cuts ? t1 + 1.0 : w->pt[w->cuts[p]];
        int64_t first = 0, last = n;
        while (first < n && t[first] < lo)
            first++;
        last = first;
        while (last < n && t[last] <= hi)
            last++;
        if (last - first < 2)
            continue;
        if (piece_chord(xy, idx + first, last - first, NULL, cfg, w, out))
            return -1;
    }
    return 0;
}

/* Whether cell (x, y) lies within band of one of the chords c[0..nc). */
static int near_chords(double x, double y, const double *c, int64_t nc, double band)
{
    for (int64_t k = 0; k < nc; k++) {
        double ax = c[4 * k], ay = c[4 * k + 1];
        double dx = c[4 * k + 2] - ax, dy = c[4 * k + 3] - ay;
        double d2 = dx * dx + dy * dy;
        double safe = d2 > 0 ? d2 : 1.0;
        double rx = x - ax, ry = y - ay;
        double t = rx * (dx / safe) + ry * (dy / safe);
        t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
        rx -= t * dx;
        ry -= t * dy;
        if (rx * rx + ry * ry <= band * band)
            return 1;
    }
    return 0;
}

int64_t wall_refit(int64_t n_cells, const double *xy, int64_t n_lines, const double *lines,
                   double inlier, double reach, double max_gap, double gap_per_range,
                   double min_length, double cell, double chord_tol, double fit_band,
                   int64_t min_points, int64_t capacity, double *chords)
{
    fit_cfg cfg = {inlier, reach, max_gap, gap_per_range, min_length, cell, chord_tol,
                   fit_band, min_points};
    chord_out out = {chords, 0, capacity};
    int64_t N = n_cells > 0 ? n_cells : 1;
    uint8_t *free_ = malloc((size_t)N);
    int64_t *ibuf = malloc((size_t)N * 5 * sizeof(int64_t));
    double *dbuf = malloc((size_t)N * 6 * sizeof(double));
    int64_t rc = 0;
    if (!free_ || !ibuf || !dbuf) {
        rc = -2;
        goto done;
    }
    memset(free_, 1, (size_t)N);
    scratch w = {ibuf, ibuf + N, ibuf + 2 * N, ibuf + 3 * N, dbuf, dbuf + N, dbuf + 2 * N,
                 dbuf + 3 * N, dbuf + 4 * N};
    int64_t *run = ibuf + 4 * N;
    double *tt = dbuf + 5 * N;
    for (int64_t l = 0; l < n_lines; l++) {
        double ax = lines[4 * l], ay = lines[4 * l + 1], bx = lines[4 * l + 2], by = lines[4 * l + 3];
        double length = hypot(bx - ax, by - ay);
        double ox = ax, oy = ay, vx = (bx - ax) / length, vy = (by - ay) / length;
        double cx = 0, cy = 0, s0 = 0, fit[4];
        int flipped = 0;
        int64_t n_sel = 0;
        for (int it = 0; it < 2; it++) {
            double half = 0.5 * length;
            n_sel = 0;
            if (it == 0) { /* the band around the line as Hough gave it */
                double mx = ox + vx * half, my = oy + vy * half;
                double along0 = mx * vx + my * vy, perp0 = oy * vx - ox * vy;
                for (int64_t p = 0; p < n_cells; p++) {
                    double x = xy[2 * p], y = xy[2 * p + 1];
                    if (free_[p] && fabs((x * vx + y * vy) - along0) <= half + reach
                        && fabs((x * -vy + y * vx) - perp0) <= inlier)
                        w.sel[n_sel++] = p;
                }
            } else {
                double perp0 = oy * vx - ox * vy, along0 = ox * vx + oy * vy + half;
                for (int64_t p = 0; p < n_cells; p++) {
                    double x = xy[2 * p], y = xy[2 * p + 1];
                    if (free_[p] && fabs((x * -vy + y * vx) - perp0) <= inlier
                        && fabs((x * vx + y * vy) - along0) <= half + reach)
                        w.sel[n_sel++] = p;
                }
            }
            if (n_sel < min_points) {
                n_sel = 0;
                break;
            }
            principal(xy, w.sel, n_sel, fit);
            cx = fit[0], cy = fit[1];
            double wx = fit[2], wy = fit[3];
            flipped = wx * vx + wy * vy < 0;
            if (flipped)
                wx = -wx, wy = -wy;
            double smin = INFINITY, smax = -INFINITY;
            for (int64_t k = 0; k < n_sel; k++) {
                double s = xy[2 * w.sel[k]] * wx + xy[2 * w.sel[k] + 1] * wy;
                w.t[k] = s;
                smin = s < smin ? s : smin;
                smax = s > smax ? s : smax;
            }
            length = smax - smin;
            for (int64_t k = 0; k < n_sel; k++)
                w.t[k] -= smin; /* along the fitted line, from its first cell */
            s0 = smin - (cx * wx + cy * wy);
            ox = cx + s0 * wx, oy = cy + s0 * wy, vx = wx, vy = wy;
        }
        if (!n_sel)
            continue;
        by_key(w.sel, w.t, n_sel, w.tmp_i, w.tmp_k);
        int64_t *sel = w.sel;
        double *s = w.t;
        /* runs between gaps wider than the range there allows */
        int64_t lo = 0;
        for (int64_t k = 1; k <= n_sel; k++) {
            if (k < n_sel) {
                double gap = s[k] - s[k - 1];
                if (!(gap > max_gap))
                    continue;
                double mid = 0.5 * (s[k] + s[k - 1]);
                double allowed = max_gap + gap_per_range * hypot(ox + mid * vx, oy + mid * vy);
                if (!(gap > allowed))
                    continue;
            }
            int64_t hi = k, len = hi - lo;
            int64_t start = lo;
            lo = k;
            if (len < min_points || s[hi - 1] - s[start] < min_length)
                continue;
            /* the run's cells and positions, in their own buffers (chords_of_run sorts) */
            for (int64_t q = 0; q < len; q++)
                run[q] = sel[start + q];
            int64_t before = out.n;
            int r;
            if (len == n_sel) { /* one run of all the cells: the fit above is theirs */
                double line[4];
                if (flipped) { /* as principal gave it: the path starts at that end */
                    line[0] = cx, line[1] = cy, line[2] = -vx, line[3] = -vy;
                    for (int64_t q = 0; q < len; q++) {
                        run[q] = sel[start + len - 1 - q];
                        tt[q] = -(s[start + len - 1 - q] + s0);
                    }
                } else {
                    line[0] = cx, line[1] = cy, line[2] = vx, line[3] = vy;
                    for (int64_t q = 0; q < len; q++)
                        tt[q] = s[start + q] + s0;
                }
                r = chords_of_run(xy, run, tt, len, line, &cfg, &w, &out);
            } else {
                r = chords_of_run(xy, run, tt, len, NULL, &cfg, &w, &out);
            }
            if (r) {
                rc = -1;
                goto done;
            }
            int64_t nc = out.n - before;
            if (!nc)
                continue;
            /* claim only the cells on the chords: a perpendicular face's stay free */
            for (int64_t q = 0; q < len; q++) {
                int64_t p = run[q];
                if (near_chords(xy[2 * p], xy[2 * p + 1], chords + 4 * before, nc, fit_band))
                    free_[p] = 0;
            }
        }
    }
    rc = out.n;
done:
    free(free_);
    free(ibuf);
    free(dbuf);
    return rc;
}
