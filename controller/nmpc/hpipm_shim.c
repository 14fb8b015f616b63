/* The NMPC's QP, handed to HPIPM's OCP interior-point solver in one call.
 *
 * CasADi's conic interface to HPIPM spends about 1 ms a call turning a sparse QP into
 * stages; the OCP already comes in stages, so this shim passes the per-stage blocks
 * straight through. Layout (all column-major, all stages contiguous):
 *
 *   stage 0 has no state (x_0 is fixed, so its step is 0): x_1 = B_0 u_0 + b_0;
 *   stages k = 1..N-1: x_{k+1} = A_k x_k + B_k u_k + b_k;
 *   cost 1/2 x'diag(Q_k)x + q_k'x + 1/2 u'diag(R_k)u + r_k'u;
 *   box bounds on nbx state and nbu input components (fixed indices),
 *   lg_k <= C_k x_k <= ug_k on stages 1..N (no input terms).
 *
 * Built with the HPIPM and BLASFEO that ship inside the casadi Python package.
 */
#include <stdlib.h>
#include <string.h>

#include "hpipm_d_ocp_qp.h"
#include "hpipm_d_ocp_qp_dim.h"
#include "hpipm_d_ocp_qp_ipm.h"
#include "hpipm_d_ocp_qp_sol.h"

typedef struct {
    int N, nx, nu, ng, nbx, nbu;
    int *nx_k, *nu_k, *nbx_k, *nbu_k, *ng_k, *ns_k;
    int *idxbx, *idxbu;
    double *Qdense, *Rdense, *Sdense, *Ddense; /* per stage, built once */
    double **hA, **hB, **hb, **hQ, **hS, **hR, **hq, **hr, **hlbx, **hubx, **hlbu, **hubu;
    double **hC, **hD, **hlg, **hug;
    int **hidxbx, **hidxbu;
    void *dim_mem, *qp_mem, *sol_mem, *arg_mem, *ws_mem;
    struct d_ocp_qp_dim dim;
    struct d_ocp_qp qp;
    struct d_ocp_qp_sol sol;
    struct d_ocp_qp_ipm_arg arg;
    struct d_ocp_qp_ipm_ws ws;
} nmpc_qp;

#define ALLOC(ptr, n) ((ptr) = calloc((size_t)(n) > 0 ? (size_t)(n) : 1, sizeof(*(ptr))))

void nmpc_qp_free(nmpc_qp *h);

/* Q: (N+1) x nx diagonals (stage 0 ignored); R: N x nu diagonals. */
nmpc_qp *nmpc_qp_create(int N, int nx, int nu, int ng, int nbx, const int *idxbx, int nbu,
                        const int *idxbu, const double *Q, const double *R, int mode,
                        int iter_max, double tol, double mu0)
{
    nmpc_qp *h = calloc(1, sizeof(nmpc_qp));
    if (!h) return NULL;
    h->N = N; h->nx = nx; h->nu = nu; h->ng = ng; h->nbx = nbx; h->nbu = nbu;
    ALLOC(h->nx_k, N + 1); ALLOC(h->nu_k, N + 1); ALLOC(h->nbx_k, N + 1);
    ALLOC(h->nbu_k, N + 1); ALLOC(h->ng_k, N + 1); ALLOC(h->ns_k, N + 1);
    for (int k = 0; k <= N; k++) {
        h->nx_k[k] = k == 0 ? 0 : nx;
        h->nu_k[k] = k == N ? 0 : nu;
        h->nbx_k[k] = k == 0 ? 0 : nbx;
        h->nbu_k[k] = k == N ? 0 : nbu;
        h->ng_k[k] = k == 0 ? 0 : ng;
    }
    ALLOC(h->idxbx, nbx); memcpy(h->idxbx, idxbx, sizeof(int) * nbx);
    ALLOC(h->idxbu, nbu); memcpy(h->idxbu, idxbu, sizeof(int) * nbu);
    ALLOC(h->Qdense, (N + 1) * nx * nx); ALLOC(h->Rdense, N * nu * nu);
    ALLOC(h->Sdense, nu * nx); ALLOC(h->Ddense, ng * nu);
    for (int k = 0; k <= N; k++)
        for (int i = 0; i < nx; i++) h->Qdense[k * nx * nx + i * nx + i] = Q[k * nx + i];
    for (int k = 0; k < N; k++)
        for (int i = 0; i < nu; i++) h->Rdense[k * nu * nu + i * nu + i] = R[k * nu + i];

    ALLOC(h->hA, N + 1); ALLOC(h->hB, N + 1); ALLOC(h->hb, N + 1); ALLOC(h->hQ, N + 1);
    ALLOC(h->hS, N + 1); ALLOC(h->hR, N + 1); ALLOC(h->hq, N + 1); ALLOC(h->hr, N + 1);
    ALLOC(h->hlbx, N + 1); ALLOC(h->hubx, N + 1); ALLOC(h->hlbu, N + 1);
    ALLOC(h->hubu, N + 1); ALLOC(h->hC, N + 1); ALLOC(h->hD, N + 1); ALLOC(h->hlg, N + 1);
    ALLOC(h->hug, N + 1); ALLOC(h->hidxbx, N + 1); ALLOC(h->hidxbu, N + 1);
    for (int k = 0; k <= N; k++) {
        h->hQ[k] = h->Qdense + k * nx * nx;
        h->hR[k] = k < N ? h->Rdense + k * nu * nu : NULL;
        h->hS[k] = h->Sdense;
        h->hD[k] = h->Ddense;
        h->hidxbx[k] = h->idxbx;
        h->hidxbu[k] = h->idxbu;
    }

    h->dim_mem = malloc(d_ocp_qp_dim_memsize(N));
    d_ocp_qp_dim_create(N, &h->dim, h->dim_mem);
    d_ocp_qp_dim_set_all(h->nx_k, h->nu_k, h->nbx_k, h->nbu_k, h->ng_k, h->ns_k, &h->dim);
    h->qp_mem = malloc(d_ocp_qp_memsize(&h->dim));
    d_ocp_qp_create(&h->dim, &h->qp, h->qp_mem);
    h->sol_mem = malloc(d_ocp_qp_sol_memsize(&h->dim));
    d_ocp_qp_sol_create(&h->dim, &h->sol, h->sol_mem);
    h->arg_mem = malloc(d_ocp_qp_ipm_arg_memsize(&h->dim));
    d_ocp_qp_ipm_arg_create(&h->dim, &h->arg, h->arg_mem);
    d_ocp_qp_ipm_arg_set_default((enum hpipm_mode)mode, &h->arg);
    d_ocp_qp_ipm_arg_set_iter_max(&iter_max, &h->arg);
    d_ocp_qp_ipm_arg_set_tol_stat(&tol, &h->arg);
    d_ocp_qp_ipm_arg_set_tol_eq(&tol, &h->arg);
    d_ocp_qp_ipm_arg_set_tol_ineq(&tol, &h->arg);
    d_ocp_qp_ipm_arg_set_tol_comp(&tol, &h->arg);
    if (mu0 > 0) d_ocp_qp_ipm_arg_set_mu0(&mu0, &h->arg);
    h->ws_mem = malloc(d_ocp_qp_ipm_ws_memsize(&h->dim, &h->arg));
    d_ocp_qp_ipm_ws_create(&h->dim, &h->arg, &h->ws, h->ws_mem);
    return h;
}

/* One QP. A: N x nx x nx (stage 0 unused), B: N x nx x nu, b: N x nx, q: (N+1) x nx
 * (stage 0 unused), r: N x nu, lbx/ubx: (N+1) x nbx (stage 0 unused), lbu/ubu: N x nbu,
 * C: (N+1) x ng x nx and lg/ug: (N+1) x ng (stage 0 unused).
 * Out: x (N+1) x nx (stage 0 left at 0), u N x nu; info = [status, iterations];
 * res = max residuals [stationarity, equality, inequality, complementarity]. */
int nmpc_qp_solve(nmpc_qp *h, double *A, double *B, double *b, double *q, double *r,
                  double *lbx, double *ubx, double *lbu, double *ubu, double *C, double *lg,
                  double *ug, double *x, double *u, int *info, double *res)
{
    int N = h->N, nx = h->nx, nu = h->nu, ng = h->ng, nbx = h->nbx, nbu = h->nbu;
    for (int k = 0; k <= N; k++) {
        h->hA[k] = k < N ? A + k * nx * nx : NULL;
        h->hB[k] = k < N ? B + k * nx * nu : NULL;
        h->hb[k] = k < N ? b + k * nx : NULL;
        h->hq[k] = q + k * nx;
        h->hr[k] = k < N ? r + k * nu : NULL;
        h->hlbx[k] = lbx + k * nbx;
        h->hubx[k] = ubx + k * nbx;
        h->hlbu[k] = k < N ? lbu + k * nbu : NULL;
        h->hubu[k] = k < N ? ubu + k * nbu : NULL;
        h->hC[k] = C + k * ng * nx;
        h->hlg[k] = lg + k * ng;
        h->hug[k] = ug + k * ng;
    }
    d_ocp_qp_set_all(h->hA, h->hB, h->hb, h->hQ, h->hS, h->hR, h->hq, h->hr, h->hidxbx,
                     h->hlbx, h->hubx, h->hidxbu, h->hlbu, h->hubu, h->hC, h->hD, h->hlg,
                     h->hug, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, &h->qp);
    d_ocp_qp_ipm_solve(&h->qp, &h->sol, &h->arg, &h->ws);
    d_ocp_qp_ipm_get_status(&h->ws, &info[0]);
    d_ocp_qp_ipm_get_iter(&h->ws, &info[1]);
    d_ocp_qp_ipm_get_max_res_stat(&h->ws, &res[0]);
    d_ocp_qp_ipm_get_max_res_eq(&h->ws, &res[1]);
    d_ocp_qp_ipm_get_max_res_ineq(&h->ws, &res[2]);
    d_ocp_qp_ipm_get_max_res_comp(&h->ws, &res[3]);
    memset(x, 0, sizeof(double) * nx);
    for (int k = 1; k <= N; k++) d_ocp_qp_sol_get_x(k, &h->sol, x + k * nx);
    for (int k = 0; k < N; k++) d_ocp_qp_sol_get_u(k, &h->sol, u + k * nu);
    return info[0];
}

void nmpc_qp_free(nmpc_qp *h)
{
    if (!h) return;
    void *blocks[] = {h->nx_k, h->nu_k, h->nbx_k, h->nbu_k, h->ng_k, h->ns_k, h->idxbx,
                      h->idxbu, h->Qdense, h->Rdense, h->Sdense, h->Ddense, h->hA, h->hB,
                      h->hb, h->hQ, h->hS, h->hR, h->hq, h->hr, h->hlbx, h->hubx, h->hlbu,
                      h->hubu, h->hC, h->hD, h->hlg, h->hug, h->hidxbx, h->hidxbu,
                      h->dim_mem, h->qp_mem, h->sol_mem, h->arg_mem, h->ws_mem};
    for (size_t i = 0; i < sizeof(blocks) / sizeof(blocks[0]); i++) free(blocks[i]);
    free(h);
}
