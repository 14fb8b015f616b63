/* The NMPC's QP, handed to HPIPM's OCP interior-point solver stage by stage.
 *
 * CasADi's conic interface to HPIPM spends about 1 ms a call turning a sparse QP into
 * stages; the OCP already comes in stages, so this shim passes the per-stage blocks
 * straight through. Layout (all column-major, all stages contiguous):
 *
 *   stage 0 has no state (x_0 is fixed, so its step is 0): x_1 = B_0 u_0 + b_0;
 *   stages k = 1..N-1: x_{k+1} = A_k x_k + B_k u_k + b_k;
 *   cost 1/2 x'diag(Q_k)x + q_k'x + 1/2 u'diag(R_k)u + r_k'u;
 *   box bounds on nbx state and nbu input components (fixed indices),
 *   lg_k <= C_k x_k <= ug_k on stages 1..N (no input terms), hard, or soft with an exact
 *   penalty: lg_k - sl_k <= C_k x_k, sl_k >= 0, costing soft_l1 * sl + soft_l2 / 2 * sl^2,
 *   so the QP is feasible whatever the rows ask, and its answer is the hard QP's whenever
 *   that one is feasible and soft_l1 exceeds its largest multiplier;
 *   some state bounds may be soft in every QP, hard rows or not (the surge cap: a plan may
 *   go faster than the reference allows, at a price), their upper slacks read apart.
 *
 * The blocks are bound once (`nmpc_qp_bind`, numpy arrays that live as long as the QP);
 * `nmpc_qp_set` copies a group of them for a range of stages into HPIPM's QP, so that the
 * RTI's preparation sets what it knows and the feedback only the few blocks the new state
 * changes; `nmpc_qp_solve` solves the QP as it is.
 *
 * HPIPM and BLASFEO are opened by path (`nmpc_qp_load`) with RTLD_DEEPBIND: two builds (the
 * one inside casadi and one tuned for the CPU) share the soname libhpipm.so, so linking by
 * name would give whichever the process loaded first. Compiled against the headers of the
 * build it opens (their structs differ between versions).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "hpipm_d_ocp_qp.h"
#include "hpipm_d_ocp_qp_dim.h"
#include "hpipm_d_ocp_qp_ipm.h"
#include "hpipm_d_ocp_qp_sol.h"

#define HPIPM_FUNCTIONS(X)                                                                   \
    X(d_ocp_qp_dim_memsize) X(d_ocp_qp_dim_create) X(d_ocp_qp_dim_set_nx)                    \
    X(d_ocp_qp_dim_set_nu) X(d_ocp_qp_dim_set_nbx) X(d_ocp_qp_dim_set_nbu)                   \
    X(d_ocp_qp_dim_set_ng) X(d_ocp_qp_memsize) X(d_ocp_qp_create) X(d_ocp_qp_set_A)          \
    X(d_ocp_qp_set_B) X(d_ocp_qp_set_b) X(d_ocp_qp_set_Q) X(d_ocp_qp_set_S)                  \
    X(d_ocp_qp_set_R) X(d_ocp_qp_set_q) X(d_ocp_qp_set_r) X(d_ocp_qp_set_idxbx)              \
    X(d_ocp_qp_set_lbx) X(d_ocp_qp_set_ubx) X(d_ocp_qp_set_idxbu) X(d_ocp_qp_set_lbu)        \
    X(d_ocp_qp_set_ubu) X(d_ocp_qp_set_C) X(d_ocp_qp_set_D) X(d_ocp_qp_set_lg)               \
    X(d_ocp_qp_set_ug) X(d_ocp_qp_sol_memsize) X(d_ocp_qp_sol_create) X(d_ocp_qp_sol_get_x)  \
    X(d_ocp_qp_sol_get_u) X(d_ocp_qp_ipm_arg_memsize) X(d_ocp_qp_ipm_arg_create)             \
    X(d_ocp_qp_ipm_arg_set_default) X(d_ocp_qp_ipm_arg_set_iter_max)                         \
    X(d_ocp_qp_ipm_arg_set_tol_stat) X(d_ocp_qp_ipm_arg_set_tol_eq)                          \
    X(d_ocp_qp_ipm_arg_set_tol_ineq) X(d_ocp_qp_ipm_arg_set_tol_comp)                        \
    X(d_ocp_qp_ipm_arg_set_mu0) X(d_ocp_qp_ipm_arg_set_warm_start) X(d_ocp_qp_ipm_ws_memsize) \
    X(d_ocp_qp_ipm_ws_create) X(d_ocp_qp_ipm_solve) X(d_ocp_qp_ipm_get_status)               \
    X(d_ocp_qp_ipm_get_iter) X(d_ocp_qp_ipm_get_max_res_stat)                                \
    X(d_ocp_qp_ipm_get_max_res_eq) X(d_ocp_qp_ipm_get_max_res_ineq)                          \
    X(d_ocp_qp_ipm_get_max_res_comp) X(d_ocp_qp_dim_set_ns) X(d_ocp_qp_set_idxs)               \
    X(d_ocp_qp_set_Zl) X(d_ocp_qp_set_Zu) X(d_ocp_qp_set_zl) X(d_ocp_qp_set_zu)               \
    X(d_ocp_qp_set_lls) X(d_ocp_qp_set_lus) X(d_ocp_qp_sol_get_sl) X(d_ocp_qp_sol_get_su)

#define DECLARE(name) __typeof__(&name) name;
static struct { HPIPM_FUNCTIONS(DECLARE) } F;
static void *blasfeo_handle, *hpipm_handle;
/* newer HPIPM counts soft general rows apart (nsg); older ones know only ns */
static void (*set_nsg)(int stage, int value, struct d_ocp_qp_dim *dim);
static void (*set_nsbx)(int stage, int value, struct d_ocp_qp_dim *dim);

/* Open BLASFEO then HPIPM by path and look the functions up: 0 on success, else the number
 * of the failing step (1, 2: a library; 3: a missing function). */
int nmpc_qp_load(const char *blasfeo_path, const char *hpipm_path)
{
    if (hpipm_handle) return 0;
    int flags = RTLD_NOW | RTLD_LOCAL | RTLD_DEEPBIND;
    blasfeo_handle = dlopen(blasfeo_path, flags);
    if (!blasfeo_handle) return 1;
    void *h = dlopen(hpipm_path, flags);
    if (!h) return 2;
#define LOOKUP(name) if (!(*(void **)&F.name = dlsym(h, #name))) return 3;
    HPIPM_FUNCTIONS(LOOKUP)
    *(void **)&set_nsg = dlsym(h, "d_ocp_qp_dim_set_nsg");
    *(void **)&set_nsbx = dlsym(h, "d_ocp_qp_dim_set_nsbx");
    hpipm_handle = h;
    return 0;
}

const char *nmpc_qp_load_error(void) { return dlerror(); }

typedef struct {
    int N, nx, nu, ng, nbx, nbu, ns, nsbx, nsg;
    int *idxbx, *idxbu, *idxs, *soft_bx;
    double *Zsoft, *zsoft, *zero, *sl, *su_bx, *slack;
    double *Qdense, *Rdense, *Sdense, *Ddense; /* per stage, built once */
    double *A, *B, *b, *q, *r, *lbx, *ubx, *lbu, *ubu, *C, *lg, *ug, *x, *u, *res;
    int *info;
    void *dim_mem, *qp_mem, *sol_mem, *arg_mem, *ws_mem;
    struct d_ocp_qp_dim dim;
    struct d_ocp_qp qp;
    struct d_ocp_qp_sol sol;
    struct d_ocp_qp_ipm_arg arg;
    struct d_ocp_qp_ipm_ws ws;
} nmpc_qp;

#define ALLOC(ptr, n) ((ptr) = calloc((size_t)(n) > 0 ? (size_t)(n) : 1, sizeof(*(ptr))))

void nmpc_qp_free(nmpc_qp *h);

/* Q: (N+1) x nx diagonals (stage 0 ignored); R: N x nu diagonals. warm_start: HPIPM's (0
 * none, 1 primal, 2 primal and dual from the previous solution). soft_l1 > 0: the general
 * rows are soft (exact penalty soft_l1 per unit, plus soft_l2 / 2 per unit squared); 0: hard.
 * soft_bx: nsbx positions in idxbx of state bounds that are soft in any case (stages 1..N),
 * at soft_bx_l1 and soft_bx_l2 likewise. Needs `nmpc_qp_load`. */
nmpc_qp *nmpc_qp_create(int N, int nx, int nu, int ng, int nbx, const int *idxbx, int nbu,
                        const int *idxbu, const double *Q, const double *R, int mode,
                        int iter_max, double tol, double mu0, int warm_start, double soft_l1,
                        double soft_l2, int nsbx, const int *soft_bx, double soft_bx_l1,
                        double soft_bx_l2)
{
    if (!hpipm_handle) return NULL;
    nmpc_qp *h = calloc(1, sizeof(nmpc_qp));
    if (!h) return NULL;
    h->N = N; h->nx = nx; h->nu = nu; h->ng = ng; h->nbx = nbx; h->nbu = nbu;
    h->nsg = soft_l1 > 0 ? ng : 0;
    h->nsbx = nsbx;
    h->ns = h->nsbx + h->nsg;
    int ns = h->ns;
    ALLOC(h->idxs, ns); ALLOC(h->Zsoft, ns); ALLOC(h->zsoft, ns); ALLOC(h->zero, ns);
    ALLOC(h->sl, (N + 1) * ng); ALLOC(h->su_bx, (N + 1) * nsbx); ALLOC(h->slack, ns);
    ALLOC(h->soft_bx, nsbx); memcpy(h->soft_bx, soft_bx, sizeof(int) * nsbx);
    for (int j = 0; j < nsbx; j++) { h->Zsoft[j] = soft_bx_l2; h->zsoft[j] = soft_bx_l1; }
    for (int j = nsbx; j < ns; j++) { h->Zsoft[j] = soft_l2; h->zsoft[j] = soft_l1; }
    ALLOC(h->idxbx, nbx); memcpy(h->idxbx, idxbx, sizeof(int) * nbx);
    ALLOC(h->idxbu, nbu); memcpy(h->idxbu, idxbu, sizeof(int) * nbu);
    ALLOC(h->Qdense, (N + 1) * nx * nx); ALLOC(h->Rdense, N * nu * nu);
    ALLOC(h->Sdense, nu * nx); ALLOC(h->Ddense, ng * nu);
    for (int k = 0; k <= N; k++)
        for (int i = 0; i < nx; i++) h->Qdense[k * nx * nx + i * nx + i] = Q[k * nx + i];
    for (int k = 0; k < N; k++)
        for (int i = 0; i < nu; i++) h->Rdense[k * nu * nu + i * nu + i] = R[k * nu + i];

    h->dim_mem = malloc(F.d_ocp_qp_dim_memsize(N));
    F.d_ocp_qp_dim_create(N, &h->dim, h->dim_mem);
    for (int k = 0; k <= N; k++) {
        F.d_ocp_qp_dim_set_nx(k, k == 0 ? 0 : nx, &h->dim);
        F.d_ocp_qp_dim_set_nu(k, k == N ? 0 : nu, &h->dim);
        F.d_ocp_qp_dim_set_nbx(k, k == 0 ? 0 : nbx, &h->dim);
        F.d_ocp_qp_dim_set_nbu(k, k == N ? 0 : nbu, &h->dim);
        F.d_ocp_qp_dim_set_ng(k, k == 0 ? 0 : ng, &h->dim);
        if (set_nsg && set_nsbx) {
            set_nsbx(k, k == 0 ? 0 : h->nsbx, &h->dim);
            set_nsg(k, k == 0 ? 0 : h->nsg, &h->dim);
        } else if (set_nsg && !h->nsbx) {
            set_nsg(k, k == 0 ? 0 : h->nsg, &h->dim);
        } else {
            F.d_ocp_qp_dim_set_ns(k, k == 0 ? 0 : h->ns, &h->dim);
        }
    }
    h->qp_mem = malloc(F.d_ocp_qp_memsize(&h->dim));
    F.d_ocp_qp_create(&h->dim, &h->qp, h->qp_mem);
    /* what never changes: the Hessian, the bounded indices, S = 0, D = 0 */
    for (int k = 0; k <= N; k++) {
        F.d_ocp_qp_set_Q(k, h->Qdense + k * nx * nx, &h->qp);
        if (k < N) {
            F.d_ocp_qp_set_R(k, h->Rdense + k * nu * nu, &h->qp);
            F.d_ocp_qp_set_S(k, h->Sdense, &h->qp);
            F.d_ocp_qp_set_idxbu(k, h->idxbu, &h->qp);
        }
        if (k > 0) {
            F.d_ocp_qp_set_idxbx(k, h->idxbx, &h->qp);
            F.d_ocp_qp_set_D(k, h->Ddense, &h->qp);
        }
        if (k > 0 && h->ns) { /* soft: the state bounds named, then the general rows, which
                                 come after the bounds (input bounds first, then state) */
            int after_bu = k < N ? nbu : 0;
            for (int j = 0; j < h->nsbx; j++) h->idxs[j] = after_bu + h->soft_bx[j];
            for (int j = 0; j < h->nsg; j++) h->idxs[h->nsbx + j] = after_bu + nbx + j;
            F.d_ocp_qp_set_idxs(k, h->idxs, &h->qp);
            F.d_ocp_qp_set_Zl(k, h->Zsoft, &h->qp);
            F.d_ocp_qp_set_Zu(k, h->Zsoft, &h->qp);
            F.d_ocp_qp_set_zl(k, h->zsoft, &h->qp);
            F.d_ocp_qp_set_zu(k, h->zsoft, &h->qp);
            F.d_ocp_qp_set_lls(k, h->zero, &h->qp);
            F.d_ocp_qp_set_lus(k, h->zero, &h->qp);
        }
    }
    h->sol_mem = malloc(F.d_ocp_qp_sol_memsize(&h->dim));
    F.d_ocp_qp_sol_create(&h->dim, &h->sol, h->sol_mem);
    h->arg_mem = malloc(F.d_ocp_qp_ipm_arg_memsize(&h->dim));
    F.d_ocp_qp_ipm_arg_create(&h->dim, &h->arg, h->arg_mem);
    F.d_ocp_qp_ipm_arg_set_default((enum hpipm_mode)mode, &h->arg);
    F.d_ocp_qp_ipm_arg_set_iter_max(&iter_max, &h->arg);
    F.d_ocp_qp_ipm_arg_set_tol_stat(&tol, &h->arg);
    F.d_ocp_qp_ipm_arg_set_tol_eq(&tol, &h->arg);
    F.d_ocp_qp_ipm_arg_set_tol_ineq(&tol, &h->arg);
    F.d_ocp_qp_ipm_arg_set_tol_comp(&tol, &h->arg);
    if (mu0 > 0) F.d_ocp_qp_ipm_arg_set_mu0(&mu0, &h->arg);
    F.d_ocp_qp_ipm_arg_set_warm_start(&warm_start, &h->arg);
    h->ws_mem = malloc(F.d_ocp_qp_ipm_ws_memsize(&h->dim, &h->arg));
    F.d_ocp_qp_ipm_ws_create(&h->dim, &h->arg, &h->ws, h->ws_mem);
    return h;
}

/* The arrays the blocks are read from and the solution written to. A: N x nx x nx (stage 0
 * unused), B: N x nx x nu, b: N x nx, q: (N+1) x nx (stage 0 unused), r: N x nu,
 * lbx/ubx: (N+1) x nbx (stage 0 unused), lbu/ubu: N x nbu, C: (N+1) x ng x nx and
 * lg/ug: (N+1) x ng (stage 0 unused); x: (N+1) x nx (stage 0 left at 0), u: N x nu;
 * info = [status, iterations]; res = max residuals [stat, eq, ineq, comp], then the
 * largest |x|, |u| of the solution (the step's size; NaN when an entry is NaN). */
void nmpc_qp_bind(nmpc_qp *h, double *A, double *B, double *b, double *q, double *r,
                  double *lbx, double *ubx, double *lbu, double *ubu, double *C, double *lg,
                  double *ug, double *x, double *u, int *info, double *res)
{
    h->A = A; h->B = B; h->b = b; h->q = q; h->r = r; h->lbx = lbx; h->ubx = ubx;
    h->lbu = lbu; h->ubu = ubu; h->C = C; h->lg = lg; h->ug = ug; h->x = x; h->u = u;
    h->info = info; h->res = res;
}

enum { SET_DYNAMICS = 1, SET_CONSTRAINTS = 2, SET_BOUNDS = 4, SET_GRADIENT = 8,
       SET_LOWER_CONSTRAINTS = 16 };

/* Copy the groups in `what` (a sum of the SET_ flags) of stages k0 <= k < k1 into the QP. */
void nmpc_qp_set(nmpc_qp *h, int what, int k0, int k1)
{
    int N = h->N, nx = h->nx, nu = h->nu, ng = h->ng, nbx = h->nbx, nbu = h->nbu;
    struct d_ocp_qp *qp = &h->qp;
    for (int k = k0; k < k1 && k <= N; k++) {
        if ((what & SET_DYNAMICS) && k < N) {
            if (k > 0) F.d_ocp_qp_set_A(k, h->A + k * nx * nx, qp);
            F.d_ocp_qp_set_B(k, h->B + k * nx * nu, qp);
            F.d_ocp_qp_set_b(k, h->b + k * nx, qp);
        }
        if (k > 0 && (what & SET_CONSTRAINTS)) {
            F.d_ocp_qp_set_C(k, h->C + k * ng * nx, qp);
            F.d_ocp_qp_set_ug(k, h->ug + k * ng, qp);
        }
        if (k > 0 && (what & (SET_CONSTRAINTS | SET_LOWER_CONSTRAINTS)))
            F.d_ocp_qp_set_lg(k, h->lg + k * ng, qp);
        if (what & SET_BOUNDS) {
            if (k > 0) {
                F.d_ocp_qp_set_lbx(k, h->lbx + k * nbx, qp);
                F.d_ocp_qp_set_ubx(k, h->ubx + k * nbx, qp);
            }
            if (k < N) {
                F.d_ocp_qp_set_lbu(k, h->lbu + k * nbu, qp);
                F.d_ocp_qp_set_ubu(k, h->ubu + k * nbu, qp);
            }
        }
        if (what & SET_GRADIENT) {
            if (k > 0) F.d_ocp_qp_set_q(k, h->q + k * nx, qp);
            if (k < N) F.d_ocp_qp_set_r(k, h->r + k * nu, qp);
        }
    }
}

/* Solve the QP as it is now; the result goes to the bound x, u, info and res. */
int nmpc_qp_solve(nmpc_qp *h)
{
    int N = h->N, nx = h->nx, nu = h->nu;
    F.d_ocp_qp_ipm_solve(&h->qp, &h->sol, &h->arg, &h->ws);
    F.d_ocp_qp_ipm_get_status(&h->ws, &h->info[0]);
    F.d_ocp_qp_ipm_get_iter(&h->ws, &h->info[1]);
    F.d_ocp_qp_ipm_get_max_res_stat(&h->ws, &h->res[0]);
    F.d_ocp_qp_ipm_get_max_res_eq(&h->ws, &h->res[1]);
    F.d_ocp_qp_ipm_get_max_res_ineq(&h->ws, &h->res[2]);
    F.d_ocp_qp_ipm_get_max_res_comp(&h->ws, &h->res[3]);
    memset(h->x, 0, sizeof(double) * nx);
    for (int k = 1; k <= N; k++) F.d_ocp_qp_sol_get_x(k, &h->sol, h->x + k * nx);
    for (int k = 0; k < N; k++) F.d_ocp_qp_sol_get_u(k, &h->sol, h->u + k * nu);
    for (int k = 1; k <= N && h->ns; k++) {
        if (h->nsg) {
            F.d_ocp_qp_sol_get_sl(k, &h->sol, h->slack);
            memcpy(h->sl + k * h->ng, h->slack + h->nsbx, sizeof(double) * h->nsg);
        }
        if (h->nsbx) {
            F.d_ocp_qp_sol_get_su(k, &h->sol, h->slack);
            memcpy(h->su_bx + k * h->nsbx, h->slack, sizeof(double) * h->nsbx);
        }
    }
    double largest = 0.0;
    int nan = 0;
    for (int i = 0; i < (N + 1) * nx + N * nu; i++) {
        double a = fabs(i < (N + 1) * nx ? h->x[i] : h->u[i - (N + 1) * nx]);
        if (a != a)
            nan = 1;
        else if (a > largest)
            largest = a;
    }
    h->res[4] = nan ? NAN : largest;
    return h->info[0];
}

/* Per-row weights of the soft general rows (ng each: the L1 and L2 penalties of row j at
 * every stage), replacing the uniform ones of `nmpc_qp_create`; nothing for hard rows. */
void nmpc_qp_soft_weights(nmpc_qp *h, const double *l1, const double *l2)
{
    if (!h->nsg) return;
    memcpy(h->zsoft + h->nsbx, l1, sizeof(double) * h->ng);
    memcpy(h->Zsoft + h->nsbx, l2, sizeof(double) * h->ng);
    for (int k = 1; k <= h->N; k++) {
        F.d_ocp_qp_set_Zl(k, h->Zsoft, &h->qp);
        F.d_ocp_qp_set_Zu(k, h->Zsoft, &h->qp);
        F.d_ocp_qp_set_zl(k, h->zsoft, &h->qp);
        F.d_ocp_qp_set_zu(k, h->zsoft, &h->qp);
    }
}

/* The lower slacks of the soft rows of the last solve: (N+1) x ng (stage 0 zeros), or
 * NULL when the rows are hard. */
const double *nmpc_qp_slack(const nmpc_qp *h)
{
    return h->nsg ? h->sl : NULL;
}

/* The upper slacks of the soft state bounds of the last solve: (N+1) x nsbx (stage 0
 * zeros), or NULL when there are none. */
const double *nmpc_qp_bound_slack(const nmpc_qp *h)
{
    return h->nsbx ? h->su_bx : NULL;
}

void nmpc_qp_free(nmpc_qp *h)
{
    if (!h) return;
    void *blocks[] = {h->idxs, h->Zsoft, h->zsoft, h->zero, h->sl, h->su_bx, h->slack,
                      h->soft_bx, h->idxbx, h->idxbu, h->Qdense, h->Rdense, h->Sdense, h->Ddense,
                      h->dim_mem, h->qp_mem, h->sol_mem, h->arg_mem, h->ws_mem};
    for (size_t i = 0; i < sizeof(blocks) / sizeof(blocks[0]); i++) free(blocks[i]);
    free(h);
}
