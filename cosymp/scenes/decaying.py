"""The paper's opening example: H = e^{-lam t} (p^2 + q^2) / 2 (lam = 1 in the paper)."""
import math
from collections import namedtuple

import numpy as np
from numba import njit

from ..kernels.dispatch import INLINE
from . import quadratic
from .base import Case, Param, Scene, SceneKernel

DecayingParams = namedtuple("DecayingParams", "lam")


@njit(**INLINE)
def coef(P, t, C, r):
    a = np.exp(-P.lam * t)
    quadratic.clear(P, C, r)
    quadratic.put_S(P, C, r, 0, 0, a)
    quadratic.put_S(P, C, r, 1, 1, a)
    quadratic.put_dS(P, C, r, 0, 0, -P.lam * a)
    quadratic.put_dS(P, C, r, 1, 1, -P.lam * a)
    quadratic.finish(P, C, r)


@njit(**INLINE)
def flow(P, t0, t1, z):
    """A rotation by the elapsed 'clock' int e^{-lam t} dt (lam > 0: no branch, so the
    compiler shares the transcendental calls between the columns of the step matrix)."""
    angle = -np.exp(-P.lam * t0) * np.expm1(-P.lam * (t1 - t0)) / P.lam
    c = np.cos(angle)
    s = np.sin(angle)
    q = z[0]
    z[0] = c * q + s * z[1]
    z[1] = -s * q + c * z[1]


@njit(**INLINE)
def drift(P, t0, tau, z):
    """The flow of T + p_t with T = e^(-lam t) p^2/2: q += p times the integral of e^(-lam t)."""
    x = -P.lam * tau
    clock = np.exp(-P.lam * t0) * tau * quadratic.exprel(x)
    p2 = z[1] * z[1]
    z[0] += clock * z[1]
    return 0.5 * p2 * P.lam * clock


def still_after(P):
    """The flow left after t rotates by e^(−λt)/λ in all: from where that is 1e-3 rad on, nothing moves visibly."""
    return math.log(1e3 / P.lam) / P.lam


SCENE = Scene(
    name="decaying",
    title="Opening example: oscillator with decaying Hamiltonian",
    summary="H = e^(−λt) (p² + q²)/2, the paper's first example (λ = 1 there); its exact flow is a rotation "
            "by (e^(−λt_k) − e^(−λt_(k+1)))/λ per step.",
    look_for="Explicit Euler's one-step determinant is 1 + h² e^(−2λt_k) > 1: the orbit spirals out. "
             "Structure-preserving methods keep det = 1 and stay on the exact circle's scale.",
    equations=(r"H(q,p,t) = \tfrac12 e^{-\lambda t}\,(p^2+q^2)",
               (r"\dot q = e^{-\lambda t} p,\quad \dot p = -e^{-\lambda t} q,\quad "
               r"\dot p_t = \tfrac{\lambda}{2} e^{-\lambda t}(p^2+q^2)"),
               r"\Phi_{t_k,h} = R\big((e^{-\lambda t_k}-e^{-\lambda (t_k+h)})/\lambda\big)"),
    params=(
        Param("lam", 1.0, "decay rate lambda of the Hamiltonian (the paper's example: 1)", (1e-9, 10.0)),
        Param("q0", 1.0, "initial position q(0)", (-1e3, 1e3), initial=True),
        Param("p0", 1.0, "initial momentum p(0)", (-1e3, 1e3), initial=True),
    ),
    kernel=SceneKernel(ndof=1, ncoef=quadratic.ncoef(1), linear=True, coef=coef,
                       energy=quadratic.energy, grad=quadratic.grad, hess=quadratic.hess,
                       dhdt=quadratic.dhdt, flow=flow, kick=quadratic.kick, drift=drift,
                       diagonal=True),
    Params=DecayingParams,
    h=0.1,
    T=10.0,
    time_scale=1.0,
    still_after=still_after,
    notes=("The paper fixes lambda = 1; a small lambda approaches the plain harmonic oscillator.",),
    cases=(
        Case("The opening example, decaying slowly",
             "The paper's own pair, its symplectic Euler-type scheme against explicit Euler (both of "
             "order 1, one evaluation a step), with λ 0.02 so that the Hamiltonian stays alive to T "
             "100 (h 0.1). Look at explicit Euler's orbit spiralling out (det M = 1 + h² e^(−2λt) > 1) "
             "and its |H + p_t| ending sixty times above the symplectic scheme's band.",
             "symplectic-euler", "euler", 0.1, 100.0, values={"lam": 0.02}, first=True),
    ),
    map_axes=(("h", 0.05, 3.0, True), ("lam", 0.1, 5.0, False)),
    map_measure="error_final",
    rank=1,
)
