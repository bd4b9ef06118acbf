"""Charged particle in the plane, in a time-dependent field, in any gauge (paper Sec. 5).

Original gauge: A = beta(t) K q with K = [[1, -1], [1, 1]], phi = 0, so B = 2 beta e_z and
E = -beta' K q. Every other gauge is built here from its gauge function, in one place:

    chi(q, t) = q.C q beta(t) / 2 + d int_0^t beta,
    A' = A + grad chi = beta (K + C) q,     phi' = phi - d_t chi = -(q.C q beta'/2 + d beta),
    H' = |p - e A'|^2 / (2m) + e phi'.

The paper's gauges are all of this form (table GAUGES); its printed per-gauge Hamiltonians are
not used (the Landau one has the sign of its scalar potential flipped and lacks the charge e).
"""
import functools
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InputError, quoted
from ..expr import ExprError, evaluate, parse, programs, zero_programs
from ..kernels.dispatch import INLINE, JIT
from . import quadratic
from .base import Case, Paper, Param, Scene, SceneKernel

ChargedParams = namedtuple("ChargedParams", "m e B0 eps w kind C00 C01 C11 d ops args")
K = np.array([[1.0, -1.0], [1.0, 1.0]])
BETA = quadratic.ncoef(2)
NCOEF = BETA + 2
BETA_PAPER, BETA_CONSTANT, BETA_EXPRESSION = 0, 1, 2


@dataclass(frozen=True)
class Gauge:
    """chi = q.C q beta / 2 + d int_0^t beta, and the condition the gauge's name promises."""

    name: str
    C: tuple
    d: float
    chi: str
    condition: str
    caveat: str = ""


GAUGES = {
    "original": Gauge("original", ((0, 0), (0, 0)), 0.0, r"0", "none: the paper's starting potentials"),
    "coulomb": Gauge("coulomb", ((-2, 0), (0, 0)), 0.0, r"-x^2\beta(t)", "div A = 0"),
    "symmetric": Gauge("symmetric", ((-1, 0), (0, -1)), 0.0, r"-\tfrac12(x^2+y^2)\beta(t)",
                       "d_y A_x + d_x A_y = 0 (A = beta (-y, x))"),
    "landau": Gauge("landau", ((-1, 1), (1, -1)), 0.0, r"-\tfrac12(x-y)^2\beta(t)",
                    "A_x = 0, A_y linear in x (A = 2 beta (0, x))",
                    "The paper's printed H_La has its scalar-potential term with the wrong sign "
                    "and without e; built from chi here, phi' = (x - y)^2 beta'/2."),
    "lorenz": Gauge("lorenz", ((0, 0), (0, 0)), -2.0, r"-2\int_0^t\beta",
                    "div A + d_t phi = 0",
                    "The paper's chi does not give the Lorenz condition: A is unchanged, phi' = 2 beta, "
                    "so div A + d_t phi = 2 beta + 2 beta' (not 0 unless beta' = -beta)."),
}


@njit(**INLINE)
def beta3(P, t):
    """beta, beta', beta'' at t."""
    if P.kind == BETA_PAPER:
        s = np.sin(P.w * t)
        return (P.B0 * (1.0 + P.eps * s), P.B0 * P.eps * P.w * np.cos(P.w * t),
                -P.B0 * P.eps * P.w * P.w * s)
    if P.kind == BETA_CONSTANT:
        return P.B0, 0.0, 0.0
    return (evaluate(P.ops[0], P.args[0], t), evaluate(P.ops[1], P.args[1], t),
            evaluate(P.ops[2], P.args[2], t))


@njit(**JIT)
def beta_many(P, ts, out):
    for k in range(ts.shape[0]):
        out[0, k], out[1, k], out[2, k] = beta3(P, ts[k])


@njit(**INLINE)
def coef(P, t, C, r):
    """S(t), S'(t), s, s' of H' = |p - L q|^2/(2m) - e beta' q.C q/2 - e d beta, L = e beta (K+C)."""
    b0, b1, b2 = beta3(P, t)
    G = ((P.C00, P.C01), (P.C01, P.C11))
    Kc = ((1.0 + P.C00, -1.0 + P.C01), (1.0 + P.C01, 1.0 + P.C11))
    inv = 1.0 / P.m
    for i in range(2):
        for j in range(2):
            LL = 0.0
            for k in range(2):
                LL += Kc[k][i] * Kc[k][j]
            e2 = P.e * P.e
            quadratic.put_S(P, C, r, i, j, e2 * b0 * b0 * LL * inv - P.e * b1 * G[i][j])
            quadratic.put_dS(P, C, r, i, j, 2.0 * e2 * b0 * b1 * LL * inv - P.e * b2 * G[i][j])
            quadratic.put_S(P, C, r, i, 2 + j, -P.e * b0 * Kc[j][i] * inv)
            quadratic.put_dS(P, C, r, i, 2 + j, -P.e * b1 * Kc[j][i] * inv)
            quadratic.put_S(P, C, r, 2 + i, j, -P.e * b0 * Kc[i][j] * inv)
            quadratic.put_dS(P, C, r, 2 + i, j, -P.e * b1 * Kc[i][j] * inv)
            quadratic.put_S(P, C, r, 2 + i, 2 + j, inv if i == j else 0.0)
            quadratic.put_dS(P, C, r, 2 + i, 2 + j, 0.0)
    quadratic.put_s(P, C, r, -P.e * P.d * b0)
    quadratic.put_ds(P, C, r, -P.e * P.d * b1)
    quadratic.finish(P, C, r)
    C[r, BETA] = b0
    C[r, BETA + 1] = b1


@njit(**INLINE)
def vecpot(P, C, r, q, A):
    A[0] = C[r, BETA] * ((1.0 + P.C00) * q[0] + (-1.0 + P.C01) * q[1])
    A[1] = C[r, BETA] * ((1.0 + P.C01) * q[0] + (1.0 + P.C11) * q[1])


@njit(**INLINE)
def efield(P, C, r, q, E):
    """E = -grad phi' - d_t A' = beta' C q - beta' (K + C) q = -beta' K q."""
    E[0] = -C[r, BETA + 1] * (q[0] - q[1])
    E[1] = -C[r, BETA + 1] * (q[0] + q[1])


@njit(**INLINE)
def bfield(P, C, r):
    """B_z = curl A' = beta ((K + C)_10 - (K + C)_01) = 2 beta."""
    return C[r, BETA] * ((1.0 + P.C01) - (-1.0 + P.C01))


class BetaParam(Param):
    """beta(t): 'paper' (B0 (1 + eps sin w t)), 'constant' (B0), or an expression of t."""

    def check(self, value):
        text = str(value).strip()
        if text in ("paper", "constant"):
            return text
        try:
            parse(text)
        except ExprError as err:
            raise InputError(f"beta(t) = {quoted(text)}: {err}") from None
        return text


PAPER_BETA = r"\beta(t) = B_0\,\big(1+\varepsilon\,\sin(\omega t)\big)"


@functools.lru_cache(maxsize=64)
def _singularity(text, T):
    """Expr.singularity of a typed beta(t) over [0, T], for each (text, T) once: a control change
    checks it before every run."""
    return parse(text).singularity(0.0, T)


class ChargedScene(Scene):
    def shown_equations(self, vals):
        """The last line is the beta(t) the values choose: the paper's, B0, or the typed expression."""
        beta = vals["beta"]
        line = {"paper": PAPER_BETA, "constant": r"\beta(t) = B_0"}.get(beta)
        return self.equations[:-1] + (line or rf"\beta(t) = {parse(beta).latex()}",)

    def unused(self, vals):
        """eps and w shape only the paper's beta(t); B0 is not in a typed one."""
        return {"paper": (), "constant": ("eps", "w")}.get(vals["beta"], ("B0", "eps", "w"))

    def check_horizon(self, vals, T):
        """A typed beta(t) with a pole in [0, T] (1/(t - 5)): a method that never evaluates beta at the
        pole steps over it and reaches T with large figures, one that does overflows there."""
        beta = vals["beta"]
        if beta in ("paper", "constant"):
            return
        t = _singularity(beta, float(T))
        if t is not None:
            raise InputError(f"beta(t) = {quoted(beta)} leaves floating-point range at t = {t:.6g} (it or its first "
                             f"two derivatives overflow there, or divide by 0), inside the run's [0, {T:g}]: change "
                             f"beta(t), or shorten T below {t:.6g}")

    def pack(self, vals):
        g = GAUGES[vals["gauge"]]
        beta = vals["beta"]
        if beta == "paper":
            kind, (ops, args) = BETA_PAPER, zero_programs(3)
        elif beta == "constant":
            kind, (ops, args) = BETA_CONSTANT, zero_programs(3)
        else:
            kind, (ops, args) = BETA_EXPRESSION, programs(parse(beta), 3)
        return ChargedParams(vals["m"], vals["e"], vals["B0"], vals["eps"], vals["w"], kind,
                      float(g.C[0][0]), float(g.C[0][1]), float(g.C[1][1]), g.d, ops, args)

    def initial(self, vals):
        """(x0, y0), and (px0, py0) given in the original gauge moved into the run's gauge."""
        q = np.array([vals["x0"], vals["y0"]], dtype=float)
        p = np.array([vals["px0"], vals["py0"]], dtype=float)
        P = self.pack(vals)
        _, pp, _ = gauge_map(P, np.zeros(1), q[None], p[None], np.zeros(1))
        return q, pp[0]


def betas(P, t):
    """beta, beta', beta'' on an array of times: shape (3, len(t))."""
    t = np.ascontiguousarray(t, dtype=float)
    out = np.empty((3, t.size))
    beta_many(P, t, out)
    return out


def gauge_matrix(P):
    return np.array([[P.C00, P.C01], [P.C01, P.C11]])


def _per_time(a, like):
    """Reshape a (K,) time series to broadcast against an array (K, ...)."""
    return a.reshape((-1,) + (1,) * (like.ndim - 1))


def vector_potential(P, t, q):
    """A' = A + grad chi = beta (K + C) q, for q of shape (K, ..., 2) at times t (K,)."""
    b = betas(P, np.atleast_1d(t))[0]
    return _per_time(b, q) * (q @ (K + gauge_matrix(P)).T)


def scalar_potential(P, t, q):
    """phi' = phi - d_t chi = -(q.C q beta'/2 + d beta), phi = 0 in the original gauge."""
    b0, b1, _ = betas(P, np.atleast_1d(t))
    quad = 0.5 * np.sum(q * (q @ gauge_matrix(P).T), axis=-1)
    return -(_per_time(b1, quad) * quad + _per_time(P.d * b0, quad))


def mechanical(P, t, q, p):
    """Pi = p - e A'(q, t): the gauge-invariant momentum."""
    return p - P.e * vector_potential(P, t, q)


def gauge_jacobian(src, target, t):
    """The Jacobian in z = (q, p) of G_target o G_src^-1 at times t (K,): [[I, 0], [e beta dC, I]],
    dC = C_target - C_src (K, 4, 4)."""
    b = betas(src, t)[0]
    G = np.tile(np.eye(4), (len(b), 1, 1))
    G[:, 2:, :2] = src.e * b[:, None, None] * (gauge_matrix(target) - gauge_matrix(src))
    return G


def gauge_map(P, t, q, p, pt, inverse=False):
    """G_chi of the gauge in P: (q, p, t, p_t) -> (q, p + e grad chi, t, p_t + e d_t chi).

    Arrays: t (K,), q and p (K, ..., 2), pt (K, ...). inverse applies G_chi^-1.
    """
    b0 = betas(P, np.atleast_1d(t))[0]
    grad_chi = _per_time(b0, q) * (q @ gauge_matrix(P).T)
    dt_chi = -scalar_potential(P, t, q)
    sign = -1.0 if inverse else 1.0
    return q, p + sign * P.e * grad_chi, pt + sign * P.e * dt_chi


SCENE = ChargedScene(
    name="charged",
    title="Charged particle in a time-dependent field, five gauges",
    summary="H = |p − e A(q, t)|²/(2m) + e φ(q, t) in the plane, A = β(t) (x − y, x + y), φ = 0 in the "
            "original gauge; β(t) = B₀ (1 + ε sin(ωt)) in the paper.",
    look_for="q and the mechanical momentum Π = p − eA agree across gauges (to the method's order for per-gauge "
             "runs, to round-off for transported maps); the canonical momentum p does not. Boris gives the same q "
             "and Π in every gauge.",
    equations=(r"H = \frac{1}{2m}\left|\,p - eA(q,t)\,\right|^2 + e\,\phi(q,t)",
               (r"A = \beta(t)\,(x-y,\;x+y),\quad \phi = 0,\quad B = 2\beta(t)\,e_z,\quad "
               r"E = -\dot\beta(t)\,(x-y,\;x+y)"),
               (r"A^{\prime} = A + \nabla\chi,\quad \phi^{\prime} = \phi - \partial_t\chi,\quad "
               r"G_\chi(q,p,t,p_t) = (q,\,p+e\nabla\chi,\,t,\,p_t+e\,\partial_t\chi)"),
               PAPER_BETA),
    params=(
        Param("m", 1.0, "mass m", (1e-3, 1e3)),
        Param("e", 1.0, "charge e", (-1e3, 1e3)),
        Param("B0", 0.05, "field scale B0 of beta(t)", (-1e3, 1e3)),
        Param("eps", 10.0, "modulation depth eps of the paper's beta(t)", (-1e3, 1e3)),
        Param("w", 2.0, "modulation frequency w of the paper's beta(t)", (0.0, 1e3)),
        BetaParam("beta", "paper", "beta(t): 'paper' = B0 (1 + eps sin(w t)), 'constant' = B0, "
                  "or an expression of t (numbers, t, pi, + - * / ^, sin cos tan exp log sqrt tanh)"),
        Param("gauge", "original", "gauge of the run", choices=tuple(GAUGES)),
        Param("x0", 0.1, "initial x", (-1e3, 1e3), initial=True),
        Param("y0", 0.4, "initial y", (-1e3, 1e3), initial=True),
        Param("px0", 0.5, "initial canonical p_x in the original gauge", (-1e3, 1e3), initial=True),
        Param("py0", -0.2, "initial canonical p_y in the original gauge", (-1e3, 1e3), initial=True),
    ),
    kernel=SceneKernel(ndof=2, ncoef=NCOEF, linear=True, coef=coef, energy=quadratic.energy,
                       grad=quadratic.grad, hess=quadratic.hess, dhdt=quadratic.dhdt,
                       vecpot=vecpot, efield=efield, bfield=bfield),
    Params=ChargedParams,
    h=0.001,
    T=20.0,
    time_scale=0.5,
    coordinates=("x", "y"),
    notes=tuple(g.caveat for g in GAUGES.values() if g.caveat),
    paper=Paper("Section 5: electric particle in an electromagnetic field, five gauges"),
    cases=(
        Case("Gyration in a breathing field",
             "A uniform field that slowly breathes, β = 1 + 0.2 sin(0.3t) (B = 2β: one gyration in "
             "about 3 time units), at h 0.15 to T 300. Look at |H + p_t|: RK4's starts below the "
             "midpoint rule's band, leaves it near t = 50 and ends five times above it, while the "
             "band stays put.",
             "midpoint", "rk4", 0.15, 300.0, values={"B0": 1.0, "eps": 0.2, "w": 0.3}, first=True),
        Case("Fig. gauge (charged, symplectic Euler, h 0.001, T 20)",
             "The charged particle in five gauges: q and Π agree across gauges, the canonical p does "
             "not; transported maps agree to round-off, per-gauge runs to the method's order.",
             "symplectic-euler", "rk4", 0.001, 20.0, view="gauges"),
        Case("Stiff field, strong B",
             "beta = 5 (1 + 10 sin 50t) reverses 16 times per unit time and gyrates at up to 110, about "
             "a radian a step at h = 0.01: both orbits leave the true one (|q| to 6-7 against 2.8) and "
             "neither method is accurate here. What structure survives differs: RK4's H + p_t reaches "
             "2e5 and midpoint's 5e3, and midpoint keeps the angular momentum x p_y - y p_x (not "
             "plotted) to round-off, where RK4's moves by 3e2.",
             "midpoint", "rk4", 0.01, 20.0, values={"B0": 5.0, "eps": 10.0, "w": 50.0}, hard=True),
        Case("Stiff field, weak B",
             "beta = 0.05 (1 + 10 sin 50t): slow gyration driven by a fast induced E field; both "
             "methods agree at h = 0.01.",
             "midpoint", "rk4", 0.01, 20.0, values={"B0": 0.05, "eps": 10.0, "w": 50.0}, hard=True),
    ),
    # Growth over the field's modulation w x eps: the parametric-resonance tongues of the gyration
    # (near w = 2.2 and 1.1 at B0 = 1). Over h x B0 it was stripes of noise, and at the first view's
    # T = 300 a log h axis down to 0.001 took 6e7 steps (15 s).
    map_axes=(("w", 0.0, 6.0, False), ("eps", 0.0, 1.0, False)),
    gauges=GAUGES,
    mechanical=mechanical,
    gauge_map=gauge_map,
    gauge_jacobian=gauge_jacobian,
    rank=4,
)
