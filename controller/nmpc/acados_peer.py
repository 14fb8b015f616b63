"""acados as a peer of canalnav's RTI, for `canalnav bench nmpc --peer acados`: the same OCP
(this package's `dynamics_function` and `clearance_function`, the same weights, bounds and
HPIPM settings) built with acados' SQP_RTI, and driven step by step in the same closed loop
with the inputs canalnav's controller computed (parameters, reference, first warm start)
handed to it ready-made.

acados is a peer for the bench, never a dependency of the controller. Its Python interface
(`acados_template`, from the `comma-deps-acados` wheel installed beside the project, as the
tuned HPIPM is) needs the casadi it ships with, so the peer runs in a child process whose
path starts with the wheel's folder: `python -m controller.nmpc.acados_peer IN OUT`.

How the two are matched, and where they differ on purpose:
- The OCP: x = [x, y, psi, u, v, r, nT, nS, slack], u = [dnT, dnS, sigma], the discrete
  dynamics f_d (RK4 in sub-steps), a linear least-squares cost whose weights are canalnav's
  Gauss-Newton Hessian diagonal (so the QPs are the same), obstacle rows h >= 0 at stages
  1..N (stage 0's slots are inactive: h = 1 there), nT, nS, slack and input bounds hard.
  The obstacle rows are hard: canalnav's exact-penalty QP equals the hard one wherever that
  is feasible, and the bench counts the steps where canalnav needed its elastic rows.
- The warm start: canalnav's previous plan moved forward by the control period (stages are
  1 s, the controller runs at 10 Hz), the first one canalnav's own first guess.
- The real-time iteration in acados' two phases: the preparation (phase 1) linearises at the
  warm start, whose stage 0 is the predicted state; the feedback (phase 2) embeds the measured
  state as stage 0's bounds and solves. canalnav's feedback also relinearises stage 0 at the
  measured state, a difference of a few millimetres a step at most.
- The driver is lean: acados' C functions bound once through ctypes, buffers reused, no
  checks per call (the `AcadosOcpSolver.set`/`get` wrappers cost ~20 us a call).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..kernels import pointer

INSTALL_HINT = ("install it beside the project (never into its environment): pip install "
                "--no-deps --target {dir} comma-deps-acados")


def wheel_dir() -> Path:
    """Where the comma-deps-acados wheel is looked for: where the tuned HPIPM is
    ($CANALNAV_HPIPM_DIR, else ~/.local/share/canalnav/hpipm)."""
    from .hpipm_qp import tuned_dir

    return tuned_dir()


def peer_environment() -> dict:
    """The child's environment: the wheel's casadi and acados_template first on the path,
    then this project; acados' install folder for its code generator and libraries."""
    folder = wheel_dir()
    template = folder / "acados" / "acados_template"
    install = folder / "acados" / "install"
    if not (template / "__init__.py").is_file() or not (install / "bin" / "t_renderer").is_file():
        raise InputError(f"bench nmpc --peer acados: acados (comma-deps-acados) not found in "
                         f"{folder}; " + INSTALL_HINT.format(dir=folder))
    project = Path(__file__).resolve().parents[2]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(folder), str(folder / "acados"), str(project)])
    env["ACADOS_SOURCE_DIR"] = str(install)
    env["ACADOS_PYTHON_INTERFACE_PATH"] = str(template)
    env["LD_LIBRARY_PATH"] = os.pathsep.join(
        [str(install / "lib")] + [p for p in [os.environ.get("LD_LIBRARY_PATH", "")] if p])
    return env


def run_peer(config, qp, record: list, x0, actuators0, speed_mps: float,
             plant_substeps: int = 2, workdir: Path | None = None, timeout_s: float = 900):
    """Run acados on the recorded closed loop (`bench.closed_loop(record=...)`) in a child
    process; returns its result dict (states, CPU and latency per step, QP iterations)."""
    import tempfile

    env = peer_environment()
    with tempfile.TemporaryDirectory() as tmp:
        inp, out = Path(tmp) / "in.pickle", Path(tmp) / "out.pickle"
        job = {"config": config, "qp": asdict(qp), "x0": np.asarray(x0, float),
               "actuators0": np.asarray(actuators0, float), "speed": float(speed_mps),
               "substeps": int(plant_substeps), "record": record,
               "cache": str(workdir or _cache_dir())}
        inp.write_bytes(pickle.dumps(job))
        done = subprocess.run([sys.executable, "-m", "controller.nmpc.acados_peer", str(inp),
                               str(out)], env=env, capture_output=True, text=True,
                              timeout=timeout_s)
        if done.returncode != 0 or not out.is_file():
            tail = (done.stderr or done.stdout).strip().splitlines()[-12:]
            raise RuntimeError("acados peer failed:\n" + "\n".join(tail))
        return pickle.loads(out.read_bytes())


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "canalnav" / "acados"


# -- the child: everything below runs with the wheel's casadi --------------------------------
def stage_params(config, p: np.ndarray) -> np.ndarray:
    """(N + 1, n) per-stage parameters from canalnav's flat vector: the shared part (boat,
    current, geometry, bias, segment slots), then stage k's vessel slots; stage 0 gets
    stage 1's slots made inactive (no obstacle rows at the fixed initial state)."""
    from .problem import ParamLayout
    from .segment_slots import SLOT_FIELDS
    from .vessel_slots import VESSEL_FIELDS

    layout = ParamLayout.of(config)
    N, nv, ns = config.horizon, config.vessel_slots, config.segment_slots
    shared = p[: layout.segments.stop]
    vessels = p[layout.vessels].reshape(N, nv * len(VESSEL_FIELDS))
    out = np.empty((N + 1, shared.size + vessels.shape[1]))
    out[:, : shared.size] = shared
    out[1:, shared.size:] = vessels
    out[0, shared.size:] = vessels[0]
    seg0 = layout.segments.start
    out[0, seg0 + len(SLOT_FIELDS) - 1: seg0 + ns * len(SLOT_FIELDS): len(SLOT_FIELDS)] = 0.0
    vstart = shared.size + len(VESSEL_FIELDS) - 1
    out[0, vstart::len(VESSEL_FIELDS)] = 0.0
    return out


def shifted(xs: np.ndarray, us: np.ndarray, elapsed_s: float, step_s: float):
    """The plan moved forward by `elapsed_s`, as canalnav's controller moves it: states
    interpolated between stages (extrapolated past the last), inputs clamped to their last
    interval."""
    N = len(us)
    pos = np.arange(N + 1) + elapsed_s / step_s
    i = np.minimum(pos.astype(int), N - 1)
    f = (pos - i)[:, None]
    x = xs[i] + f * (xs[i + 1] - xs[i])
    j = np.minimum(pos[:N].astype(int), N - 2)
    g = np.clip(pos[:N] - j, 0.0, 1.0)[:, None]
    u = us[j] + g * (us[j + 1] - us[j])
    return x, u


def build_solver(config, qp: dict, cache: Path):
    """The acados OCP solver of `config`, generated and compiled once per problem (cached
    under `cache` by a hash of the config and the QP settings)."""
    import casadi as ca
    from acados_template import AcadosModel, AcadosOcp, AcadosOcpSolver

    from .problem import NU, NX, ParamLayout, build_ocp, clearance_function, dynamics_function
    from .segment_slots import SLOT_FIELDS
    from .vessel_slots import VESSEL_FIELDS

    N, layout = config.horizon, ParamLayout.of(config)
    key = hashlib.sha256(repr((config, sorted(qp.items()))).encode()
                         + Path(__file__).read_bytes()).hexdigest()[:16]
    folder = cache / key
    folder.mkdir(parents=True, exist_ok=True)
    n_shared = layout.segments.stop
    n_vessel = config.vessel_slots * len(VESSEL_FIELDS)
    x, u = ca.SX.sym("x", NX), ca.SX.sym("u", NU)
    p = ca.SX.sym("p", n_shared + n_vessel)
    f_d, clearance = dynamics_function(config), clearance_function(config)
    model = AcadosModel()
    model.name = "canalnav_rti"
    model.x, model.u, model.p = x, u, p
    model.disc_dyn_expr = f_d(x, u, p[layout.boat], p[layout.current], p[layout.bias])
    slots = ca.reshape(p[layout.segments], len(SLOT_FIELDS), config.segment_slots)
    vessels = ca.reshape(p[n_shared:], len(VESSEL_FIELDS), config.vessel_slots)
    h = clearance(x, slots, p[layout.geometry], vessels)
    model.con_h_expr = h
    model.con_h_expr_e = h

    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = N
    ocp.code_export_directory = str(folder / "code")
    problem = build_ocp(config)
    d, S, U = problem.hessian(), problem.states_at, problem.inputs_at
    w0, w, w_e = (np.concatenate([d[S[0]], d[U[0]]]), np.concatenate([d[S[1]], d[U[1]]]),
                  d[S[N]])
    ny = NX + NU
    for suffix, weights in (("_0", w0), ("", w)):
        setattr(ocp.cost, "cost_type" + suffix, "LINEAR_LS")
        setattr(ocp.cost, "W" + suffix, np.diag(weights))
        setattr(ocp.cost, "Vx" + suffix, np.eye(ny, NX))
        vu = np.zeros((ny, NU))
        vu[NX:, :] = np.eye(NU)
        setattr(ocp.cost, "Vu" + suffix, vu)
        setattr(ocp.cost, "yref" + suffix, np.zeros(ny))
    ocp.cost.cost_type_e = "LINEAR_LS"
    ocp.cost.W_e = np.diag(w_e)
    ocp.cost.Vx_e = np.eye(NX)
    ocp.cost.yref_e = np.zeros(NX)
    lbw, ubw = problem.bounds(np.zeros(NX - 1))
    lbx, ubx, lbu, ubu = lbw[S[1]], ubw[S[1]], lbw[U[1]], ubw[U[1]]
    bounded = np.flatnonzero(np.isfinite(lbx) | np.isfinite(ubx))
    ocp.constraints.x0 = np.zeros(NX)
    ocp.constraints.idxbx = bounded
    ocp.constraints.lbx, ocp.constraints.ubx = lbx[bounded], ubx[bounded]
    ocp.constraints.idxbx_e = bounded
    ocp.constraints.lbx_e, ocp.constraints.ubx_e = lbx[bounded], ubx[bounded]
    ocp.constraints.idxbu = np.arange(NU)
    ocp.constraints.lbu, ocp.constraints.ubu = lbu, ubu
    n_h = h.numel()
    ocp.constraints.lh, ocp.constraints.uh = np.zeros(n_h), np.full(n_h, qp["inf"])
    ocp.constraints.lh_e, ocp.constraints.uh_e = np.zeros(n_h), np.full(n_h, qp["inf"])
    ocp.parameter_values = np.zeros(p.numel())
    o = ocp.solver_options
    o.tf = N * config.step_s
    o.integrator_type = "DISCRETE"
    o.nlp_solver_type = "SQP_RTI"
    o.hessian_approx = "GAUSS_NEWTON"
    o.qp_solver = "PARTIAL_CONDENSING_HPIPM"
    o.qp_solver_cond_N = N  # no condensing: the OCP QP as canalnav hands it to HPIPM
    o.hpipm_mode = qp["hpipm_mode"].upper()
    o.qp_solver_iter_max = qp["iter_max"]
    o.qp_solver_warm_start = qp["warm_start"]
    for name in ("stat", "eq", "ineq", "comp"):
        setattr(o, "qp_solver_tol_" + name, qp["tol"])
    o.print_level = 0
    o.ext_fun_compile_flags = "-O2"
    json_file = str(folder / "acados_ocp.json")
    built = (folder / "built").is_file()
    solver = AcadosOcpSolver(ocp, json_file=json_file, build=not built, generate=not built,
                             verbose=False)
    (folder / "built").write_text("ok")
    # canalnav's mu0 = 0 leaves HPIPM its own initial barrier, 10 (the same iterations as
    # mu0 = 10, measured); acados would start from its own, 1
    solver.options_set("qp_mu0", float(qp["mu0"] or 10.0))
    return solver


class LeanDriver:
    """acados' C interface bound once: set a stage's parameters, reference, bounds and guess,
    run a phase of the RTI, read the plan, with preallocated buffers."""

    def __init__(self, solver, N: int):
        import ctypes

        self.solver, self.N = solver, N
        lib, name = solver.shared_lib, solver.model_name
        vp, ci, cp = ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p
        self._set_p = getattr(lib, f"{name}_acados_update_params")
        self._set_p.argtypes, self._set_p.restype = [vp, ci, vp, ci], ci
        self._solve = getattr(lib, f"{name}_acados_solve")
        self._solve.argtypes, self._solve.restype = [vp], ci
        self._out_set, self._out_get = lib.ocp_nlp_out_set, lib.ocp_nlp_out_get
        self._cost_set, self._con_set = lib.ocp_nlp_cost_model_set, lib.ocp_nlp_constraints_model_set
        for f in (self._out_set, self._out_get, self._cost_set, self._con_set):
            f.argtypes, f.restype = [vp, vp, vp, ci, cp, vp], None
        self._opts_set = lib.ocp_nlp_solver_opts_set
        self._opts_set.argtypes, self._opts_set.restype = [vp, vp, cp, vp], None
        self._get_stats = lib.ocp_nlp_get
        self._get_stats.argtypes, self._get_stats.restype = [vp, vp, cp, vp], None
        s = solver
        self._cfg, self._dims, self._in, self._out = s.nlp_config, s.nlp_dims, s.nlp_in, s.nlp_out
        self._opts, self._nlp = s.nlp_opts, s.nlp_solver
        self._capsule = s.capsule
        self._phase = ctypes.c_int(0)
        self._phase_ptr = ctypes.cast(ctypes.pointer(self._phase), vp)
        self._qp_iter = ctypes.c_int(0)
        self._qp_iter_ptr = ctypes.cast(ctypes.pointer(self._qp_iter), vp)

    ptr = staticmethod(pointer)  # an array's address, as canalnav's kernels get it

    def params(self, stage: int, values: np.ndarray) -> None:
        self._set_p(self._capsule, stage, self.ptr(values), values.size)

    def out(self, stage: int, field: bytes, values: np.ndarray) -> None:
        self._out_set(self._cfg, self._dims, self._out, stage, field, self.ptr(values))

    def read(self, stage: int, field: bytes, into: np.ndarray) -> None:
        self._out_get(self._cfg, self._dims, self._out, stage, field, self.ptr(into))

    def cost(self, stage: int, field: bytes, values: np.ndarray) -> None:
        self._cost_set(self._cfg, self._dims, self._in, stage, field, self.ptr(values))

    def bound(self, stage: int, field: bytes, values: np.ndarray) -> None:
        self._con_set(self._cfg, self._dims, self._in, stage, field, self.ptr(values))

    def phase(self, which: int) -> int:
        self._phase.value = which
        self._opts_set(self._cfg, self._opts, b"rti_phase", self._phase_ptr)
        return self._solve(self._capsule)

    def qp_iterations(self) -> int:
        self._get_stats(self._cfg, self._nlp, b"qp_iter", self._qp_iter_ptr)
        return int(self._qp_iter.value)


def run_child(job: dict) -> dict:
    """The closed loop with acados: per step, the recorded inputs set, the preparation, the
    measured state embedded and the feedback; the plant as `bench.closed_loop` runs it."""
    import time

    from ..model import SMOOTH, plant_step_function
    from .problem import NU, NX

    config, qp, record = job["config"], job["qp"], job["record"]
    solver = build_solver(config, qp, Path(job["cache"]))
    N, Ts, dt = config.horizon, config.step_s, config.control_period_s
    drive = LeanDriver(solver, N)
    plant = plant_step_function(SMOOTH)
    boat = config.boat.as_vector()
    rate_max = np.array([config.dnT_max, config.dnS_max])
    act_hi = np.array([config.nT_max, config.nS_max])
    h = dt / job["substeps"]
    from .problem import build_ocp

    problem = build_ocp(config)
    states_at, inputs_at = problem.states_at, problem.inputs_at
    x = job["x0"].copy()
    act = job["actuators0"].copy()
    xs, us = np.zeros((N + 1, NX)), np.zeros((N, NU))
    x_init = np.zeros(NX)
    yref = [np.zeros(NX + NU) for _ in range(N)] + [np.zeros(NX)]
    states, cpu, feedback, feedback_cpu, qp_iters, statuses = [x.copy()], [], [], [], [], []
    for k, (_, _, p, w_ref, guess0) in enumerate(record):
        c0 = time.thread_time()
        # the inputs, ready-made: parameters and reference per stage
        params = stage_params(config, p)
        for i in range(N + 1):
            drive.params(i, params[i])
            ref = yref[i]
            ref[:NX] = w_ref[states_at[i]]
            if i < N:
                ref[NX:] = w_ref[inputs_at[i]]
            drive.cost(i, b"yref", ref)
        # the warm start: canalnav's first guess, then the plan moved on by a period
        if k == 0:
            gx, gu = guess0[states_at], guess0[inputs_at]
        else:
            gx, gu = shifted(xs, us, dt, Ts)
        for i in range(N + 1):
            drive.out(i, b"x", np.ascontiguousarray(gx[i]))
            if i < N:
                drive.out(i, b"u", np.ascontiguousarray(gu[i]))
        drive.phase(1)
        # the feedback: the measured state in, the command out
        t0, c1 = time.perf_counter(), time.thread_time()
        psi = float(x[2])
        ref_psi = float(gx[0, 2])
        psi = ref_psi + (psi - ref_psi + np.pi) % (2 * np.pi) - np.pi
        x_init[:6] = x
        x_init[2] = psi
        x_init[6:8] = np.minimum(np.maximum(act, -act_hi), act_hi)
        x_init[8] = 0.0
        drive.bound(0, b"lbx", x_init)
        drive.bound(0, b"ubx", x_init)
        status = drive.phase(2)
        u0 = np.zeros(NU)
        drive.read(0, b"u", u0)
        rate = np.clip(u0[:2], -rate_max, rate_max)
        command = np.clip(x_init[6:8] + rate * dt, -act_hi, act_hi)
        feedback.append(time.perf_counter() - t0)
        feedback_cpu.append(time.thread_time() - c1)
        for i in range(N + 1):
            drive.read(i, b"x", xs[i])
            if i < N:
                drive.read(i, b"u", us[i])
        cpu.append(time.thread_time() - c0)
        qp_iters.append(drive.qp_iterations())
        statuses.append(int(status))
        for _ in range(job["substeps"]):
            x_next, act_next, _ = plant(x, act, command, boat, (0.0, 0.0), rate_max, h)
            x, act = np.asarray(x_next).ravel(), np.asarray(act_next).ravel()
        states.append(x.copy())
    return {"states": np.array(states), "cpu_s": np.array(cpu),
            "feedback_s": np.array(feedback), "feedback_cpu_s": np.array(feedback_cpu),
            "qp_iterations": np.array(qp_iters), "status": np.array(statuses)}


def main(argv: list[str]) -> int:
    job = pickle.loads(Path(argv[0]).read_bytes())
    result = run_child(job)
    Path(argv[1]).write_bytes(pickle.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
