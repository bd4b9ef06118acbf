"""Kapitza's pendulum: a pendulum whose pivot oscillates vertically, y_pivot = a cos(nu t)."""
from collections import namedtuple

import numpy as np
from numba import njit

from ..kernels.dispatch import INLINE
from .base import Case, Param, Scene, SceneKernel, free_drift

KapitzaParams = namedtuple("KapitzaParams", "w0 a nu")


@njit(**INLINE)
def coef(P, t, C, r):
    """(g(t), g'(t)) with g = w0^2 - a nu^2 cos(nu t), the gravity felt in the pivot's frame."""
    C[r, 0] = P.w0 * P.w0 - P.a * P.nu * P.nu * np.cos(P.nu * t)
    C[r, 1] = P.a * P.nu * P.nu * P.nu * np.sin(P.nu * t)


@njit(**INLINE)
def energy_coef(P, t, C, r):
    """What energy reads of row r: g(t) alone."""
    C[r, 0] = P.w0 * P.w0 - P.a * P.nu * P.nu * np.cos(P.nu * t)


@njit(**INLINE)
def energy(P, C, r, z):
    return 0.5 * z[1] * z[1] - C[r, 0] * np.cos(z[0])


@njit(**INLINE)
def grad(P, C, r, z, g):
    g[0] = C[r, 0] * np.sin(z[0])
    g[1] = z[1]


@njit(**INLINE)
def hess(P, C, r, z, Hm):
    Hm[0, 0] = C[r, 0] * np.cos(z[0])
    Hm[0, 1] = Hm[1, 0] = 0.0
    Hm[1, 1] = 1.0


@njit(**INLINE)
def dhdt(P, C, r, z):
    return -C[r, 1] * np.cos(z[0])


@njit(**INLINE)
def kick(P, C, r, tau, z):
    """The flow of V = -g(t) cos q for a time tau at row r's time: p -= tau g sin q."""
    z[1] -= tau * C[r, 0] * np.sin(z[0])
    return tau * C[r, 1] * np.cos(z[0])


SCENE = Scene(
    name="kapitza",
    title="Kapitza's pendulum (vertically driven pivot)",
    summary="H = p²/2 − (ω₀² − a ν² cos(νt)) cos q, lengths in units of the pendulum's, q measured from the "
            "downward vertical. Nonlinear: the implicit methods iterate Newton.",
    look_for="For a ν > √2 ω₀ (and ν ≫ ω₀) the inverted position q = π becomes stable: start near q = π and "
             "watch the pendulum stay up, wobbling at the drive frequency.",
    equations=(r"H(q,p,t) = \tfrac12 p^2 - \big(\omega_0^2 - a\nu^2\cos(\nu t)\big)\cos q",
               (r"\dot q = p,\quad \dot p = -\big(\omega_0^2 - a\nu^2\cos(\nu t)\big)\sin q,\quad "
               r"\dot p_t = a\nu^3\sin(\nu t)\cos q"),
               r"a\,\nu > \sqrt2\,\omega_0 \;\Rightarrow\; q=\pi \text{ stable (Kapitza)}"),
    params=(
        Param("w0", 1.0, "small-swing frequency sqrt(g/l) of the undriven pendulum", (0.0, 100.0)),
        Param("a", 0.1, "pivot amplitude in units of the pendulum length", (0.0, 1.0)),
        Param("nu", 40.0, "pivot drive frequency", (0.0, 1e3)),
        Param("q0", 3.0, "initial angle q(0) from the downward vertical (3: near the top, where the drive holds it)",
              (-10.0, 10.0), initial=True),
        Param("p0", 0.0, "initial angular momentum p(0)", (-1e3, 1e3), initial=True),
    ),
    kernel=SceneKernel(ndof=1, ncoef=2, linear=False, coef=coef, energy=energy, grad=grad,
                       hess=hess, dhdt=dhdt, kick=kick, drift=free_drift, energy_coef=energy_coef),
    Params=KapitzaParams,
    h=0.005,
    T=20.0,
    time_scale=0.1,
    notes=("Not in the paper: the classic teaching case of a time-dependent Hamiltonian.",),
    cases=(
        Case("Kapitza: RK4 against Gauss at equal order",
             "The pendulum held up by its fast-driven pivot (a 0.1, ν 40) at h 0.01 to T 25, with the "
             "two-stage Gauss method: symplectic, of order 4 like RK4, at 2 stages a step against its 4 (implicit "
             "ones: each step solves for them by Newton, so a step costs more wall time than RK4's). "
             "Look at |H + p_t|: RK4's climbs steadily to nearly three times Gauss's flat band. (The midpoint "
             "rule's band, 0.5 at h 0.005 from the drive, is far above anything RK4 drifts to in a live run.)",
             "gauss4", "rk4", 0.01, 25.0, first=True),
        Case("Kapitza: stabilized inverted pendulum",
             "Started near the top (q0 = 3.0) with a fast-driven pivot (a = 0.1, ν = 40), the pendulum "
             "stays up, wobbling at the drive frequency.",
             "midpoint", "rk4", 0.002, 20.0, values={"q0": 3.0, "a": 0.1, "nu": 40.0}, view="play"),
        Case("Kapitza: Newton at a large step",
             "h = 0.1 with the drive at nu = 40 (h nu = 4): Newton still converges to round-off every "
             "step and the pendulum stays up, but a step this long does not follow the drive: |H + p_t| "
             "is as large as H itself, and the verdict says that this h bounds nothing.",
             "midpoint", "rk4", 0.1, 20.0, values={"q0": 3.0, "a": 0.1, "nu": 40.0}, hard=True),
        Case("Kapitza: Newton fails",
             "a = 0.3 at h = 0.5: the midpoint equations have no nearby solution; the message names "
             "the step, the flow's local rate there and an h to try (h = 0.4, 0.3 or 0.1 fail sooner), and the "
             "data up to it stay.",
             "midpoint", "rk4", 0.5, 100.0, values={"q0": 3.0, "a": 0.3, "nu": 40.0}, hard=True, fails=("midpoint",)),
    ),
    map_axes=(("nu", 5.0, 80.0, False), ("a", 0.0, 0.5, False)),
    rank=5,
)
