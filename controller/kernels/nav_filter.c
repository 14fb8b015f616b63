/* The navigation EKF's prediction and updates (controller/navigation.py), on a state
 * x = [x, y, psi, u, v, r] and its 6 x 6 covariance P (row-major), both updated in place.
 * The same arithmetic as filterpy's ExtendedKalmanFilter with the strapdown prediction:
 * P = F P F' + Q; K = P H' S^-1; x += K y; P = (I - K H) P (I - K H)' + K R K'. */
#include <math.h>

#define N 6

static double wrap_angle(double a)
{
    /* numpy's (a + pi) % (2 pi) - pi: the remainder takes the divisor's sign */
    const double two_pi = 2.0 * M_PI;
    double m = fmod(a + M_PI, two_pi);
    if (m != 0.0) {
        if (m < 0.0)
            m += two_pi;
    } else {
        m = 0.0;
    }
    return m - M_PI;
}

/* out = A B (n x k times k x m) */
static void mul(const double *A, const double *B, double *out, int n, int k, int m)
{
    for (int i = 0; i < n; i++)
        for (int j = 0; j < m; j++) {
            double s = 0.0;
            for (int l = 0; l < k; l++)
                s += A[i * k + l] * B[l * m + j];
            out[i * m + j] = s;
        }
}

/* out = A B' (n x k times (m x k)') */
static void mul_t(const double *A, const double *B, double *out, int n, int k, int m)
{
    for (int i = 0; i < n; i++)
        for (int j = 0; j < m; j++) {
            double s = 0.0;
            for (int l = 0; l < k; l++)
                s += A[i * k + l] * B[j * k + l];
            out[i * m + j] = s;
        }
}

/* Propagate by dt with the body specific force (ax, ay); has_accel 0: coast (0, 0).
 * q_a, q_r: variances of the white acceleration on u, v and of r's random walk. */
void nav_predict(double *x, double *P, double dt, int has_accel, double ax, double ay,
                 double q_a, double q_r)
{
    double psi = x[2], u = x[3], v = x[4], r = x[5];
    double c = cos(psi), s = sin(psi);
    double F[N * N] = {0}, G[N * 3] = {0}, FP[N * N], Q[N * N];
    for (int i = 0; i < N; i++)
        F[i * N + i] = 1.0;
    F[0 * N + 2] = dt * (-s * u - c * v);
    F[0 * N + 3] = dt * c;
    F[0 * N + 4] = dt * -s;
    F[1 * N + 2] = dt * (c * u - s * v);
    F[1 * N + 3] = dt * s;
    F[1 * N + 4] = dt * c;
    F[2 * N + 5] = dt;
    F[3 * N + 4] = dt * r;
    F[3 * N + 5] = dt * v;
    F[4 * N + 3] = -dt * r;
    F[4 * N + 5] = -dt * u;
    double h = 0.5 * dt * dt;
    G[0 * 3 + 0] = h * c;
    G[0 * 3 + 1] = -h * s;
    G[1 * 3 + 0] = h * s;
    G[1 * 3 + 1] = h * c;
    G[3 * 3 + 0] = dt;
    G[4 * 3 + 1] = dt;
    G[2 * 3 + 2] = h;
    G[5 * 3 + 2] = dt;
    double q[3] = {q_a, q_a, q_r};
    for (int i = 0; i < N; i++)
        for (int j = 0; j < N; j++) {
            double sum = 0.0;
            for (int l = 0; l < 3; l++)
                sum += G[i * 3 + l] * q[l] * G[j * 3 + l];
            Q[i * N + j] = sum;
        }
    if (!has_accel)
        ax = ay = 0.0;
    x[0] = x[0] + dt * (c * u - s * v);
    x[1] = x[1] + dt * (s * u + c * v);
    x[2] = wrap_angle(psi + dt * r);
    x[3] = u + dt * (ax + r * v);
    x[4] = v + dt * (ay - r * u);
    mul(F, P, FP, N, N, N);
    mul_t(FP, F, P, N, N, N);
    for (int i = 0; i < N * N; i++)
        P[i] += Q[i];
}

/* One update with a 2-vector measurement z and its covariance R (2 x 2).
 * kind 0: NED position; 1: NED velocity; 2: heading and yaw rate (the heading taken
 * nearest the state's, the residual's heading and the state's heading wrapped). */
void nav_update(double *x, double *P, int kind, const double *z_in, const double *R)
{
    double H[2 * N] = {0}, hx[2], z[2] = {z_in[0], z_in[1]};
    double c = cos(x[2]), s = sin(x[2]), u = x[3], v = x[4];
    if (kind == 0) {
        H[0 * N + 0] = H[1 * N + 1] = 1.0;
        hx[0] = x[0];
        hx[1] = x[1];
    } else if (kind == 1) {
        H[0 * N + 2] = -s * u - c * v;
        H[0 * N + 3] = c;
        H[0 * N + 4] = -s;
        H[1 * N + 2] = c * u - s * v;
        H[1 * N + 3] = s;
        H[1 * N + 4] = c;
        hx[0] = c * u - s * v;
        hx[1] = s * u + c * v;
    } else {
        z[0] = x[2] + wrap_angle(z[0] - x[2]);
        H[0 * N + 2] = H[1 * N + 5] = 1.0;
        hx[0] = x[2];
        hx[1] = x[5];
    }
    double PHT[N * 2], S[4], SI[4], K[N * 2], y[2], IKH[N * N], T[N * N], KR[N * 2];
    mul_t(P, H, PHT, N, N, 2);
    mul(H, PHT, S, 2, N, 2);
    for (int i = 0; i < 4; i++)
        S[i] += R[i];
    double det = S[0] * S[3] - S[1] * S[2];
    SI[0] = S[3] / det;
    SI[1] = -S[1] / det;
    SI[2] = -S[2] / det;
    SI[3] = S[0] / det;
    mul(PHT, SI, K, N, 2, 2);
    y[0] = z[0] - hx[0];
    y[1] = z[1] - hx[1];
    if (kind == 2)
        y[0] = wrap_angle(y[0]);
    for (int i = 0; i < N; i++)
        x[i] += K[i * 2 + 0] * y[0] + K[i * 2 + 1] * y[1];
    if (kind == 2)
        x[2] = wrap_angle(x[2]);
    mul(K, H, IKH, N, 2, N);
    for (int i = 0; i < N * N; i++)
        IKH[i] = (i % (N + 1) == 0 ? 1.0 : 0.0) - IKH[i];
    mul(IKH, P, T, N, N, N);
    mul_t(T, IKH, P, N, N, N);
    mul(K, R, KR, N, 2, 2);
    mul_t(KR, K, T, N, 2, N);
    for (int i = 0; i < N * N; i++)
        P[i] += T[i];
}
