"""The Caldirola-Kanai oscillator exactly as printed in the paper (Sec. 4.1)."""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from ..kernels.dispatch import INLINE
from . import quadratic
from .base import Case, Paper, Param, Scene, SceneKernel

DampedParams = namedtuple("DampedParams", "m w0 gamma")
LN2 = math.log(2.0)


@njit(**INLINE)
def coef(P, t, C, r):
    grow = np.exp(P.gamma * t)
    kin = grow / P.m
    pot = P.m * P.w0 / grow
    quadratic.clear(P, C, r)
    quadratic.put_S(P, C, r, 0, 0, pot)
    quadratic.put_S(P, C, r, 1, 1, kin)
    quadratic.put_dS(P, C, r, 0, 0, -P.gamma * pot)
    quadratic.put_dS(P, C, r, 1, 1, P.gamma * kin)
    quadratic.finish(P, C, r)


@njit(**INLINE)
def scaling(P, t):
    """H(q, p, t) = H(q/E, p E, t - tau) with E^2 = e^{gamma tau}: the step from t is taken with
    E = 2^e nearest to e^{gamma t/2}, so the coefficients e^{+-gamma t} stay near 1 at any t."""
    if P.gamma == 0.0:
        return 0
    return int(np.rint(P.gamma * t * (0.5 / LN2)))


@njit(**INLINE)
def shift(P, e):
    """tau with e^{gamma tau} = 2^(2e)."""
    return 0.0 if e == 0 else e * (2.0 * LN2) / P.gamma


def scaled_beyond(P):
    """Up to |gamma t| = ln 2 the scaled step has e = 0 (it is the plain step), so a run within
    that range takes the plain steps without computing a scaling. Beyond it the coefficients
    e^(+-gamma t) spread, and an ensemble's step matrix (kernels.loops.propagate_matrix) gives p_t
    through a quadratic form whose round-off grows with that spread: Blanes & Moan's SRKN11b
    splitting's |H + p_t| grew to 5e-3 by gamma t = 40 with plain steps, at round-off (3e-13)
    with scaled ones or member steps."""
    return math.inf if P.gamma == 0.0 else LN2 / abs(P.gamma)


@njit(**INLINE)
def flow(P, t0, t1, z):
    """Exact flow of q'' - gamma q' + w0 q = 0 with p = m e^{-gamma t} q'.

    With W^2 = w0 - gamma^2/4 and s = t1 - t0, C(s), S(s) solve u'' = -W^2 u with
    C(0) = 1, C'(0) = 0, S(0) = 0, S'(0) = 1 (trigonometric, linear or hyperbolic).
    """
    s = t1 - t0
    W2 = P.w0 - 0.25 * P.gamma * P.gamma
    if W2 > 0.0:
        W = np.sqrt(W2)
        C = np.cos(W * s)
        S = np.sin(W * s) / W
    elif W2 < 0.0:
        W = np.sqrt(-W2)
        C = np.cosh(W * s)
        S = np.sinh(W * s) / W
    else:
        C = 1.0
        S = s
    q, p = z[0], z[1]
    root = np.exp(0.5 * P.gamma * t0)
    half = np.exp(0.5 * P.gamma * s)
    z[0] = half * (q * C + (root * (root * p) / P.m - 0.5 * P.gamma * q) * S)
    z[1] = (p * C + (0.5 * P.gamma * p - P.m * P.w0 * (q / root) / root) * S) / half


@njit(**INLINE)
def drift(P, t0, tau, z):
    """The flow of T + p_t with T = e^(gamma t) p^2/(2m): q += p/m times the integral of e^(gamma t)."""
    clock = np.exp(P.gamma * t0) * tau * quadratic.exprel(P.gamma * tau)
    p = z[1]
    z[0] += clock * p / P.m
    return -0.5 * p * p / P.m * P.gamma * clock


SCENE = Scene(
    name="damped",
    title="Damped oscillator (Caldirola-Kanai, as printed)",
    summary="H = e^(γt) p²/(2m) + e^(−γt) m ω₀ q²/2, the paper's Sec. 4.1, whose figures take γ = 0.2, h = 0.1, "
            "T = 50 (the scene's defaults). As printed it gives q″ − γ q′ + ω₀ q = 0.",
    look_for="With the paper's sign, γ > 0 makes q grow like e^(γt/2) while p decays like e^(−γt/2); γ < 0 is "
             "the usual damping of q. H + p_t oscillates boundedly for the structure-preserving methods and drifts "
             "for RK4 over long runs.",
    equations=(r"H(q,p,t) = \frac{e^{\gamma t}}{2m}\,p^2 + \frac{m\,\omega_0}{2}\,e^{-\gamma t} q^2",
               (r"\dot q = \frac{e^{\gamma t}}{m} p,\quad \dot p = -m\omega_0 e^{-\gamma t} q,\quad "
               r"\dot p_t = -\frac{\gamma e^{\gamma t}}{2m}p^2 + \frac{\gamma m\omega_0}{2} e^{-\gamma t} q^2"),
               r"\ddot q - \gamma\,\dot q + \omega_0\, q = 0"),
    params=(
        Param("m", 1.0, "mass m", (1e-3, 1e3)),
        Param("w0", 1.0, "stiffness w0 (the paper writes w0 where w0^2 is usual; same at 1)", (0.0, 1e3)),
        Param("gamma", 0.2, "gamma > 0 grows q and damps p (the paper's sign); gamma < 0 damps q",
              (-10.0, 10.0)),
        Param("q0", 1.0, "initial position q(0)", (-1e3, 1e3), initial=True),
        Param("p0", 1.0, "initial momentum p(0)", (-1e3, 1e3), initial=True),
    ),
    kernel=SceneKernel(ndof=1, ncoef=quadratic.ncoef(1), linear=True, coef=coef,
                       energy=quadratic.energy, grad=quadratic.grad, hess=quadratic.hess,
                       dhdt=quadratic.dhdt, flow=flow, scaling=scaling, shift=shift, kick=quadratic.kick, drift=drift,
                       scaled_beyond=scaled_beyond, diagonal=True),
    Params=DampedParams,
    h=0.1,
    T=50.0,
    time_scale=1.0,
    notes=(("Printed sign kept: the usual Caldirola-Kanai damping has the exponentials the other "
           "way round, i.e. gamma -> -gamma here."),
           ("Printed stiffness kept: H has w0 where w0^2 is usual, so the undamped angular frequency is "
            "sqrt(w0) (the same at the paper's w0 = 1)."),
           "Volume-form run in the paper: gamma = 2e-4, T = 5e5."),
    paper=Paper("Section 4.1: damped harmonic oscillator", {"gamma": 0.2}, {"gamma": 2e-4}, 5e5),
    cases=(
        Case("Weakly damped, long enough to drift",
             "The printed oscillator at γ 0.01 (q grows like e^(γt/2) while p shrinks) with h 0.2 to "
             "T 200. Look at |H + p_t|: RK4's starts below the midpoint rule's band, leaves it near "
             "t = 23 and ends nine times above it, while the band stays put.",
             "midpoint", "rk4", 0.2, 200.0, values={"gamma": 0.01}, first=True),
        Case("Fig. damped: extended Hamiltonian and symplectic form",
             "The paper's symplectic Euler against RK4 (γ 0.2, h 0.1, T 50): the first-order scheme's "
             "H + p_t oscillates in a fixed band, RK4's starts far smaller; the gap is what the long "
             "runs close.",
             "symplectic-euler", "rk4", 0.1, 50.0, values={"gamma": 0.2}),
        Case("Fig. damped: volume form (gamma 2e-4, T 5e5)",
             "The paper's long run (γ 2e-4, h 0.1, 5e6 steps, in the Long run view): the paper's "
             "volume estimator follows the orbit's slow growth for both methods; |det M − 1| stays at "
             "round-off only for the symplectic scheme.",
             "symplectic-euler", "rk4", 0.1, 50.0, values={"gamma": 2e-4}, view="long", T_long=5e5),
        Case("Damped across 600 decades",
             "γ T = 1400: e^(γt) reaches 1e608, q 1e304 and p 1e-304. Steps are taken in "
             "scaled coordinates, so both runs reach T, and H + p_t stays bounded.",
             "symplectic-euler", "rk4", 0.1, 7000.0, values={"gamma": 0.2}, hard=True),
        Case("Damped beyond floating point",
             "Near t = 7098 the true q passes 1.8e308: each run stops just before (t ≈ 7094, where its "
             "next step would overflow) with a message and shows its data up to that step.",
             "symplectic-euler", "rk4", 0.1, 7500.0, values={"gamma": 0.2}, hard=True, fails=("symplectic-euler", "rk4")),
    ),
    # max |H + p_t| over h x gamma: the band's size, smooth in both (as h^2 for midpoint). Growth is
    # gamma/2 for every method, and the error at T, a phase gone round, is noise over this map.
    map_axes=(("h", 0.05, 3.0, True), ("gamma", -0.5, 0.5, False)),
    map_measure="H_ext_max_abs",
    rank=2,
)
