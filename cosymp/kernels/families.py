"""Method families: each is a data tuple (what a method is) plus one member-step function.

A step advances one trajectory of the extended state (q, t, p, p_t) by h, given the scene's
time coefficients at the family's time offsets (row j of C at t + offsets[j] h, shared by every
member of an ensemble). z = (q, p) is updated in place; the new p_t is returned with a status.
Family data are arrays, so that every tableau of a family runs one compiled loop, its stack
scratch sized by kernels.stack's bounds; the Gauss tableaus and the explicit ones of at most
methods.FIXED_STAGES stages are tuples instead, so that their stage count (and the size of the
Gauss Newton solve) is known at compile time: one loop per stage count, see methods._fixed. So are
the time offsets of the families whose count is fixed (Theta's one, Boris's three, Exact's two):
as an array, a step's coefficient rows were filled by a loop of run-time length through memory
(damped midpoint 26 -> 22 ns a step, its run with every figure 52 -> 48). Linear scenes use the
same families as matrices (kernels.linear).

Sums of p_t increments start from -0.0, not 0.0 * pt: x + (-0.0) is x for every x, so the compiler
drops that first addition (x + 0.0 is not x when x is -0.0), and the float unifies with a complex
increment in the complex-step tangent maps.
"""
from collections import namedtuple

import numpy as np
from numba import njit
from numba.core import types
from numba.extending import overload

from .dispatch import (
    _IR_INLINE,
    INLINE,
    IR_INLINE,
    bfield,
    coef,
    dhdt,
    drift,
    efield,
    energy,
    flow,
    grad,
    hess,
    interleaved,
    is_linear,
    kick,
    ncoef,
    ndof,
    nudge,
    rotate,
    vecpot,
)
from .linalg import factor, solve, substitute
from .stack import matrices, stage_flat, stage_pivots, stage_square, stage_unknowns, stage_vectors, vectors

OK, OVERFLOW, NEWTON, SINGULAR = 0, 1, 2, 3
START = -1  # H is not finite at the start: no step taken
NEWTON_MAX = 50
NEWTON_TOL = 4e-15

Explicit = namedtuple("Explicit", "A b stage offsets")
Explicit.__doc__ = ("Explicit Runge-Kutta tableau (A row-major, flattened); stage i is evaluated at "
                    "offsets[stage[i]].")
Theta = namedtuple("Theta", "wq0 wq1 wp0 wp1 offsets")
Theta.__doc__ = ("Theta step: H evaluated at q = wq0 q_k + wq1 q_k+1, p = wp0 p_k + wp1 p_k+1, "
                 "t = t_k + offsets[0] h.")
Gauss = namedtuple("Gauss", "A b offsets")
Gauss.__doc__ = "Implicit (collocation) Runge-Kutta tableau (A flattened), nodes = offsets; tuples."
Composition = namedtuple("Composition", "gammas offsets")
Composition.__doc__ = "Midpoint sub-steps of sizes gammas[i] h, sub-step i centred at offsets[i]."
Boris = namedtuple("Boris", "offsets")
Boris.__doc__ = "Boris push (drift-kick-drift), offsets (0, 1/2, 1)."
Exact = namedtuple("Exact", "offsets")
Exact.__doc__ = "The scene's exact flow, offsets (0, 1)."
Splitting = namedtuple("Splitting", "a b kick offsets")
Splitting.__doc__ = ("Explicit splitting of a separable H = T(p, t) + V(q, t), t carried by T: for each i, the "
                     "kick b[i] h (the exact flow of V at the time offsets[kick[i]]; skipped where b[i] = 0), "
                     "then the drift a[i] h (the exact flow of T + p_t).")
Perturbed = namedtuple("Perturbed", "a b kick offsets")
Perturbed.__doc__ = ("Explicit splitting of a near-integrable H = H0 + (H - H0), H0 with a closed-form flow and "
                     "H - H0 small: as Splitting, the kick b[i] h being the flow of H - H0 (nudge) and the drift "
                     "a[i] h the flow of H0 + p_t (rotate).")


@njit(**INLINE)
def pending(D, P):
    """Whether the loop leaves family D's coefficient rows pending for its step to compute where a
    stage first uses them (row): an interleaved family (the splittings, kernels.registry) on a
    nonlinear scene, where the kicks' own transcendentals make a long dependency chain that the
    rows' then overlap. On a linear scene the chain is short and the check costs more than it
    saves (measured when rk4 was interleaved too: on modulated 37 -> 50 ns a step)."""
    return interleaved(D) and not is_linear(P)


@njit(**INLINE)
def row(D, P, C, j):
    """Make row j of C hold its coefficients where D's rows are pending: compute them now if the
    loop left the row's time in the last column (kernels.loops._coefs), then mark it NaN."""
    if pending(D, P):
        t = C[j, ncoef(P)]
        if not np.isnan(t):
            coef(P, t, C, j)
            C[j, ncoef(P)] = np.nan


@njit(**INLINE)
def stage_row(D, i):
    """The coefficient row of explicit stage i: 0, a constant, where D has one row (explicit Euler).
    Read from D.stage, a run-time index, the row stayed in memory and its coefficients were loaded
    every step; indexed by a constant, the compiler keeps it in registers (modulated euler 19.5 ->
    18.0 ns a step)."""
    return 0 if len(D.offsets) == 1 else D.stage[i]


def newton_done(dz, ndz, z, nz, prev):
    """Whether Newton has converged, and the size of its correction dz: to round-off, a small
    correction or one that stopped shrinking near the floor. In complex arithmetic (a tangent
    map's complex step) after the first correction: the real part is the real step's root, kept
    by newton_update, so the real correction, which is never applied, measures that root's
    round-off and a root the real step accepted near the floor could repeat it above the
    tolerance on every pass, to NEWTON_MAX; and the imaginary part solves a linear system (the
    step's linearization at that root; COMPLEX_STEP's square is far below round-off), which one
    correction solves."""


@overload(newton_done, jit_options=_IR_INLINE, inline="always")
def _newton_done(dz, ndz, z, nz, prev):
    if isinstance(z.dtype, types.Complex):
        return lambda dz, ndz, z, nz, prev: (True, 0.0)

    def converged(dz, ndz, z, nz, prev):
        size = 1.0
        for i in range(nz):
            size = max(size, abs(z[i]))
        corr = 0.0
        for i in range(ndz):
            corr = max(corr, abs(dz[i]))
        return corr <= NEWTON_TOL * size or (corr <= 1e-10 * size and corr >= 0.5 * prev), corr
    return converged


def newton_update(x, dx):
    """x + dx, Newton's correction; in complex arithmetic (a tangent map's complex step, which
    starts from the real step's solution: theta_start, gauss_start) the imaginary part alone, so
    that the real part stays the real step's own and the imaginary part solves its linearization
    there."""


@overload(newton_update, jit_options=_IR_INLINE, inline="always")
def _newton_update(x, dx):
    if isinstance(x, types.Complex):
        return lambda x, dx: complex(x.real, x.imag + dx.imag)
    return lambda x, dx: x + dx


def theta_start(P, C, j, h, wq0, wq1, wp0, wp1, z, z1):
    """Newton's start z1 for theta_core from z, and a status: z itself; in complex arithmetic
    the real step's solution from Re z (its status if it fails). A complex step cold from z
    iterated its real part with other roundings than the real step (products contracted
    otherwise): where Newton converges only barely (h times the flow's rate about 3-10 on
    kapitza), one converged and the other not, or to another root, and a fused run stopped at a
    tangent map whose step converges (17 of 207 kapitza runs of midpoint, theta and gauss4,
    q0 in 1-3, h in 0.05-0.6, 60 time units). From the real root, one iteration solves for the
    imaginary part: the derivative of the root the step took."""


@overload(theta_start, jit_options=_IR_INLINE, inline="always")
def _theta_start(P, C, j, h, wq0, wq1, wp0, wp1, z, z1):
    if not isinstance(z.dtype, types.Complex):
        def cold(P, C, j, h, wq0, wq1, wp0, wp1, z, z1):
            for i in range(z.shape[0]):
                z1[i] = z[i]
            return OK
        return cold

    def warm(P, C, j, h, wq0, wq1, wp0, wp1, z, z1):
        V = vectors(P, 5, 0.0)
        MM = matrices(P, 2, 0.0)
        zr = V[4]
        for i in range(z.shape[0]):
            zr[i] = z[i].real
            V[0, i] = zr[i]
        status, _ = theta_newton(P, C, j, h, wq0, wq1, wp0, wp1, zr, 0.0, V, MM[0], MM[1])
        for i in range(z.shape[0]):
            z1[i] = zr[i]
        return status
    return warm


def gauss_start(D, P, C, t, h, z, Zs):
    """The Gauss stages' Newton start from z, and a status: z in every stage; in complex
    arithmetic the real step's stages from Re z (theta_start says why)."""


@overload(gauss_start, jit_options=_IR_INLINE, inline="always")
def _gauss_start(D, P, C, t, h, z, Zs):
    if not isinstance(z.dtype, types.Complex):
        def cold(D, P, C, t, h, z, Zs):
            for i in range(len(D.b)):
                for r in range(z.shape[0]):
                    Zs[i, r] = z[r]
            return OK
        return cold

    def warm(D, P, C, t, h, z, Zs):
        W = gauss_work(D, P, 0.0)
        zr = vectors(P, 1, 0.0)[0]
        for r in range(z.shape[0]):
            zr[r] = z[r].real
        for i in range(len(D.b)):
            for r in range(z.shape[0]):
                W[0][i, r] = zr[r]
        status, _ = gauss_newton(D, P, C, t, h, zr, 0.0, W)
        for i in range(len(D.b)):
            for r in range(z.shape[0]):
                Zs[i, r] = W[0][i, r]
        return status
    return warm


@njit(**INLINE)
def theta_core(P, C, j, h, wq0, wq1, wp0, wp1, z, pt, V, Hm, Jm):
    """Solve q1 - q = h H_p(Z), p1 - p = -h H_q(Z) with Z the weighted point, by Newton."""
    status = theta_start(P, C, j, h, wq0, wq1, wp0, wp1, z, V[0])
    if status != OK:
        return status, pt
    return theta_newton(P, C, j, h, wq0, wq1, wp0, wp1, z, pt, V, Hm, Jm)


@njit(**INLINE)
def theta_newton(P, C, j, h, wq0, wq1, wp0, wp1, z, pt, V, Hm, Jm):
    """theta_core's Newton iteration from its start V[0]."""
    n = ndof(P)
    m = 2 * n
    z1, Zt, g, F = V[0], V[1], V[2], V[3]
    prev = np.inf
    status = NEWTON
    for it in range(NEWTON_MAX):
        for i in range(n):
            Zt[i] = wq0 * z[i] + wq1 * z1[i]
            Zt[n + i] = wp0 * z[n + i] + wp1 * z1[n + i]
        grad(P, C, j, Zt, g)
        hess(P, C, j, Zt, Hm)
        for i in range(n):
            F[i] = z[i] - z1[i] + h * g[n + i]
            F[n + i] = z[n + i] - z1[n + i] - h * g[i]
        for i in range(n):
            for c in range(m):
                w = wq1 if c < n else wp1
                Jm[i, c] = -h * w * Hm[n + i, c]
                Jm[n + i, c] = h * w * Hm[i, c]
        for i in range(m):
            Jm[i, i] += 1.0
        if not solve(Jm, F, m, 1):
            status = SINGULAR
            break
        for i in range(m):
            z1[i] = newton_update(z1[i], F[i])
        done, prev = newton_done(F, m, z1, m, prev)
        if done or is_linear(P):
            status = OK
            break
    if status == OK:
        for i in range(n):
            Zt[i] = wq0 * z[i] + wq1 * z1[i]
            Zt[n + i] = wp0 * z[n + i] + wp1 * z1[n + i]
        pt = pt - h * dhdt(P, C, j, Zt)
        for i in range(m):
            z[i] = z1[i]
    return status, pt


@njit(**IR_INLINE)
def theta_work(D, P, z):
    return vectors(P, 4, z), matrices(P, 2, z)


@njit(**INLINE)
def theta_step(D, P, C, t, h, z, pt, W):
    V, MM = W
    return theta_core(P, C, 0, h, D.wq0, D.wq1, D.wp0, D.wp1, z, pt, V, MM[0], MM[1])


@njit(**INLINE)
def composition_step(D, P, C, t, h, z, pt, W):
    V, MM = W
    status = OK
    for i in range(len(D.gammas)):
        status, pt = theta_core(P, C, i, D.gammas[i] * h, 0.5, 0.5, 0.5, 0.5, z, pt, V, MM[0], MM[1])
        if status != OK:
            break
    return status, pt


@njit(**IR_INLINE)
def explicit_work(D, P, z):
    return stage_vectors(D, P, z), vectors(P, 2, z)


@njit(**INLINE)
def explicit_step(D, P, C, t, h, z, pt, W):
    K, V = W
    Y, g = V[0], V[1]
    n = ndof(P)
    m = 2 * n
    s = len(D.b)
    dpt = -0.0
    for i in range(s):
        for r in range(m):
            Y[r] = z[r]
        for j in range(i):
            a = h * D.A[i * s + j]
            if a != 0.0:
                for r in range(m):
                    Y[r] += a * K[j, r]
        j = stage_row(D, i)
        grad(P, C, j, Y, g)
        for r in range(n):
            K[i, r] = g[n + r]
            K[i, n + r] = -g[r]
        dpt += D.b[i] * dhdt(P, C, j, Y)
    for i in range(s):
        bh = h * D.b[i]
        for r in range(m):
            z[r] += bh * K[i, r]
    return OK, pt - h * dpt


@njit(**IR_INLINE)
def gauss_work(D, P, z):
    return (stage_vectors(D, P, z), stage_vectors(D, P, z), vectors(P, 2, z), stage_flat(D, P, z),
            matrices(P, 1, z)[0], stage_square(D, P, z), stage_pivots(D, P))


@njit(**IR_INLINE)
def _gauss_residual(D, P, C, h, z, Zs, Fs, F, y, g):
    """F = z - Z_i + h sum_j A_ij f(Z_j) for every stage i."""
    n = ndof(P)
    m = 2 * n
    s = len(D.b)
    for j in range(s):
        for r in range(m):
            y[r] = Zs[j, r]
        grad(P, C, j, y, g)
        for r in range(n):
            Fs[j, r] = g[n + r]
            Fs[j, n + r] = -g[r]
    for i in range(s):
        for r in range(m):
            acc = z[r] - Zs[i, r]
            for j in range(s):
                acc += h * D.A[i * s + j] * Fs[j, r]
            F[i * m + r] = acc


@njit(**IR_INLINE)
def _gauss_newton(D, P, C, h, Zs, F, y, Hm, Jm, piv):
    """The Newton correction of the stages: Jm (the residual's Jacobian, negated) factored, F
    overwritten with Jm^-1 F and added to them. Returns False if Jm is singular."""
    n = ndof(P)
    m = 2 * n
    s = len(D.b)
    for j in range(s):
        for r in range(m):
            y[r] = Zs[j, r]
        hess(P, C, j, y, Hm)
        for i in range(s):
            a = h * D.A[i * s + j]
            for r in range(n):
                for c in range(m):
                    Jm[i * m + r, j * m + c] = -a * Hm[n + r, c]
                    Jm[i * m + n + r, j * m + c] = a * Hm[r, c]
    for r in range(s * m):
        Jm[r, r] += 1.0
    if not factor(Jm, piv, stage_unknowns(D, P)):
        return False
    _gauss_correct(D, P, Zs, F, Jm, piv)
    return True


@njit(**IR_INLINE)
def _gauss_correct(D, P, Zs, F, Jm, piv):
    m = 2 * ndof(P)
    s = len(D.b)
    substitute(Jm, piv, F, stage_unknowns(D, P), 1)
    for i in range(s):
        for r in range(m):
            Zs[i, r] = newton_update(Zs[i, r], F[i * m + r])


@njit(**INLINE)
def gauss_step(D, P, C, t, h, z, pt, W):
    """Collocation: stage values Z_i = z + h sum_j A_ij f(Z_j, t + c_j h), solved by Newton.

    On a linear scene one Newton step solves the stages exactly but for the factorization's
    round-off, which is systematic where the matrix changes slowly from step to step: H + p_t
    drifted (gauss6 on damped, gamma = 2e-4, h = 0.1, 2e6 steps from 16 nearby starts: the mean of
    H + p_t at the end -4.8e-13, 12.8 standard errors from 0). A second step with the same factors,
    from the residual, refines the stages (mean -2.3e-14, 0.5 standard errors; README, round-off)."""
    status = gauss_start(D, P, C, t, h, z, W[0])
    if status != OK:
        return status, pt
    return gauss_newton(D, P, C, t, h, z, pt, W)


@njit(**INLINE)
def gauss_newton(D, P, C, t, h, z, pt, W):
    """gauss_step's Newton iteration from its start, the stages W[0]."""
    Zs, Fs, V, F, Hm, Jm, piv = W
    y, g = V[0], V[1]
    n = ndof(P)
    m = 2 * n
    s = len(D.b)
    if is_linear(P):
        _gauss_residual(D, P, C, h, z, Zs, Fs, F, y, g)
        status = SINGULAR
        if _gauss_newton(D, P, C, h, Zs, F, y, Hm, Jm, piv):
            _gauss_residual(D, P, C, h, z, Zs, Fs, F, y, g)
            _gauss_correct(D, P, Zs, F, Jm, piv)
            status = OK
    else:
        prev = np.inf
        status = NEWTON
        for it in range(NEWTON_MAX):
            _gauss_residual(D, P, C, h, z, Zs, Fs, F, y, g)
            if not _gauss_newton(D, P, C, h, Zs, F, y, Hm, Jm, piv):
                status = SINGULAR
                break
            done, prev = newton_done(F, s * m, z, m, prev)
            if done:
                status = OK
                break
    if status == OK:
        dpt = -0.0
        for j in range(s):
            for r in range(m):
                y[r] = Zs[j, r]
            grad(P, C, j, y, g)
            bh = h * D.b[j]
            for r in range(n):
                z[r] += bh * g[n + r]
                z[n + r] -= bh * g[r]
            dpt += D.b[j] * dhdt(P, C, j, y)
        pt = pt - h * dpt
    return status, pt


@njit(**IR_INLINE)
def boris_work(D, P, z):
    return vectors(P, 5, z)


@njit(**INLINE)
def boris_core(P, C, h, z, pt, V):
    """Drift-kick-drift Boris push in (q, v), v = (p - e A) / m; fields at the half step.
    Leaves the half-step state (q, p) in V[4]."""
    q, v, A, E, zh = V[0], V[1], V[2], V[3], V[4]
    a = P.e * h / (2.0 * P.m)
    vecpot(P, C, 0, z, A)
    v0x = (z[2] - P.e * A[0]) / P.m
    v0y = (z[3] - P.e * A[1]) / P.m
    q[0] = z[0] + 0.5 * h * v0x
    q[1] = z[1] + 0.5 * h * v0y
    efield(P, C, 1, q, E)
    tau = a * bfield(P, C, 1)
    sig = 2.0 * tau / (1.0 + tau * tau)
    vx = v0x + a * E[0]
    vy = v0y + a * E[1]
    wx = vx + vy * tau
    wy = vy - vx * tau
    vx += wy * sig
    vy -= wx * sig
    v[0] = vx + a * E[0]
    v[1] = vy + a * E[1]
    vecpot(P, C, 1, q, A)
    zh[0] = q[0]
    zh[1] = q[1]
    zh[2] = 0.5 * P.m * (v0x + v[0]) + P.e * A[0]
    zh[3] = 0.5 * P.m * (v0y + v[1]) + P.e * A[1]
    pt = pt - h * dhdt(P, C, 1, zh)
    z[0] = q[0] + 0.5 * h * v[0]
    z[1] = q[1] + 0.5 * h * v[1]
    vecpot(P, C, 2, z, A)
    z[2] = P.m * v[0] + P.e * A[0]
    z[3] = P.m * v[1] + P.e * A[1]
    return OK, pt


@njit(**INLINE)
def boris_step(D, P, C, t, h, z, pt, W):
    return boris_core(P, C, h, z, pt, W)


@njit(**IR_INLINE)
def exact_work(D, P, z):
    return vectors(P, 1, z)


@njit(**INLINE)
def exact_step(D, P, C, t, h, z, pt, W):
    """The scene's exact flow; p_t follows from the exact conservation of H + p_t."""
    H0 = energy(P, C, 0, z)
    flow(P, t, t + h, z)
    return OK, pt + H0 - energy(P, C, 1, z)


@njit(**IR_INLINE)
def splitting_work(D, P, z):
    return vectors(P, 1, z)


@njit(**INLINE)
def splitting_step(D, P, C, t, h, z, pt, W):
    """Kicks and drifts, each an exact flow of one part of H + p_t (so each is symplectic on the
    extended phase space and their composition is): explicit, no Newton."""
    dpt = -0.0
    c = 0.0
    for i in range(len(D.b)):
        if D.b[i] != 0.0:
            row(D, P, C, D.kick[i])
            dpt += kick(P, C, D.kick[i], D.b[i] * h, z)
        if D.a[i] != 0.0:
            dpt += drift(P, t + c * h, D.a[i] * h, z)
            c += D.a[i]
    return OK, pt + dpt


@njit(**INLINE)
def perturbed_step(D, P, C, t, h, z, pt, W):
    """As splitting_step, with the flows of the near-integrable split: H0 + p_t (closed form: the
    unperturbed motion, t moving) and the small H - H0 (q and t staying)."""
    dpt = -0.0
    c = 0.0
    for i in range(len(D.b)):
        if D.b[i] != 0.0:
            row(D, P, C, D.kick[i])
            dpt += nudge(P, C, D.kick[i], D.b[i] * h, z)
        if D.a[i] != 0.0:
            dpt += rotate(P, t + c * h, D.a[i] * h, z)
            c += D.a[i]
    return OK, pt + dpt
