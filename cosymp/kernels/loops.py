"""The generic compiled loops: every scene and every method family runs through these.

Each step is taken in the scene's scaled coordinates (scenes.base.SceneKernel.scaling): the state
is scaled by exact powers of two and the coefficients are read at the shifted time, so that a
step's arithmetic stays in floating-point range while the state does.
"""
import math

import numpy as np
from numba import njit

from .borrow import borrow
from .dispatch import (
    INLINE,
    IR_INLINE,
    JIT,
    Vectorizing,
    coef,
    dhdt,
    energy,
    energy_coef,
    grad,
    lmatrix,
    lwork,
    ncoef,
    ndof,
    scaling,
    shift,
    step,
    work,
)
from .families import OK, OVERFLOW, START, pending
from .stack import coef_table, matrices, vectors

COMPLEX_STEP = 1e-50


@njit(**INLINE)
def _scale(P, t, scaled, prev, tau, up, down):
    """The scaling (e, tau, 2^e, 2^-e) of the step from t, e = 0 without `scaled` (a run whose range
    needs none: scenes.base.Scene.needs_scaling), given the last step's exponent `prev` and its
    tau and factors: recomputed only where e changed. That branch keeps the coefficients' times
    from waiting on a division every step (measured: 4 ns of a 26 ns damped midpoint step)."""
    e = scaling(P, t) if scaled else 0
    if e != prev:
        tau = shift(P, e)
        up, down = _factors(e)
    return e, tau, up, down


@njit(**INLINE)
def scaling_at(P, t):
    """(e, tau) of the step from t."""
    e = scaling(P, t)
    return e, shift(P, e)


@njit(**INLINE)
def _coefs(D, P, tk, tk1, h, tau, C, reuse, B, b):
    """Time coefficients at family D's offsets for the step from tk to tk1, read at the scene's
    time shifted by tau. With `reuse`, row b of B holds the first row (computed or still pending):
    the last step's end (same scaling), row u - 1 of C itself, or the row the fused loop computed
    there for H (kernels.survey._fused). Where D's rows are `pending` (an interleaved family on a
    nonlinear scene), each row is left for the step to compute where it uses it
    (kernels.families.row): its time goes in the last column, which the step sets to NaN."""
    offsets = D.offsets
    u = len(offsets)
    nc = ncoef(P)
    for j in range(u):
        if j == 0 and reuse:
            for c in range(nc + 1):
                C[0, c] = B[b, c]
            continue
        t = (tk1 if offsets[j] == 1.0 else tk + offsets[j] * h) - tau
        if pending(D, P):
            C[j, nc] = t
        else:
            coef(P, t, C, j)


@njit(**INLINE)
def _reusable(D):
    """Whether family D's first coefficient row of a step is the last row of the step before (its
    offsets run from 0 to 1)."""
    u = len(D.offsets)
    return u > 1 and D.offsets[0] == 0.0 and D.offsets[u - 1] == 1.0


@njit(**INLINE)
def _step_start(D, P, t0, h, g, fresh, scaled, prev, tau, up, down, C, reusable, B, b):
    """The start of step g from t0: its scaling (`_scale`, given the last step's) and its time
    coefficients into C (`_coefs`, reusing row b of B, the last step's end, unless `fresh` or the
    scaling changed). Returns (e, tau, 2^e, 2^-e, the step's start time shifted by tau)."""
    e, tau, up, down = _scale(P, t0 + g * h, scaled, prev, tau, up, down)
    _coefs(D, P, t0 + g * h, t0 + (g + 1) * h, h, tau, C, reusable and not fresh and e == prev, B, b)
    return e, tau, up, down, t0 + g * h - tau


@njit(**INLINE)
def _factors(e):
    """(2^e, 2^-e): exact powers of two (0 or inf only where |e| passes the exponent range, at
    the end of the state's own range)."""
    return math.ldexp(1.0, e), math.ldexp(1.0, -e)


# The state helpers below (_rescale to _accept, apply_matrix, _advance) take the scene's parameters
# P rather than the state's size: m = 2 ndof(P) is a constant of the scene, so each is compiled once
# per scene (per (scene, family) for _advance), its loops unrolled, and cached. Inlined in numba's IR
# (kernels.dispatch.IR_INLINE, which a size received as an argument needs) they were typed and
# lowered again in every loop of every (scene, family): with survey's defects and grow so too, the
# cold compile inside CI took 627 -> 507 s on 2 cores (side by side, damped x Theta, Explicit and
# kapitza x Gauss 179 -> 156 s), and the steps measured the same (damped single runs, ensembles and
# fused runs with maps, kapitza gauss4: 0.94-1.04x).
# LITERALS: numba types a constant int argument as a literal and compiles a separate copy of a
# function called with it (and, while it infers a variable's type, one for the literal the variable
# starts as): the loops pass these helpers int64 values only.
@njit(**INLINE)
def _rescale(z, P, e, qf, pf):
    """q <- q qf, p <- p pf in place for a state z of the scene of P, unless e = 0 (qf, pf powers
    of two: exact)."""
    n = ndof(P)
    if e != 0:
        for i in range(n):
            z[i] *= qf
            z[n + i] *= pf


@njit(**INLINE)
def _record_start(t0, Z, PT, Trec, Zrec, PTrec, dZrec, P):
    m = 2 * ndof(P)
    Trec[0] = t0
    for i in range(Z.shape[0]):
        PTrec[0, i] = PT[i]
        for r in range(m):
            Zrec[0, i, r] = Z[i, r]
            if dZrec.shape[0] > 0:
                dZrec[0, i, r] = np.nan


@njit(**INLINE)
def _finite(pt, z, P):
    """Whether pt and the state z are all finite: 0 x is 0 for every finite x and NaN otherwise, so
    one comparison tests them all (a test and branch per value cost 1-2 ns of a 20 ns leapfrog step)."""
    m = 2 * ndof(P)
    nan = 0.0 * pt
    for r in range(m):
        nan += 0.0 * z[r]
    return nan == 0.0


@njit(**INLINE)
def _store(Z, PT, i, z, pt, P):
    m = 2 * ndof(P)
    PT[i] = pt
    for r in range(m):
        Z[i, r] = z[r]


@njit(**INLINE)
def _record(rec, i, z, old, pt, Zrec, PTrec, dZrec, P):
    m = 2 * ndof(P)
    PTrec[rec, i] = pt
    for r in range(m):
        Zrec[rec, i, r] = z[r]
        if dZrec.shape[0] > 0:
            dZrec[rec, i, r] = z[r] - old[r]


@njit(**INLINE)
def _accept(status, i, z, old, pt, Z, PT, rec, recording, Zrec, PTrec, dZrec, P):
    """Check the member's new state, store it, record it. Returns the status."""
    if status == OK and not _finite(pt, z, P):
        status = OVERFLOW
    if status == OK:
        _store(Z, PT, i, z, pt, P)
        if recording:
            _record(rec, i, z, old, pt, Zrec, PTrec, dZrec, P)
    return status


@njit(**INLINE)
def _load(Z, i, old, zs, P, e, up, down):
    """old <- Z[i]; zs <- old in the step's scaled coordinates (exponent e)."""
    for r in range(2 * ndof(P)):
        old[r] = Z[i, r]
        zs[r] = old[r]
    _rescale(zs, P, e, down, up)


@njit(**INLINE)
def apply_matrix(Z, i, M, Q, old, zs, z, P, e, up, down):
    """A linear scene's step on member i: old <- Z[i]; z <- M zs with zs = old in the step's scaled
    coordinates (exponent e), z left scaled; returns zs.Q zs, p_t's quadratic term."""
    m = 2 * ndof(P)
    quad = 0.0
    _load(Z, i, old, zs, P, e, up, down)
    for r in range(m):
        acc = 0.0
        qr = 0.0
        for c in range(m):
            acc += M[r, c] * zs[c]
            qr += Q[r, c] * zs[c]
        z[r] = acc
        quad += zs[r] * qr
    return quad


@njit(**INLINE)
def apply_map(Z, i, M, old, zs, z, P, e, up, down):
    """apply_matrix without p_t: z <- M zs alone (a test of Q's rows inside its loop cost the
    step-matrix loop of a 4-member ensemble 20%: damped midpoint 45 -> 53 ns a step)."""
    m = 2 * ndof(P)
    _load(Z, i, old, zs, P, e, up, down)
    for r in range(m):
        acc = 0.0
        for c in range(m):
            acc += M[r, c] * zs[c]
        z[r] = acc


@njit(**INLINE)
def _add(S, Cc, d):
    """Kahan's compensated sum: (S, Cc) holds p_t = S - Cc, Cc the negated error of S; returns the
    pair for p_t + d. p_t is a sum of one increment per step, and its round-off (up to half an ulp
    per step) overtook the oscillation of H + p_t of the high-order symplectic methods over a long
    run. Kahan's four additions rather than Neumaier's nine operations: p_t's increments are small
    against p_t, where both are exact to first order, and the five more cost 1 ns of a 20 ns
    leapfrog step."""
    y = d - Cc
    s = S + y
    return s, (s - S) - y


@njit(**INLINE)
def _advance(D, P, C, tk, h, z, W, e, up, down, S, Cc):
    """One member's step of z in place (taken in the step's scaled coordinates) and its p_t
    increment added to the compensated sum (S, Cc): returns (status, S, Cc). p_t enters no step
    otherwise, so the step gets -0.0 for it (see kernels.families) and returns the increment alone."""
    _rescale(z, P, e, down, up)
    status, dpt = step(D, P, C, tk, h, z, -0.0, W)
    _rescale(z, P, e, up, down)
    s, c = _add(S, Cc, dpt)
    return np.int64(status), s, c  # an explicit family's status is a literal OK (LITERALS)


@njit(**INLINE)
def coef_at(P, t, C):
    """What H reads of row 0 of C at t (energy_coef), read at the step's shifted time; returns that
    step's (e, 2^e, 2^-e)."""
    e, tau = scaling_at(P, t)
    energy_coef(P, t - tau, C, 0)
    up, down = _factors(e)
    return e, up, down


@njit(**INLINE)
def energy_at(P, C, z, zs, e, up, down):
    """H of the state z (copied into zs and scaled: H is invariant under the scaling) from row 0
    of C, given coef_at's scaling; NaN (no value, as the figures read it) where it is not finite.
    A state near the end of the floating-point range gave NaN by accident, 0 x Inf in the couplings
    of its scaled copy; a diagonal form (scenes.quadratic) skips them and gave Inf."""
    for r in range(zs.shape[0]):
        zs[r] = z[r]
    _rescale(zs, P, e, down, up)
    H = energy(P, C, 0, zs)
    return H if np.isfinite(H) else np.nan


@njit(**INLINE)
def _energies(P, T, Z, out, C, zs):
    """H of the members Z (K, N, 2n) at the times T (K,) into out (K, N)."""
    for k in range(T.shape[0]):
        e, up, down = coef_at(P, T[k], C)
        for i in range(Z.shape[1]):
            out[k, i] = energy_at(P, C, Z[k, i], zs, e, up, down)


@njit(**INLINE)
def _run(loop, D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, Hrec, scaled, start):
    """A compiled loop's call: the start state (Z, and PT or with `start` p_t = -H(z, t0), START if
    not finite) into the first record, where the loop takes it from; then the loop; then H of the
    recorded states into Hrec (where it has rows). One compiled call per run: each call from Python
    costs microseconds."""
    D, P, Z, PT, Trec, Zrec, PTrec, dZrec, Hrec = borrow((D, P, Z, PT, Trec, Zrec, PTrec, dZrec, Hrec))
    C = coef_table(D, P)
    zs = vectors(P, 1, 0.0)[0]
    _record_start(t0, Z, PT, Trec, Zrec, PTrec, dZrec, P)
    if start:
        e, up, down = coef_at(P, t0, C)
        for i in range(Z.shape[0]):
            H0 = energy_at(P, C, Z[i], zs, e, up, down)
            if not np.isfinite(H0):
                return START, 0
            PTrec[0, i] = -H0
    status, k, rec = loop(D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, scaled)
    if Hrec.shape[0] > 0:
        _energies(P, Trec[:rec], Zrec[:rec], Hrec[:rec], C, zs)
    return status, k


@njit(**INLINE)
def _matrix_loop(D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, scaled):
    C = coef_table(D, P)
    LW = lwork(D, P)
    MQ = matrices(P, 2, 0.0)
    M, Q = MQ[0], MQ[1]
    V = vectors(P, 3, 0.0)
    z, old, zs = V[0], V[1], V[2]
    reusable = _reusable(D)
    for i in range(Z.shape[0]):
        PT[i] = PTrec[0, i]
    S, Cc = PT.copy(), np.zeros_like(PT)
    rec = np.int64(1)  # int64 from the start, as the helpers' other int arguments (LITERALS)
    due = stride  # a countdown: a remainder per step, (k + 1) % stride, is an integer division
    prev = 0
    tau = 0.0
    up = down = 1.0
    for k in range(nsteps):
        e, tau, up, down, tk = _step_start(D, P, t0, h, k, k == 0, scaled, prev, tau, up, down, C, reusable,
                                           C, np.int64(len(D.offsets) - 1))
        prev = e
        s = lmatrix(D, P, C, tk, h, M, Q, LW)
        due -= 1
        recording = due == 0 or k + 1 == nsteps
        if due == 0:
            due = stride
        for i in range(Z.shape[0]):
            quad = apply_matrix(Z, i, M, Q, old, zs, z, P, e, up, down)
            _rescale(z, P, e, up, down)
            sum_, comp = _add(S[i], Cc[i], -(0.5 * quad + s))
            status = _accept(np.int64(OK), i, z, old, sum_ - comp, Z, PT, rec, recording, Zrec, PTrec, dZrec, P)
            if status != OK:
                return status, k, rec
            S[i], Cc[i] = sum_, comp
        if recording:
            Trec[rec] = t0 + (k + 1) * h
            rec += 1
    return OK, nsteps, rec


@njit(**IR_INLINE)
def _member_scratch(D, P):
    """A member loop's stack scratch (inlined in numba's IR, so that it is the loop's): the step's
    coefficient rows and work, the state and the state before the step."""
    V = vectors(P, 2, 0.0)
    return coef_table(D, P), work(D, P, 0.0), V[0], V[1]


@njit(**INLINE)
def _one_loop(D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, scaled):
    """One member's loop: the family's step, its state, p_t and p_t's compensation kept in local
    variables from step to step, from the first record (Z and PT are not written: the caller passes
    its own start, uncopied). Read back from an array every step, the state cost a cheap step 1-2
    ns: the compiler must assume that storing into one array changes the others."""
    C, W, z, old = _member_scratch(D, P)
    m = 2 * ndof(P)
    reusable = _reusable(D)
    for r in range(m):
        z[r] = Zrec[0, 0, r]
    pt = PTrec[0, 0]
    S, Cc = pt, 0.0
    rec, first = np.int64(1), np.int64(0)  # record 1, member 0: int64, not literals (LITERALS)
    due = stride
    prev = 0
    tau = 0.0
    up = down = 1.0
    for k in range(nsteps):
        e, tau, up, down, tk = _step_start(D, P, t0, h, k, k == 0, scaled, prev, tau, up, down, C, reusable,
                                           C, np.int64(len(D.offsets) - 1))
        prev = e
        for r in range(m):
            old[r] = z[r]
        status, sum_, comp = _advance(D, P, C, tk, h, z, W, e, up, down, S, Cc)
        if status == OK and not _finite(sum_, z, P):
            status = OVERFLOW
        if status != OK:
            return status, k, rec
        S, Cc, pt = sum_, comp, sum_ - comp
        due -= 1
        if due == 0 or k + 1 == nsteps:
            _record(rec, first, z, old, pt, Zrec, PTrec, dZrec, P)
            Trec[rec] = t0 + (k + 1) * h
            rec += 1
            due = stride
    return OK, nsteps, rec


@njit(**JIT, pipeline_class=Vectorizing)
def propagate_matrix(D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, Hrec, scaled, start):
    """Advance the N members of (Z, PT) of a linear scene by nsteps steps of h from t0.

    One step matrix (M, Q, s) per step (kernels.linear), applied to every member:
    z <- M z, p_t <- p_t - (z.Q z / 2 + s). Records every stride-th state (index j is step
    j*stride, index 0 the start) and the final state (one more record when stride does not divide
    nsteps) and, when dZrec is non-empty, the increment z_k - z_(k-1) of the step before each
    record; H of each recorded state into Hrec where it has rows; with `start`, p_t starts at
    -H(z, t0). `scaled`: whether the run's range needs the scene's scaled steps. Returns
    (status, k): k steps completed; on failure step k -> k+1 failed and the records hold every
    recorded state before it; START (no step) where H is not finite at the start.
    """
    return _run(_matrix_loop, D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, Hrec, scaled, start)


@njit(**JIT)
def propagate_one(D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, Hrec, scaled, start):
    """As propagate_matrix, for one trajectory (Z and PT have one row) of any scene, but Z and PT are
    only read (the states it reaches are its records, the final one among them): the family's
    member step (Newton where the method is implicit), p_t summed with compensation (`_add`). An
    ensemble of a nonlinear scene runs through the fused loop (kernels.survey), which steps its
    members the same way: a member loop here too cost 11% of each (scene, family)'s compile and
    ran no faster (kapitza's 64-member ensembles, 79 ns per member step with rk4 in both)."""
    if Z.shape[0] != 1:
        raise ValueError("propagate_one steps one trajectory: Z must have one row")
    return _run(_one_loop, D, P, t0, h, Z, PT, nsteps, stride, Trec, Zrec, PTrec, dZrec, Hrec, scaled, start)


@njit(**JIT)
def tangent_matrix(D, P, h, T, Z, PT, M):
    """One-step tangent maps M[k] = d z_(k+1) / d z_k at t = T[k] of a linear scene: the step
    matrix itself, in the step's scaled coordinates (identical where the scene has no scaling;
    det and symplecticity do not depend on that symplectic scaling)."""
    D, P, T, M = borrow((D, P, T, M))
    C = coef_table(D, P)
    LW = lwork(D, P)
    Q = matrices(P, 1, 0.0)[0][:0]  # M alone (kernels.linear)
    for k in range(T.shape[0]):
        tau = scaling_at(P, T[k])[1]
        _coefs(D, P, T[k], T[k] + h, h, tau, C, False, C, np.int64(0))
        lmatrix(D, P, C, T[k] - tau, h, M[k], Q, LW)
    return OK, T.shape[0]


@njit(**JIT)
def tangent_complex(D, P, h, T, Z, PT, M):
    """One-step tangent maps M[k] = d z_(k+1) / d z_k on the time slice t = T[k], by complex
    step on the member step: exact to round-off (no subtraction). In the step's scaled
    coordinates, as tangent_matrix."""
    D, P, T, Z, PT, M = borrow((D, P, T, Z, PT, M))
    C = coef_table(D, P)
    W = work(D, P, 0j)
    zc = vectors(P, 1, 0j)[0]
    m = 2 * ndof(P)
    zs = vectors(P, 1, 0.0)[0]
    for k in range(Z.shape[0]):
        e, tau = scaling_at(P, T[k])
        _coefs(D, P, T[k], T[k] + h, h, tau, C, False, C, np.int64(0))
        for r in range(m):
            zs[r] = Z[k, r]
        up, down = _factors(e)
        _rescale(zs, P, e, down, up)
        for j in range(m):
            for r in range(m):
                zc[r] = zs[r]
            zc[j] += 1j * COMPLEX_STEP
            status, _ = step(D, P, C, T[k] - tau, h, zc, PT[k] + 0j, W)
            if status != OK:
                return status, k
            for r in range(m):
                M[k, r, j] = zc[r].imag / COMPLEX_STEP
    return OK, Z.shape[0]


def tangent(setup):
    return tangent_matrix if setup.scene.kernel.linear else tangent_complex


@njit(**JIT)
def energies(P, T, Z, out):
    """H at recorded states: T (K,), Z (K, N, 2n) -> out (K, N)."""
    _energies(P, T, Z, out, np.empty((1, ncoef(P))), np.empty(Z.shape[2]))


@njit(**JIT)
def vector_field(P, t, z, out):
    """The extended vector field (dq/dt, dp/dt, dp_t/dt) at (z, t), for reference solvers."""
    n = ndof(P)
    C = np.empty((1, ncoef(P)))
    e, tau = scaling_at(P, t)
    coef(P, t - tau, C, 0)
    zs = z.copy()
    up, down = _factors(e)
    _rescale(zs, P, e, down, up)
    g = np.empty(2 * n)
    grad(P, C, 0, zs, g)
    for i in range(n):
        out[i] = g[n + i] * up
        out[n + i] = -g[i] * down
    out[2 * n] = -dhdt(P, C, 0, zs)
