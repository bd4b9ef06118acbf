"""Oscillator with time-dependent potential (paper Sec. 4.2, after Marthinsen & Owren)."""
from collections import namedtuple

import numpy as np
from numba import njit

from ..kernels.dispatch import INLINE
from . import quadratic
from .base import Case, Paper, Param, Scene, SceneKernel, free_drift

ModulatedParams = namedtuple("ModulatedParams", "eps alpha")


@njit(**INLINE)
def coef(P, t, C, r):
    quadratic.clear(P, C, r)
    quadratic.put_S(P, C, r, 0, 0, 1.0 + P.eps * np.sin(P.alpha * t))
    quadratic.put_S(P, C, r, 1, 1, 1.0)
    quadratic.put_dS(P, C, r, 0, 0, P.eps * P.alpha * np.cos(P.alpha * t))
    quadratic.finish(P, C, r)


@njit(**INLINE)
def energy_coef(P, t, C, r):
    """What quadratic.energy reads of row r (S and s): coef without its cos(αt)."""
    quadratic.put_S(P, C, r, 0, 0, 1.0 + P.eps * np.sin(P.alpha * t))
    quadratic.put_S(P, C, r, 0, 1, 0.0)
    quadratic.put_S(P, C, r, 1, 0, 0.0)
    quadratic.put_S(P, C, r, 1, 1, 1.0)
    quadratic.put_s(P, C, r, 0.0)


@njit(**INLINE)
def rotate(P, t0, tau, z):
    """The flow of H0 + p_t, H0 = (q² + p²)/2 (the unmodulated oscillator): (q, p) turn by the angle
    tau, t moves by tau; p_t stays (H0 does not depend on t)."""
    c, s = np.cos(tau), np.sin(tau)
    q, p = z[0], z[1]
    z[0] = c * q + s * p
    z[1] = c * p - s * q
    return -0.0


@njit(**INLINE)
def nudge(P, C, r, tau, z):
    """The flow of H - H0 = ε sin(αt) q²/2 for a time tau at row r's time: p -= tau ε sin(αt) q;
    returns p_t's increment -tau ε α cos(αt) q²/2."""
    z[1] -= tau * (quadratic.get_S(P, C, r, 0, 0) - 1.0) * z[0]
    return -0.5 * tau * quadratic.get_dS(P, C, r, 0, 0) * z[0] * z[0]


SCENE = Scene(
    name="modulated",
    title="Oscillator with time-dependent potential",
    summary=("H = ((1 + ε sin(αt)) q² + p²)/2, the paper's Sec. 4.2 (its figures: ε = 0.0035, α = 0.0008, the "
             "scene's defaults)."),
    look_for="A slowly modulated stiffness: the structure-preserving methods keep H + p_t oscillating around 0; "
             "RK4 loses energy at every step, so its H + p_t drifts away (over long runs its orbit spirals in). Large ε with α "
             "near 2 (or 1, 2/3, ...) puts it in a Mathieu resonance tongue.",
    equations=(r"H(q,p,t) = \tfrac12\big((1+\varepsilon\,\sin(\alpha t))\,q^2 + p^2\big)",
               (r"\dot q = p,\quad \dot p = -(1+\varepsilon\,\sin(\alpha t))\,q,\quad "
               r"\dot p_t = -\tfrac12\alpha\varepsilon\cos(\alpha t)\,q^2")),
    params=(
        Param("eps", 0.0035, "modulation depth eps of the stiffness", (-10.0, 10.0)),
        Param("alpha", 0.0008, "modulation frequency alpha", (0.0, 100.0)),
        Param("q0", 1.0, "initial position q(0)", (-1e3, 1e3), initial=True),
        Param("p0", 1.0, "initial momentum p(0)", (-1e3, 1e3), initial=True),
    ),
    kernel=SceneKernel(ndof=1, ncoef=quadratic.ncoef(1), linear=True, coef=coef,
                       energy=quadratic.energy, grad=quadratic.grad, hess=quadratic.hess,
                       dhdt=quadratic.dhdt, kick=quadratic.kick, drift=free_drift, rotate=rotate, nudge=nudge,
                       energy_coef=energy_coef, diagonal=True),
    Params=ModulatedParams,
    h=0.1,
    T=50.0,
    time_scale=1.0,
    notes=("Long run in the paper: T = 2e5.",),
    paper=Paper("Section 4.2: harmonic oscillator with time-dependent potential", T_long=2e5),
    cases=(
        Case("What structure preservation buys",
             "A strongly modulated oscillator (ε 0.2, α 0.05) at h 0.25 to T 1000, the app's first view. "
             "Look at |H + p_t|: RK4 (fourth order, 4 stages per step) starts with the smaller "
             "one but loses energy at every step, passes the symplectic midpoint rule's band near "
             "t = 94 and ends nine times above it, while the band stays put.",
             "midpoint", "rk4", 0.25, 1000.0, values={"eps": 0.2, "alpha": 0.05}, first=True, lead=True),
        Case("Fig. time-dependent potential (T 50)",
             "A slowly modulated stiffness (ε 0.0035, α 0.0008, h 0.1, T 50): over so short a run both "
             "methods keep H + p_t small; the long run shows RK4 drifting.",
             "symplectic-euler", "rk4", 0.1, 50.0),
        Case("Fig. time-dependent potential: long run (T 2e5)",
             "The same oscillator over 2e6 steps (Long run view): the symplectic scheme's H + p_t "
             "stays in its band while RK4's leaves it linearly.",
             "symplectic-euler", "rk4", 0.1, 50.0, view="long", T_long=2e5),
        Case("RK4 just past its stability limit",
             "The plain oscillator at h = 2.9 > 2√2: RK4's amplitude grows by |R(2.9i)| = 1.19 per "
             "step (1e76 by T), implicit midpoint stays on its circle with 2 points per period.",
             "midpoint", "rk4", 2.9, 2900.0, values={"eps": 0.0}, hard=True),
        Case("Explicit Euler at a small step",
             "Explicit Euler spirals out at every h, by √(1 + h²) per step (×148 here at h = 0.05); "
             "the paper's symplectic Euler stays on a closed curve.",
             "symplectic-euler", "euler", 0.05, 200.0, values={"eps": 0.0}, hard=True),
        Case("Mathieu tongue: parametric resonance",
             "Stiffness 1 + 0.2 sin(2t) is inside the principal tongue: the true solution grows like "
             "e^(0.05 t), and both methods grow at that rate (e^10 by T).",
             "midpoint", "rk4", 0.05, 200.0, values={"eps": 0.2, "alpha": 2.0}, hard=True),
        Case("Just outside the tongue",
             "The same depth at alpha = 2.5 is stable: the solution beats but stays bounded, and "
             "neither method reports growth.",
             "midpoint", "rk4", 0.05, 200.0, values={"eps": 0.2, "alpha": 2.5}, hard=True),
        Case("Ten million steps",
             "The modulated oscillator to T = 1e6 at h = 0.1, 1e7 steps per method in the Long run "
             "view (5-10 s): midpoint's H + p_t stays bounded, RK4's drifts.",
             "midpoint", "rk4", 0.1, 50.0, view="long", T_long=1e6, hard=True),
    ),
    map_axes=(("alpha", 0.5, 4.5, False), ("eps", 0.0, 0.8, False)),
    strong={"eps": 0.5, "alpha": 2.0},
    rank=3,
)
