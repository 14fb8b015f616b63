/* The distance from each point to the nearest of many segments (legs of polylines):
 * geometry.point_segment_distance(points, a, b).min(axis=1) in the same operations and order
 * (the projection clipped to the leg, then the length of the offset), without the (N, M)
 * arrays. The clearance metric asks it of the true walls every control step. */
#include <math.h>
#include <stdint.h>

void nearest_leg(int64_t n, const double *p, int64_t m, const double *a, const double *b,
                 double *out)
{
    for (int64_t i = 0; i < n; i++) {
        double px = p[2 * i], py = p[2 * i + 1], best = INFINITY;
        for (int64_t j = 0; j < m; j++) {
            double ax = a[2 * j], ay = a[2 * j + 1];
            double abx = b[2 * j] - ax, aby = b[2 * j + 1] - ay;
            double denom = abx * abx + aby * aby;
            double t = ((px - ax) * abx + (py - ay) * aby) / (denom > 0.0 ? denom : 1.0);
            t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
            double dx = px - (ax + t * abx), dy = py - (ay + t * aby);
            double d = sqrt(dx * dx + dy * dy);
            if (d < best || j == 0)
                best = d;
        }
        out[i] = best;
    }
}
