"""The boat: the paper's 3-DOF model (§II) as CasADi expressions, written once.

    M nu_r_dot + C(nu_r) nu_r + D(nu_r) nu_r = tau(nT, nS)        (kinetics, eq. kinetics)
    eta_dot = R(psi) nu                                           (kinematics)

with eta = [x, y, psi] (NED, psi clockwise from north), nu = [u, v, r] the body-frame velocity
over ground, and nu_r = nu - R(psi)^T [V_n, V_e, 0] the velocity through the water, so a
constant current enters the damping and Coriolis terms (Fossen's relative-velocity model).
An optional body-frame acceleration bias b = [b_u, b_v, b_r] (m/s^2, m/s^2, rad/s^2) adds to
nu_dot: the rest of the model's error, as an on-line estimator finds it (zero for the plant).
Thrust `F = c_eff nT|nT|` keeps reverse thrust negative; `delta = delta_max * nS / 100`;
`tau = [F cos delta, F sin delta, -ly F sin delta]`, so nS > 0 turns the boat to port.

Parameters are a symbolic input (PARAM_NAMES order), so new values need no new code. The
exact variant (|z|) is the plant; the smooth variant (sqrt(z^2 + eps)) is for optimisers.
Everything else - the NMPC's prediction model, the FMU's C code, the identification NLP -
is generated from `boat_ode` and the discretisations below.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from .params import PARAM_NAMES

STATE_NAMES = ("x", "y", "psi", "u", "v", "r")
INPUT_NAMES = ("nT", "nS")
CURRENT_NAMES = ("current_north", "current_east")
NX, NU, NP = len(STATE_NAMES), len(INPUT_NAMES), len(PARAM_NAMES)

SMOOTH_EPS = 1e-4
"""Default eps of the smooth |z| = sqrt(z^2 + eps): at most 0.01 off near zero."""


@dataclass(frozen=True)
class Variant:
    """Which |z| the model uses: exact (plant) or smooth with a given eps (optimisers)."""

    smooth: bool = False
    eps: float = SMOOTH_EPS

    def abs(self, z):
        return ca.sqrt(z * z + self.eps) if self.smooth else ca.fabs(z)


EXACT = Variant(smooth=False)
SMOOTH = Variant(smooth=True)


def unpack_params(p) -> dict:
    """Name the entries of a symbolic (or numeric) parameter vector."""
    return {name: p[i] for i, name in enumerate(PARAM_NAMES)}


def rotation(psi):
    """R(psi): body to NED for the horizontal plane (eq. rot)."""
    c, s = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))


def thrust(command, P: dict, variant: Variant = EXACT):
    """tau_c = [F cos delta, F sin delta, -ly F sin delta] from [nT, nS] in percent (eq. force)."""
    nT, nS = command[0], command[1]
    c_eff = P["c"] * P["thrust_scale"] ** 2
    F = c_eff * nT * variant.abs(nT)
    delta = P["delta_max"] / 100.0 * nS
    return ca.vertcat(F * ca.cos(delta), F * ca.sin(delta), -P["ly"] * F * ca.sin(delta))


def mass_matrix(P: dict):
    return ca.diag(ca.vertcat(P["m11"], P["m22"], P["m33"]))


def coriolis(nu, P: dict):
    """C(nu) of eq. C_matrix."""
    u, v = nu[0], nu[1]
    return ca.vertcat(
        ca.horzcat(0, 0, -P["m22"] * v),
        ca.horzcat(0, 0, P["m11"] * u),
        ca.horzcat(P["m22"] * v, -P["m11"] * u, 0),
    )


def damping(nu, P: dict, variant: Variant = EXACT):
    """D(nu) of eq. D_matrix: minus the linear and the modulus-quadratic derivatives."""
    au, av, ar = variant.abs(nu[0]), variant.abs(nu[1]), variant.abs(nu[2])
    linear = ca.vertcat(
        ca.horzcat(P["Xu"], 0, 0),
        ca.horzcat(0, P["Yv"], P["Yr"]),
        ca.horzcat(0, P["Nv"], P["Nr"]),
    )
    quadratic = ca.vertcat(
        ca.horzcat(P["Xuu"] * au, 0, 0),
        ca.horzcat(0, P["Yvv"] * av, P["Yrr"] * ar),
        ca.horzcat(0, P["Nvv"] * av, P["Nrr"] * ar),
    )
    return -linear - quadratic


def boat_ode(state, command, p, current=(0.0, 0.0), variant: Variant = EXACT, bias=None):
    """x_dot = f(x, u, P) of eq. final, with the water current [V_north, V_east] in m/s and
    an optional body-frame acceleration bias [b_u, b_v, b_r]."""
    P = unpack_params(p)
    psi, nu = state[2], state[3:6]
    R = rotation(psi)
    nu_c = ca.mtimes(R.T, ca.vertcat(current[0], current[1], 0))  # current in the body frame
    nu_r = nu - nu_c
    # d/dt of the body-frame current for a constant NED current: turning the boat turns it.
    nu_c_dot = ca.vertcat(nu[2] * nu_c[1], -nu[2] * nu_c[0], 0)
    tau = thrust(command, P, variant)
    rhs = tau - ca.mtimes(coriolis(nu_r, P), nu_r) - ca.mtimes(damping(nu_r, P, variant), nu_r)
    nu_dot = nu_c_dot + rhs / ca.diag(mass_matrix(P))  # M is diagonal (eq. M_matrix)
    if bias is not None:
        nu_dot = nu_dot + ca.vertcat(bias[0], bias[1], bias[2])
    eta_dot = ca.mtimes(R, nu)
    return ca.vertcat(eta_dot, nu_dot)


def rk4(f, x, h, n_sub: int = 1):
    """Classic RK4 of x' = f(x) over h in n_sub equal sub-steps (symbolic or numeric)."""
    dt = h / n_sub
    for _ in range(n_sub):
        k1 = f(x)
        k2 = f(x + dt / 2 * k1)
        k3 = f(x + dt / 2 * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


# -- CasADi Functions built from boat_ode --------------------------------------------------
def _symbols():
    x = ca.SX.sym("x", NX)
    u = ca.SX.sym("u", NU)
    p = ca.SX.sym("p", NP)
    w = ca.SX.sym("current", 2)
    return x, u, p, w


def ode_function(variant: Variant = EXACT) -> ca.Function:
    """`boat_ode(x[6], u[2], p[NP], current[2]) -> xdot[6]`."""
    x, u, p, w = _symbols()
    return ca.Function(
        "boat_ode", [x, u, p, w], [boat_ode(x, u, p, w, variant)],
        ["x", "u", "p", "current"], ["xdot"],
    )


def step_function(dt: float, n_sub: int = 1, variant: Variant = EXACT) -> ca.Function:
    """`boat_step(x, u, p, current) -> x_next`: RK4 over `dt` in `n_sub` sub-steps, u held."""
    x, u, p, w = _symbols()
    x_next = rk4(lambda z: boat_ode(z, u, p, w, variant), x, dt, n_sub)
    return ca.Function("boat_step", [x, u, p, w], [x_next], ["x", "u", "p", "current"], ["x_next"])


def rate_limit(actual, command, rate_max, h):
    """Move `actual` toward `command` by at most `rate_max * h`; rate_max <= 0 means no limit."""
    step = ca.fmin(ca.fmax(command - actual, -rate_max * h), rate_max * h)
    return ca.if_else(rate_max > 0, actual + step, command)


def plant_step_function(variant: Variant = EXACT) -> ca.Function:
    """One plant step with the actuators' optional rate limits (the FMU's and simulators' step).

    `plant_step(x[6], act[2], cmd[2], p, current[2], rate_max[2], h) -> (x_next, act_next, xdot)`:
    the actuators move toward the command at most `rate_max` (%/s, 0 = off) over `h`, then one
    RK4 step of length `h` with the actuators held. `xdot` is f at the start of the step with
    the new actuator values (the body-frame accelerations an IMU would see).
    """
    x, cmd, p, w = _symbols()
    act = ca.SX.sym("act", NU)
    rate = ca.SX.sym("rate_max", NU)
    h = ca.SX.sym("h")
    act_next = ca.vertcat(
        rate_limit(act[0], cmd[0], rate[0], h), rate_limit(act[1], cmd[1], rate[1], h)
    )
    act_next = ca.fmin(ca.fmax(act_next, -100), 100)
    f = lambda z: boat_ode(z, act_next, p, w, variant)  # noqa: E731
    x_next = rk4(f, x, h, 1)
    return ca.Function(
        "plant_step",
        [x, act, cmd, p, w, rate, h],
        [x_next, act_next, f(x)],
        ["x", "act", "cmd", "p", "current", "rate_max", "h"],
        ["x_next", "act_next", "xdot"],
    )


def augmented_ode(x8, du, p, current=(0.0, 0.0), variant: Variant = SMOOTH, bias=None):
    """The NMPC's model: state [x, y, psi, u, v, r, nT, nS], input [dnT, dnS] in %/s."""
    return ca.vertcat(boat_ode(x8[:NX], x8[NX:NX + NU], p, current, variant, bias), du)
