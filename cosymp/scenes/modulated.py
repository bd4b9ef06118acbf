"""Oscillator with time-dependent potential (paper Sec. 4.2, after Marthinsen & Owren)."""
from collections import namedtuple

import numpy as np
from numba import njit

from ..kernels.dispatch import INLINE
from . import quadratic
from .base import Param, Scene, SceneKernel, free_drift

ModulatedParams = namedtuple("ModulatedParams", "eps alpha")


@njit(**INLINE)
def coef(P, t, C, r):
    quadratic.clear(P, C, r)
    C[r, 0] = 1.0 + P.eps * np.sin(P.alpha * t)
    C[r, 3] = 1.0
    C[r, 4] = P.eps * P.alpha * np.cos(P.alpha * t)
    quadratic.finish(P, C, r)


SCENE = Scene(
    name="modulated",
    title="Oscillator with time-dependent potential",
    summary=("H = ((1 + ε sin(αt)) q² + p²)/2, the paper's Sec. 4.2; the paper's ε = 0.0035 and α = 0.0008 "
             "are the scene's defaults."),
    look_for="A slowly modulated stiffness: the structure-preserving methods keep H + p_t oscillating around 0; "
             "RK4 loses energy at every step, so its H + p_t drifts away and its orbit spirals in. Large ε with α "
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
                       dhdt=quadratic.dhdt, kick=quadratic.kick, drift=free_drift),
    Params=ModulatedParams,
    h=0.1,
    T=50.0,
    time_scale=1.0,
    notes=("Long run in the paper: T = 2e5.",),
)
