"""IPOPT on the same NLP as the SQP solvers: the reference the real-time iteration is
measured against (CasADi's interpreted functions, exact Hessian, as a do-mpc user runs it)."""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from .problem import Ocp
from .rti import SqpResult


class IpoptSolver:
    """min 1/2 (w - w_ref)' H (w - w_ref) s.t. g(w, p) within bounds, by IPOPT."""

    def __init__(self, ocp: Ocp, max_iter: int = 500, tol: float = 1e-8):
        self.ocp = ocp
        # SX throughout (the shooting intervals inlined), as a do-mpc user builds it: CasADi's
        # exact Hessian through MX maps is ~50x slower here
        constraints = ocp.constraints.expand()
        w = ca.SX.sym("w", ocp.nw)
        p = ca.SX.sym("p", ocp.linearisation.nnz_in(1))
        w_ref = ca.SX.sym("w_ref", ocp.nw)
        e = w - w_ref
        cost = 0.5 * ca.dot(e, ocp.hessian() * e)
        nlp = {"x": w, "p": ca.vertcat(p, w_ref), "f": cost, "g": constraints(w, p)}
        opts = {"print_time": False, "error_on_fail": False,
                "ipopt": {"print_level": 0, "max_iter": max_iter, "tol": tol,
                          "sb": "yes"}}
        self.solver = ca.nlpsol("nmpc_ipopt", "ipopt", nlp, opts)
        self.lbg, self.ubg = ocp.constraint_bounds()

    def solve(self, w: np.ndarray, p: np.ndarray, w_ref: np.ndarray, lbw: np.ndarray,
              ubw: np.ndarray) -> SqpResult:
        t0 = time.perf_counter()
        r = self.solver(x0=w, p=np.concatenate([p, w_ref]), lbx=lbw, ubx=ubw,
                        lbg=self.lbg, ubg=self.ubg)
        elapsed = time.perf_counter() - t0
        stats = self.solver.stats()
        w_new = np.asarray(r["x"]).ravel()
        ok = bool(stats["success"]) and bool(np.isfinite(w_new).all())
        return SqpResult(w_new, ok, ok, str(stats["return_status"]),
                         int(stats.get("iter_count", 0)), 0, np.nan, 0.0, elapsed)
