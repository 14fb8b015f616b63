"""Sequential quadratic programming on the OCP: one step per control period (real-time
iteration, as the paper's ACADO RTI), or iterated to convergence.

Each SQP step solves the Gauss-Newton QP around the current guess w:

    min_dw  1/2 dw' H dw + (H (w - w_ref))' dw
    s.t.    lbg - g(w) <= J(w) dw <= ubg - g(w),   lbw - w <= dw <= ubw - w

The cost is a sum of weighted squares, so H is constant and Gauss-Newton is its exact Hessian.
g and J come from one CasADi Function (compiled C when possible, see `codegen_cache`), called
through `Function.buffer()`, which skips CasADi's argument conversion (about 60 us a call from
numpy, against 3 us).
"""

from __future__ import annotations

import subprocess
import time
import warnings
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from ..errors import InputError
from .hpipm_qp import (SET_BOUNDS, SET_CONSTRAINTS, SET_DYNAMICS, SET_GRADIENT, STATUS,
                       HPIPM_BUILDS)
from .problem import NU, NX, Ocp

QP_SOLVERS = ("hpipm", "hpipm-casadi", "piqp")
"""hpipm: HPIPM's OCP solver called directly with the stage blocks (`hpipm_qp`);
hpipm-casadi and piqp: through CasADi's conic interface, from the sparse QP."""


@dataclass(frozen=True)
class QpOptions:
    """The QP solver and its settings (measured choices, see `canalnav bench nmpc`)."""

    solver: str = "hpipm"
    hpipm_mode: str = "speed_abs"  # absolute IPM: about half the iterations of "speed" here
    tol: float = 1e-4  # on HPIPM's residuals (direct hpipm only); 1e-6 costs 3 more iterations
    warm_start: int = 0  # HPIPM's warm start (direct hpipm only): 0 none, 1 primal, 2 primal-dual
    hpipm_build: str = "auto"  # which HPIPM + BLASFEO (`hpipm_qp.HPIPM_BUILDS`): "auto" takes
    # the one tuned for the CPU when installed, else casadi's
    mu0: float = 0.0  # HPIPM's initial barrier (direct hpipm only); 0: its default (1e3 was
    # better on one QP but took 7.2 iterations against 5.6 over the bench run)
    iter_max: int = 50
    inf: float = 1e4  # stand-in for a missing bound; CasADi's default 1e8 breaks hpipm

    def __post_init__(self) -> None:
        if self.solver not in QP_SOLVERS:
            raise InputError(f"QP solver {self.solver!r}: choose one of {', '.join(QP_SOLVERS)}")
        if self.iter_max < 1:
            raise InputError(f"QP iter_max: must be positive, got {self.iter_max!r}")
        if self.warm_start not in (0, 1, 2):
            raise InputError(f"QP warm_start: 0, 1 or 2, got {self.warm_start!r}")
        if self.hpipm_build not in HPIPM_BUILDS:
            raise InputError(f"QP hpipm_build {self.hpipm_build!r}: choose one of "
                             f"{', '.join(HPIPM_BUILDS)}")
        if not self.tol > 0:
            raise InputError(f"QP tol: must be positive, got {self.tol!r}")


@dataclass(frozen=True)
class QpStepResult:
    """One SQP step: the step dw, whether the QP solver vouched for it, and what it cost."""

    dw: np.ndarray
    ok: bool
    status: str
    qp_iterations: int
    time_linearisation_s: float
    time_qp_s: float
    step_norm: float | None = None  # max |dw_i| (NaN: an entry is NaN), when known


def _bind(function: ca.Function, inputs: list[np.ndarray]):
    """A buffer of `function` bound to numpy arrays: write the inputs in place, then call."""
    buf, trigger = function.buffer()
    for i, array in enumerate(inputs):
        buf.set_arg(i, memoryview(array))
    outputs = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
    for i, array in enumerate(outputs):
        buf.set_res(i, memoryview(array))
    return buf, trigger, outputs


class QpStep:
    """The linearise-and-solve step of SQP, with its buffers set up once."""

    def __init__(self, ocp: Ocp, linearisation: ca.Function, options: QpOptions = QpOptions(),
                 compile=None):
        """compile(Function) -> Function: the compiled form of the direct HPIPM path's
        linearisations (default: interpreted)."""
        self.ocp, self.options = ocp, options
        compile = compile or (lambda f: f)
        N, n = ocp.N, ocp.nw
        self.hessian = ocp.hessian()
        self.lbg, self.ubg = ocp.constraint_bounds()
        self.states_at, self.inputs_at = ocp.states_at, ocp.inputs_at
        self.x0_at = self.states_at[0]

        # linearisation: (w, p) -> stagewise pieces; keep the Function alive with its buffer
        self.linearisation = linearisation
        self.w = np.zeros(n)
        self.p = np.zeros(linearisation.nnz_in(1))
        self._lin_buf, self._lin, self.pieces = _bind(linearisation, [self.w, self.p])

        # the plan's soft surge ceiling per stage (`problem.surge_cap`), set by the caller
        # before each solve; only the direct HPIPM path has soft bounds to give it
        self.surge_soft = False
        self.surge_cap = np.full(N + 1, options.inf)
        self._u_at = ocp.states_at[:, 3]
        self._surge = np.zeros(N + 1)
        if options.solver == "hpipm":
            self._hpipm_lin = compile(ocp.hpipm_linearisation)
            self._first_stage = compile(ocp.first_stage)
            self._hpipm_clearance = compile(ocp.hpipm_clearance)
            try:
                self._init_hpipm()
            except (OSError, subprocess.CalledProcessError) as exc:
                detail = (getattr(exc, "stderr", "") or str(exc)).strip()[:300]
                warnings.warn(f"cannot build the direct HPIPM interface ({detail}); using "
                              "CasADi's (about 1 ms slower a step)", RuntimeWarning,
                              stacklevel=2)
                self.options = replace(options, solver="hpipm-casadi")
                self.surge_soft = False
                self._init_conic()
        else:
            self._init_conic()

    # -- HPIPM directly, stage by stage -------------------------------------------------------
    def _init_hpipm(self) -> None:
        from .hpipm_qp import HpipmOcpQp, choose_build

        ocp, o = self.ocp, self.options
        N, nx, nu, nh = ocp.N, NX, NU, ocp.n_h
        c = ocp.config
        # nT, nS, slack; and the surge, a soft ceiling in every QP (`surge_cap`)
        self.surge_soft = c.surge_margin_mps is not None
        self.bounded_states = np.array([3, 6, 7, 8] if self.surge_soft else [6, 7, 8])
        soft = dict(soft_bounds=[0], soft_bound_l1=c.surge_l1,
                    soft_bound_l2=c.surge_l2) if self.surge_soft else {}
        build = choose_build(o.hpipm_build)
        args = (N, nx, nu, nh, self.bounded_states, np.arange(nu),
                self.hessian[self.states_at], self.hessian[self.inputs_at], o.hpipm_mode,
                o.iter_max, o.tol, o.mu0, o.warm_start, build)
        self.qp = HpipmOcpQp(*args, **soft)
        self.qp.ug[:] = o.inf
        # The elastic QP: the same blocks (it reads the hard QP's arrays) with the obstacle
        # rows soft, solved only where the hard one fails (`_hpipm_result`). Elastic rows
        # cost the IPM about three times the iterations, so they are not the default path;
        # where the hard QP solves, the answer is exactly the hard one.
        self.elastic_qp = None
        if c.obstacle_rows == "exact-penalty":
            self.elastic_qp = HpipmOcpQp(*args, soft_l1=c.obstacle_l1, soft_l2=c.obstacle_l2,
                                         **soft)
            # rows: both circles' segment slots, then their vessel slots; a wall is where
            # it is, another boat's hull is a prediction grown by its uncertainty: where
            # not all can hold, the vessel rows give first (`vessel_l1_share`)
            n_seg = 2 * c.segment_slots
            share = np.ones(nh)
            share[n_seg:] = c.vessel_l1_share
            self.elastic_qp.soft_weights(c.obstacle_l1 * share, c.obstacle_l2 * share)
            # (`_bind_hpipm` makes it read the hard QP's arrays)
        self.elastic_used = False
        self._bind_hpipm()
        self._solve = self._solve_hpipm

    def _bind_hpipm(self) -> None:
        """Function buffers that write the QP's blocks straight into its arrays: the whole
        horizon at w, and stage 0 alone (the feedback's part)."""
        qp, N, nx, nu = self.qp, self.ocp.N, NX, NU
        self._bound_qp = qp
        if getattr(self, "elastic_qp", None) is not None:
            self.elastic_qp.share_arrays(qp)
        self._hl_w, self._hl_p = np.zeros(self.ocp.nw), np.zeros(self.p.size)
        outs = [qp.b, qp.A, qp.B, qp.lg[1:], qp.C[1:]]
        self._hl_buf, self._hl = self._bind_out(self._hpipm_lin, [self._hl_w, self._hl_p], outs)
        self._fs_x0, self._fs_u0, self._fs_x1 = np.zeros(nx), np.zeros(nu), np.zeros(nx)
        outs = [qp.b[0], qp.A[0], qp.B[0]]
        self._fs_buf, self._fs = self._bind_out(
            self._first_stage, [self._fs_x0, self._fs_u0, self._fs_x1, self._hl_p], outs)
        self._cl_buf, self._cl = self._bind_out(self._hpipm_clearance,
                                                [self._hl_w, self._hl_p], [qp.lg[1:], qp.C[1:]])
        self._dyn_p = self.ocp.dynamics_params
        self._grad = np.zeros(self.ocp.nw)
        self._lo, self._hi = np.zeros(self.ocp.nw), np.zeros(self.ocp.nw)
        self._dw = np.zeros(self.ocp.nw)
        # w's stages as rows [x_k, u_k] (x_N alone at the end): the QP's solution is written
        # into them by slices, in a third of the time of index arrays
        nz = nx + nu
        rows = self._dw[:N * nz].reshape(N, nz)
        self._dw_x, self._dw_u, self._dw_last = rows[:, :nx], rows[:, nx:], self._dw[N * nz:]
        assert (self.states_at[:N] == np.arange(N * nz).reshape(N, nz)[:, :nx]).all() \
            and (self.inputs_at == np.arange(N * nz).reshape(N, nz)[:, nx:]).all() \
            and (self.states_at[N] == np.arange(N * nz, N * nz + nx)).all()
        self._bx_at = self.states_at[:, self.bounded_states]
        self._x1_at, self._u0_at = self.states_at[1], self.inputs_at[0]
        self.prepared = False

    @staticmethod
    def _bind_out(function: ca.Function, inputs, outputs):
        buf, trigger = function.buffer()
        for i, array in enumerate(inputs):
            buf.set_arg(i, memoryview(array))
        for i, array in enumerate(outputs):
            assert array.flags.c_contiguous and array.size == function.nnz_out(i)
            buf.set_res(i, memoryview(array.reshape(-1)))
        return buf, trigger

    def _linearise_hpipm(self, w, p) -> None:
        if self._bound_qp is not self.qp:  # the QP was swapped (tests): bind the new one
            self._bind_hpipm()
        self._hl_w[:] = w
        self._hl_p[:] = p
        self._hl()

    def _set_bounds(self, w, lbw, ubw) -> None:
        qp = self.qp
        np.subtract(lbw, w, out=self._lo)
        np.subtract(ubw, w, out=self._hi)
        self._lo.take(self._bx_at, out=qp.lbx)  # the method: a third of np.take's time
        self._hi.take(self._bx_at, out=qp.ubx)
        self._lo.take(self.inputs_at, out=qp.lbu)
        self._hi.take(self.inputs_at, out=qp.ubu)
        if self.surge_soft:  # (the OCP's own surge bounds are infinite)
            qp.lbx[:, 0] = -self.options.inf
            self._set_surge_cap(w)

    def _set_surge_cap(self, w) -> None:
        w.take(self._u_at, out=self._surge)
        np.subtract(self.surge_cap, self._surge, out=self.qp.ubx[:, 0])

    def _set_gradient(self, w, w_ref) -> None:
        qp = self.qp
        np.subtract(w, w_ref, out=self._grad)
        np.multiply(self.hessian, self._grad, out=self._grad)
        self._grad.take(self.states_at, out=qp.q)
        self._grad.take(self.inputs_at, out=qp.r)

    def _solve_hpipm(self, w, w_ref, lbw, ubw) -> tuple[np.ndarray, bool, str, int]:
        """The QP at w, all of it set afresh (the pieces are linearised at w)."""
        self.prepared = False  # the blocks are now those of w
        self._set_bounds(w, lbw, ubw)
        self._set_gradient(w, w_ref)
        self.qp.set(SET_DYNAMICS | SET_CONSTRAINTS | SET_BOUNDS | SET_GRADIENT)
        return self._hpipm_result()

    def _hpipm_result(self) -> tuple[np.ndarray, bool, str, int]:
        qp = self.qp
        status, iterations = qp.solve()
        self.elastic_used = False
        if status != 0 and self.elastic_qp is not None:  # no feasible point, or no
            # convergence near one: the same QP with elastic obstacle rows, all of it set
            self.elastic_qp.set(SET_DYNAMICS | SET_CONSTRAINTS | SET_BOUNDS | SET_GRADIENT)
            status, more = self.elastic_qp.solve()
            iterations += more
            self.elastic_used = True
        x = qp.x
        self._dw_x[1:] = x[1:-1]  # (x_0's step stays 0: x_0 is fixed)
        self._dw_u[:] = qp.u
        self._dw_last[:] = x[-1]
        return self._dw.copy(), status == 0, STATUS.get(status, str(status)), iterations

    # -- the real-time iteration split: preparation, then feedback ---------------------------
    def prepare(self, w: np.ndarray, p: np.ndarray, lbw: np.ndarray, ubw: np.ndarray,
                w_ref: np.ndarray | None = None) -> bool:
        """Linearise at the guess w (x_0 there is the predicted state) with parameters p and
        set up the QP but for stage 0's dynamics, and the gradient if w_ref is given (it
        does not depend on x_0: stage 0 has no state in the QP). False when the QP solver
        does not split (CasADi's conic ones): `feedback` then does everything."""
        if self._solve != self._solve_hpipm:
            return False
        self._linearise_hpipm(w, p)
        self._set_bounds(w, lbw, ubw)
        self.qp.set(SET_DYNAMICS | SET_CONSTRAINTS | SET_BOUNDS, 1)
        # stage 0's input bounds too (u_0 is the guess's, which the feedback keeps): left
        # out, the QP kept those of the last full solve, around an older u_0, and the step's
        # first move could break its rate limits once the plan changed enough (a way that
        # opens: the prepared QP failed where the one-phase step did not)
        self.qp.set(SET_BOUNDS, 0, 1)
        if w_ref is not None:
            self._set_gradient(w, w_ref)
            self.qp.set(SET_GRADIENT)
        self.prepared = True
        return True

    def can_feed_back(self, w: np.ndarray, p: np.ndarray) -> bool:
        """The prepared QP serves w and p: prepared at the same w but for x_0 (which the
        feedback embeds), with the same dynamics parameters (boat, current, bias; other
        segments or vessels only make the feedback linearise the obstacle rows anew)."""
        if not self.prepared or self._bound_qp is not self.qp:
            return False
        dyn = self._dyn_p
        return bool((w[NX:] == self._hl_w[NX:]).all() and (p[dyn] == self._hl_p[dyn]).all())

    def feedback(self, w: np.ndarray, p: np.ndarray,
                 w_ref: np.ndarray | None) -> QpStepResult:
        """The QP prepared at w but for x_0: stage 0 linearised at the new x_0 (as `solve`
        does), the obstacle rows anew if p's segments or vessels changed, the gradient from
        w_ref (None: the one `prepare` set, and p the one it was given), one solve: the QP
        `solve` would set up. Needs `can_feed_back(w, p)`. dw is HPIPM's, unchecked: the
        caller checks that it is finite (step_norm, its largest entry, is then finite)."""
        t0 = time.perf_counter()
        if w_ref is not None and not (p == self._hl_p).all():
            self._hl_p[:] = p
            self._cl()
            self.qp.set(SET_CONSTRAINTS, 1)
        if w_ref is not None and self.surge_soft:  # a new setup: its surge ceiling
            self._set_surge_cap(w)
            self.qp.set(SET_BOUNDS, 1)
        self._fs_x0[:] = w[:NX]  # (x_0 leads w)
        w.take(self._u0_at, out=self._fs_u0)
        w.take(self._x1_at, out=self._fs_x1)
        self._fs()
        t1 = time.perf_counter()
        if w_ref is None:
            self.qp.set(SET_DYNAMICS, 0, 1)
        else:
            self._set_gradient(w, w_ref)
            self.qp.set(SET_DYNAMICS | SET_GRADIENT, 0, 1)
            self.qp.set(SET_GRADIENT, 1)
        self.prepared = False  # stage 0 and the gradient are now this state's
        dw, ok, status, iterations = self._hpipm_result()
        t2 = time.perf_counter()
        return QpStepResult(dw, ok, status, iterations, t1 - t0, t2 - t1,
                            self.qp.largest_entry())

    def elastic(self) -> tuple[float, float]:
        """How far the last QP's obstacle rows were violated, in units of h: the largest
        slack over the horizon of the segment rows and of the vessel rows; (0, 0) when the
        hard QP solved (or the rows are hard: another QP solver, `obstacle_rows = "hard"`)."""
        qp = getattr(self, "elastic_qp", None)
        if qp is None or not self.elastic_used or self._solve != self._solve_hpipm:
            return 0.0, 0.0
        n_seg = 2 * self.ocp.config.segment_slots  # rows: both circles' segments, then vessels
        sl = qp.slack
        return float(sl[:, :n_seg].max(initial=0.0)), float(sl[:, n_seg:].max(initial=0.0))

    # -- any QP solver through CasADi's conic interface ---------------------------------------
    def _init_conic(self) -> None:
        ocp, o = self.ocp, self.options
        qp = {"h": ca.Sparsity.diag(ocp.nw), "a": ocp.jac_sparsity}
        opts: dict = {"error_on_fail": False}
        if o.solver == "hpipm-casadi":
            opts.update(ocp.hpipm_structure())
            opts.update({"inf": o.inf, "hpipm": {"mode": o.hpipm_mode, "iter_max": o.iter_max}})
            plugin = "hpipm"
        else:
            opts.update({"piqp": {"max_iter": o.iter_max}})
            plugin = "piqp"
        # called the ordinary way: a Function buffer of this solver corrupts the heap (CasADi
        # 3.8.2), and converting the arguments costs about 1 ms a call
        self.solver = ca.conic("nmpc_qp", plugin, qp, opts)
        self._h = ca.DM(ca.Sparsity.diag(ocp.nw), self.hessian)
        self._solve = self._solve_conic

    def _solve_conic(self, w, w_ref, lbw, ubw) -> tuple[np.ndarray, bool, str, int]:
        g, jac_nz = self.ocp.assemble(*self.pieces)
        out = self.solver(h=self._h, g=self.hessian * (w - w_ref),
                          a=ca.DM(self.ocp.jac_sparsity, jac_nz), lba=self.lbg - g,
                          uba=self.ubg - g, lbx=lbw - w, ubx=ubw - w)
        stats = self.solver.stats()
        status = str(stats.get("return_status", stats.get("unified_return_status", "")))
        return (np.asarray(out["x"]).ravel(), bool(stats.get("success", False)), status,
                int(stats.get("iter_count", -1)))

    # -- the merit of a guess ------------------------------------------------------------------
    def merit(self, w: np.ndarray, p: np.ndarray, w_ref: np.ndarray,
              weight: float) -> tuple[float, float]:
        """(cost + weight * infeasibility, infeasibility): the L1 merit of SQP's line search."""
        self.w[:] = w
        self.p[:] = p
        self._lin()
        gaps, _, h, _ = self.pieces
        infeasibility = float(np.abs(gaps).sum() + np.maximum(-h, 0.0).sum())
        e = w - w_ref
        return 0.5 * float(e @ (self.hessian * e)) + weight * infeasibility, infeasibility

    # -- the step -----------------------------------------------------------------------------
    def solve(self, w: np.ndarray, p: np.ndarray, w_ref: np.ndarray, lbw: np.ndarray,
              ubw: np.ndarray) -> QpStepResult:
        """One Gauss-Newton step from w. x_0 is fixed by lbw = ubw; w's x_0 is set to it."""
        t0 = time.perf_counter()
        w_caller, w = w, np.array(w, float)
        w[self.x0_at] = lbw[self.x0_at]
        if self._solve == self._solve_hpipm:
            self._linearise_hpipm(w, p)
        else:
            self.w[:] = w
            self.p[:] = p
            self._lin()
        t1 = time.perf_counter()
        dw, ok, status, iterations = self._solve(w, w_ref, lbw, ubw)
        t2 = time.perf_counter()
        ok = ok and bool(np.isfinite(dw).all())
        return QpStepResult(dw + (w - w_caller), ok, status, iterations, t1 - t0, t2 - t1)

@dataclass(frozen=True)
class SqpResult:
    """The outcome of one solve of the OCP by SQP (one step for RTI)."""

    w: np.ndarray
    ok: bool
    converged: bool
    status: str
    sqp_iterations: int
    qp_iterations: int
    step_norm: float
    time_linearisation_s: float
    time_qp_s: float


MERIT_WEIGHT = 1e5
"""L1 penalty on constraint violation in SQP's merit: above the largest multiplier seen here
(slack weight 1e4 per m^2, terminal heading weight 2.5e4)."""


def sqp(step: QpStep, w: np.ndarray, p: np.ndarray, w_ref: np.ndarray, lbw: np.ndarray,
        ubw: np.ndarray, max_iter: int = 1, tol: float = 1e-4) -> SqpResult:
    """Gauss-Newton SQP from w: max_iter=1 is the real-time iteration (one full step).

    Iterated, it backtracks along each step on an L1 merit function (full steps alone can
    cycle near active obstacle constraints), and has converged when the largest component of
    the accepted step is below `tol`. A QP failing on the first iteration returns ok=False; on a
    later one, the last accepted iterate (ok=True, not converged, the failure in the status).
    """
    w = np.array(w, float)
    x0 = step.x0_at
    w[x0] = lbw[x0]
    t_lin = t_qp = 0.0
    qp_iters, norm, status = 0, np.inf, ""
    for k in range(1, max_iter + 1):
        r = step.solve(w, p, w_ref, lbw, ubw)
        t_lin += r.time_linearisation_s
        t_qp += r.time_qp_s
        qp_iters += max(r.qp_iterations, 0)
        status = r.status
        if not r.ok:
            if k > 1:  # keep the last accepted iterate: at least as good as a real-time iteration
                return SqpResult(w, True, False, f"QP failed ({r.status}) at iteration {k}; "
                                 f"kept iterate {k - 1}", k, qp_iters, norm, t_lin, t_qp)
            return SqpResult(w, False, False, f"QP failed ({r.status})", k, qp_iters, norm,
                             t_lin, t_qp)
        alpha = 1.0
        if max_iter > 1:
            t0 = time.perf_counter()
            phi, infeasibility = step.merit(w, p, w_ref, MERIT_WEIGHT)
            e = w - w_ref
            slope = float((step.hessian * e) @ r.dw) - MERIT_WEIGHT * infeasibility
            while alpha > 1.0 / 64:
                trial, _ = step.merit(w + alpha * r.dw, p, w_ref, MERIT_WEIGHT)
                if trial <= phi + 1e-4 * alpha * min(slope, 0.0):
                    break
                alpha *= 0.5
            t_lin += time.perf_counter() - t0
        w = w + alpha * r.dw
        norm = float(np.max(np.abs(alpha * r.dw)))
        if norm < tol:
            return SqpResult(w, True, True, status, k, qp_iters, norm, t_lin, t_qp)
    return SqpResult(w, True, False, status, max_iter, qp_iters, norm, t_lin, t_qp)
