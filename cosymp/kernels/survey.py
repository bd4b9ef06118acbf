"""The fused driver's compiled loop: step, form each step's tangent map, reduce the diagnostics.

One pass per call, nothing stored per step. The members take member steps, as
kernels.loops.propagate_one does, so a fused run's states are those of `simulate`'s single
trajectories and of its ensembles of a nonlinear scene (which it runs through this loop), on a
linear scene too (stepping by the step matrix instead gave p_t through its quadratic form
z.Q z/2, whose round-off grows with the spread of Q's entries: the splittings' Q, read off by
polarization, made |H + p_t| of the SRKN11b splitting on damped grow to 5e-3 by gamma t = 40 with
unscaled steps, and 1000x the member steps' round-off with scaled ones). One exception: in a run
that records nothing, on a linear scene, at a step whose map is formed, members 1.. take that
step matrix (_member), as `simulate`'s ensembles of a linear scene do, and carry no p_t: their p_t
enters no figure of such a run (H + p_t is member 0's), their states only the volume estimator,
and each costs a matrix product instead of a step. With the volume estimator's closed form
(_volume), the app's long run of the paper's damped run (5e6 steps, 4 members, 20,000 bins) went
from 99 to 68 ns a step with midpoint and from 142 to 100 with rk4 (in-process A/B, min of 5);
without the members' p_t (no Q formed, nothing stored for it), with the volume estimator's scratch
and the current bin's figures on the stack and in local variables (the compiler must assume that a
store into a heap array changes the others), to 56-58 with midpoint (benchmarks/drive.py --repeats
7, 2026-12-02). Member 0's one-step
tangent map M_k (the step matrix on a linear scene, a complex step of the member step
otherwise, in the step's scaled coordinates as kernels.loops.tangent_matrix and tangent_complex
give it) feeds the running maxima of |det M_k - 1| and of the symplecticity defect, and the
growth product; H + p_t of member 0 feeds its running maximum; with 2n + 2 members, members
1..2n+1 give the paper's volume estimator det[X^1 ... X^(2n+1)] of their increments (for bins or
per-record figures); and each of these is also reduced to per-bin minima and maxima over bins of `width` steps. The members'
states Z and p_t PT are advanced in place; a call may also record them at a stride, with the
figures of each recorded state (a comparison's plots), and stores nothing else per step.

Arguments of the loop (_fused): D, P, t0, h, Z, PT, nsteps as kernels.loops.propagate_matrix
takes them; first: the steps are numbered from `first`, at times t0 + (first + k) h, and S, Cc:
p_t's compensated sum and its compensation, carried from call to call, so that a run cut into
calls takes the same steps as one call; every: form member 0's tangent map at the steps k with
k % every == 0 (0: never); want: which figures to reduce (WANT_H: H + p_t; WANT_MAPS: det and
symplecticity of the maps), the growth product being kept wherever G is given; scaled: whether
the run's range needs the scene's scaled steps (scenes.base.Scene.needs_scaling);
acc: running maxima (ACC_*), updated in place; env: (bins, len(ENV)) per-bin reductions of this
call (bin b holds steps b*width .. (b+1)*width - 1; rows preset by the caller), tb (bins,) the
time after each bin's first step; G: the growth product (m x m, or 0 x 0 for none) and gstate
its (log scale, exponent, 1.0 while finite) as in diagnostics.MapGrowth; stride, Trec, Zrec,
PTrec, dZrec: records as kernels.loops.propagate_matrix makes them (record j is this call's
step j*stride, record 0 its start, the last its last step; none where Trec is empty), and F
(records - 1, 3): per record j, |det M - 1| and ||M^T J M - J|| of the map of the step from
record j (with every = stride, the steps mapped are the records'), and the paper's volume
estimator of the step into record j + 1 (diagnostics.paper_volume_form's entry j), where F has
rows. It returns (status, k, in_tangent, records made): k steps completed, and whether a failure
came from the tangent map's complex step.
"""
import math

import numpy as np
from numba import njit
from numba.core import types
from numba.extending import overload
from numba.np.unsafe.ndarray import to_fixed_tuple

from .borrow import borrow
from .dispatch import (
    _INLINE,
    _IR_INLINE,
    INLINE,
    JIT,
    coef,
    energy,
    energy_coef,
    is_linear,
    lmatrix,
    lwork,
    ncoef,
    ndof,
    step,
    work,
)
from .families import OK, OVERFLOW, START, row
from .loops import (
    COMPLEX_STEP,
    _accept,
    _add,
    _advance,
    _energies,
    _finite,
    _record,
    _record_start,
    _rescale,
    _reusable,
    _step_start,
    _store,
    apply_map,
    coef_at,
    energy_at,
)
from .stack import _scene, coef_table, matrices, vectors

ACC = ("H_ext_max_abs", "det_max_dev", "symp_max_dev", "symp_max_rel")
WANT_H, WANT_MAPS = 1, 2
RANGE = 64
LN2 = math.log(2.0)
ENV = ("H_min", "H_max", "vol_min", "vol_max", "det", "symp")


@njit(**INLINE)
def _most(a, b):
    """max(a, b), NaN if either is (numba's max drops a NaN argument, NumPy's maximum keeps it)."""
    return b if b > a or math.isnan(b) else a


@njit(**INLINE)
def _least(a, b):
    """min(a, b), NaN if either is."""
    return b if b < a or math.isnan(b) else a


# determinant, _copy and symplecticity are compiled on their own (INLINE, not IR_INLINE: see
# kernels.dispatch) although their loops run over a size they receive: their arguments' types are
# the same in every (scene, family), so each is compiled once and cached, where inlined in numba's
# IR they were typed and lowered again in each of the 43 fused loops, 10-12% of each group's
# compile (side by side: damped x Theta 35.0 -> 31.2 s, kapitza x Explicit 74.3 -> 65.6 s). Their
# loops then stay rolled where m is 2 or 4; the diagnosed steps that run them measured 0.98-1.03x
# (damped and modulated midpoint with the growth product, charged, kapitza's volume estimator).
# defects and grow, which run at every step of a map's or a sweep's run, take the scene's
# parameters P instead of m, as the state helpers of kernels.loops do: their size is a constant of
# the scene (2 ndof), so each is compiled once per scene with its loops unrolled, where inlined in
# numba's IR they were typed and lowered again in every fused loop. _flush (no size) is compiled
# once for all.


@njit(**INLINE)
def determinant(A, m):
    """det of A[:m, :m] by LU with partial pivoting (A is overwritten)."""
    d = 1.0
    for c in range(m):
        p = c
        big = abs(A[c, c])
        for i in range(c + 1, m):
            if abs(A[i, c]) > big:
                big = abs(A[i, c])
                p = i
        if big == 0.0:
            return 0.0
        if p != c:
            d = -d
            for j in range(c, m):
                A[c, j], A[p, j] = A[p, j], A[c, j]
        d *= A[c, c]
        inv = 1.0 / A[c, c]
        for i in range(c + 1, m):
            f = A[i, c] * inv
            for j in range(c + 1, m):
                A[i, j] -= f * A[c, j]
    return d


@njit(**INLINE)
def _copy(A, B, m):
    """B <- A (m x m)."""
    for i in range(m):
        for j in range(m):
            B[i, j] = A[i, j]


@njit(**INLINE)
def _relative(worst, size):
    """worst / size, inf where size is 0 (M = 0), NaN where worst is."""
    if math.isnan(worst):
        return math.nan
    return worst / size if size > 0.0 else math.inf


@njit(**INLINE)
def symplecticity(M, m):
    """(||M^T J M - J||_max, the same divided by the largest sum of |terms| that make up an entry
    of M^T J M): the absolute defect and a scale-free one (round-off level for a symplectic map
    whatever the size of M, the method's own defect otherwise). The maxima are plain ones, a NaN
    being caught by one flag (a NaN-keeping max per entry cost 2 ns of a damped midpoint step)."""
    n = m // 2
    worst = 0.0
    size = 0.0
    nan = False
    for i in range(m):
        for j in range(m):
            v = 0.0
            s = 0.0
            for r in range(n):
                a = M[r, i] * M[r + n, j]
                b = M[r + n, i] * M[r, j]
                v += a - b
                s += abs(a) + abs(b)
            target = 1.0 if j == i + n else (-1.0 if i == j + n else 0.0)
            d = abs(v - target)
            nan |= math.isnan(d)
            worst = max(worst, d)
            size = max(size, s)
    if nan:
        worst = math.nan
    return worst, _relative(worst, size)


@njit(**INLINE)
def defects(M, B, P):
    """(|det M - 1|, symplecticity(M)) of a one-step map M of the scene of P (B: scratch). With one degree of
    freedom M^T J M = det(M) J, so the defect is |det M - 1|: both from the two products that
    symplecticity forms (its figures bit for bit; det to round-off of the LU's), which halves the
    maps' cost of a damped midpoint step (run_summary's figures 39 -> 35 ns/step)."""
    m = 2 * ndof(P)
    if m == 2:
        x, y = M[0, 0] * M[1, 1], M[1, 0] * M[0, 1]
        dev = abs((x - y) - 1.0)
        size = max(abs(x) + abs(y), 2.0 * abs(M[0, 0] * M[1, 0]), 2.0 * abs(M[0, 1] * M[1, 1]))
        return dev, dev, _relative(dev, size)
    _copy(M, B, m)
    symp, rel = symplecticity(M, m)
    return abs(determinant(B, m) - 1.0), symp, rel


@njit(**INLINE)
def grow(M, e, A, B, P, scale, exponent):
    """A <- M A, scaled by an exact power of two 2^-x once its largest entry leaves [2^-RANGE,
    2^RANGE] (x ln 2 added to `scale`: no logarithm per step); A is kept in the scaled coordinates
    of `exponent` (see diagnostics.MapGrowth); M, A, B are m x m for the scene of P. Returns (finite,
    scale, exponent)."""
    m = 2 * ndof(P)
    n = m // 2
    shift = e - exponent
    if shift != 0:
        qf, pf = math.ldexp(1.0, -shift), math.ldexp(1.0, shift)
        for i in range(n):
            for j in range(m):
                A[i, j] *= qf
                A[n + i, j] *= pf
        exponent = e
    big = 0.0
    for i in range(m):
        for j in range(m):
            s = 0.0
            for r in range(m):
                s += M[i, r] * A[r, j]
            if not np.isfinite(s):
                return False, scale, exponent
            B[i, j] = s
            big = max(big, abs(s))
    if big == 0.0:
        return False, scale, exponent
    f = 1.0
    if not (2.0 ** -RANGE < big < 2.0 ** RANGE):
        x = math.frexp(big)[1]
        f = math.ldexp(1.0, -x)
        scale += x * LN2
    for i in range(m):
        for j in range(m):
            A[i, j] = B[i, j] * f
    return True, scale, exponent


@njit(**INLINE)
def _energy_after(D, P, C, end, Ce, t, z, ahead):
    """H of the new state z of a step, in the step's scaled coordinates (H is invariant under the
    scaling, see scenes.base.SceneKernel), with time t (shifted): from the step's own last
    coefficient row where the family has one at the step's end, else from a new row, all of it
    where it is the next step's first (`ahead`), else what H reads of it (energy_coef)."""
    if end >= 0:
        row(D, P, C, end)
        return energy(P, C, end, z)
    if ahead:
        coef(P, t, Ce, 0)
    else:
        energy_coef(P, t, Ce, 0)
    return energy(P, Ce, 0, z)


@njit(**INLINE)
def _lead(D, P, C, Ce, end, tk, t1, h, y, yold, W, e, up, down, S0, C0, hnew, want, ahead):
    """Member 0's step of the fused loop (_fused): y in place (yold <- y before; y restored where the
    step fails or overflows), its p_t increment added to (S0, C0), and with WANT_H its H after the
    step (_energy_after, at t1 shifted). Returns (status, S0, C0, hnew), (S0, C0, hnew) unchanged
    where the step failed."""
    m = 2 * ndof(P)
    for r in range(m):
        yold[r] = y[r]
    _rescale(y, P, e, down, up)
    status, dpt = step(D, P, C, tk, h, y, -0.0, W)
    if want & WANT_H:
        hnew = _energy_after(D, P, C, end, Ce, t1, y, ahead)
    _rescale(y, P, e, up, down)
    sum_, comp = _add(S0, C0, dpt)
    if status == OK and not _finite(sum_, y, P):
        status = OVERFLOW
    if status != OK:
        for r in range(m):
            y[r] = yold[r]
        return np.int64(status), S0, C0, hnew
    return np.int64(status), sum_, comp, hnew


@njit(**INLINE)
def _volume_row(X, inc, i, z, old, P):
    """Member i's increment (i = 1 .. 2n + 1) toward the paper's volume estimator (_volume): member
    1's into inc, member i's less member 1's into row i - 2 of X, in (q, p)."""
    m = 2 * ndof(P)
    if i == 1:
        for r in range(m):
            inc[r] = z[r] - old[r]
    else:
        for r in range(m):
            X[i - 2, r] = (z[r] - old[r]) - inc[r]


@njit(**INLINE)
def _volume(X, h, P):
    """The paper's volume estimator det[X^1 ... X^(2n+1)] of the members' increments X^i = (dq^i,
    h, dp^i) (diagnostics.paper_volume_form), from _volume_row's differences X (overwritten):
    rows 2 .. 2n + 1 less row 1 leave 0 under t and the same determinant, which is then
    (-1)^n h det of the differences' (q, p) parts. Nearby members' increments are nearly parallel:
    their differences first (exact where two are within a factor of 2), the round-off is that of
    the 2n x 2n determinant of the differences (a closed form for one degree of freedom), where the
    LU of the raw rows lost digits to its first elimination: against the exact determinant of the
    same increments, 3e-15 relative against 1e-12 on damped and modulated (tests/test_drive.py)."""
    n = ndof(P)
    if n == 1:
        return -h * (X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0])
    d = h * determinant(X, 2 * n)
    return -d if n % 2 else d


def tangent_work(D, P):
    """Stack scratch of member 0's tangent map (_tangent): on a linear scene the step matrix's
    work and a Q with no rows (kernels.linear: M alone)."""


@overload(tangent_work, jit_options=_IR_INLINE, inline="always")
def _tangent_work(D, P):
    if _scene(P).linear:
        return lambda D, P: (lwork(D, P), matrices(P, 1, 0.0)[0][:0])
    return lambda D, P: (work(D, P, 0j), vectors(P, 1, 0j)[0])


def _tangent(D, P, C, tk, h, zs, pt, M, TW):
    """Member 0's one-step tangent map M at the (scaled) state zs: the step matrix on a linear
    scene, a complex step of the member step otherwise (kernels.loops.tangent_matrix and
    tangent_complex). Returns the status."""


@overload(_tangent, jit_options=_INLINE)
def _tangent_impl(D, P, C, tk, h, zs, pt, M, TW):
    if _scene(P).linear:
        def matrix(D, P, C, tk, h, zs, pt, M, TW):
            LW, Q = TW
            lmatrix(D, P, C, tk, h, M, Q, LW)
            return OK
        return matrix

    def complex_step(D, P, C, tk, h, zs, pt, M, TW):
        Wc, zc = TW
        m = zs.shape[0]
        for j in range(m):
            for r in range(m):
                zc[r] = zs[r]
            zc[j] += 1j * COMPLEX_STEP
            status, _ = step(D, P, C, tk, h, zc, pt + 0j, Wc)
            if status != OK:
                return status
            for r in range(m):
                M[r, j] = zc[r].imag / COMPLEX_STEP
        return OK
    return complex_step


def _member(D, P, C, tk, h, Z, i, z, old, zs, W, e, up, down, S, Cc, by_map, M):
    """Member i's step from Z[i] (old <- Z[i], z <- the new state) and its p_t sum (S, Cc): the
    member step (_advance), or where by_map on a linear scene the step matrix M of _tangent applied
    alone (kernels.loops.apply_map), without p_t (S, Cc returned as they came: no
    figure of a run that records nothing reads a member's p_t but member 0's, and forming Q for it
    cost the app's long run 4-6 ns of a 68 ns step; zs: scratch). Returns (status, S, Cc)."""


@njit(**INLINE)
def _stepped(D, P, C, tk, h, Z, i, z, old, W, e, up, down, S, Cc):
    """Member i's member step (_member)."""
    for r in range(z.shape[0]):
        old[r] = Z[i, r]
        z[r] = old[r]
    return _advance(D, P, C, tk, h, z, W, e, up, down, S, Cc)


@overload(_member, jit_options=_INLINE)
def _member_impl(D, P, C, tk, h, Z, i, z, old, zs, W, e, up, down, S, Cc, by_map, M):
    if not _scene(P).linear:
        return lambda D, P, C, tk, h, Z, i, z, old, zs, W, e, up, down, S, Cc, by_map, M: _stepped(
            D, P, C, tk, h, Z, i, z, old, W, e, up, down, S, Cc)

    def by_matrix(D, P, C, tk, h, Z, i, z, old, zs, W, e, up, down, S, Cc, by_map, M):
        if not by_map:
            return _stepped(D, P, C, tk, h, Z, i, z, old, W, e, up, down, S, Cc)
        apply_map(Z, i, M, old, zs, z, P, e, up, down)
        _rescale(z, P, e, up, down)
        return np.int64(OK), S, Cc
    return by_matrix


@njit(**INLINE)
def _flush(env, tb, b, t, h_min, h_max, vol_min, vol_max, det, symp):
    """Bin b's time and figures (min and max of H + p_t and of the volume estimator, max of the
    defects) into tb and env (rows preset to the identities of min and max)."""
    if b >= 0:
        tb[b] = t
        env[b, 0], env[b, 1], env[b, 2], env[b, 3], env[b, 4], env[b, 5] = h_min, h_max, vol_min, vol_max, det, symp


@njit(**INLINE)
def _fused(D, P, t0, first, h, Z, PT, S, Cc, nsteps, every, want, width, acc, env, tb, G,
           gstate, scaled, stride, Trec, Zrec, PTrec, dZrec, F):
    """Member steps, as kernels.loops.propagate_one takes them (so a run's states are those
    of `simulate`, to round-off: the same step compiled in two loops may contract its products
    differently, tests/test_drive.py; by the step matrix for members 1.. of a linear scene's run that records
    nothing, see _member), and member 0's tangent map (_tangent) at the mapped steps. The figures are
    reduced in local variables and a stack copy of the growth product, written back once per
    call (stored into the arrays every step, they cost 6-10 ns a step: the compiler must assume
    those stores change the states it keeps in registers). Member 0's state, p_t and p_t's sum are
    kept so too (y, pt0, S0, C0), the other members' go through Z and PT."""
    C = coef_table(D, P)
    Ce = coef_table(D, P)
    W = work(D, P, 0.0)
    records = Trec.shape[0] > 0
    TW = tangent_work(D, P)
    V = vectors(P, 6, 0.0)
    z, old, zs, y, yold, inc = V[0], V[1], V[2], V[3], V[4], V[5]
    MB = matrices(P, 4, 0.0)
    M, B, A, X = MB[0], MB[1], MB[2], MB[3]
    m = 2 * ndof(P)
    figures = F.shape[0] > 0
    volume = Z.shape[0] >= m + 2 and (width > 0 or figures)  # the paper's estimator, for bins or figures
    rec, member0 = np.int64(0), np.int64(0)  # int64, not literals (kernels.loops, LITERALS)
    if records:
        _record_start(t0 + first * h, Z, PT, Trec, Zrec, PTrec, dZrec, P)
        rec = np.int64(1)
    u = len(D.offsets)
    reusable = _reusable(D)
    end = u - 1 if D.offsets[u - 1] == 1.0 else -1
    # Where the step has no row at its end but one at its start (explicit and symplectic Euler), the
    # row computed for H at a step's end is the next step's first (same time and scaling): one row a
    # step instead of two (modulated euler's run with H + p_t 31 -> 22 ns a step).
    ahead = end < 0 and D.offsets[0] == 0.0 and want & WANT_H != 0
    first_from, first_row = (Ce, np.int64(0)) if ahead else (C, np.int64(u - 1))  # a step's first row
    Ce[0, ncoef(P)] = np.nan  # a computed row, not pending (kernels.families.row)
    hmax, dmax, smax, rmax = acc[0], acc[1], acc[2], acc[3]
    growing = G.shape[0] > 0 and gstate[2] == 1.0
    if growing:
        _copy(G, A, m)
    gscale, gexp = gstate[0], int(gstate[1])
    # the current bin's figures (env's columns), in local variables as the maxima are
    h_min = h_max = vol_min = vol_max = det_max = symp_max = 0.0
    b, tbin = np.int64(-1), 0.0
    # Countdowns to the next mapped step, record and bin: a remainder per step (k % every) is an
    # integer division, tens of cycles (with the offsets as tuples, damped midpoint's run with every
    # figure 48 -> 46 ns a step).
    map_in, rec_in, bin_in = np.int64(0 if every > 0 else -1), stride, np.int64(0)
    fmap = np.int64(0)
    status, done, in_tangent = np.int64(OK), nsteps, False
    for r in range(m):
        y[r] = Z[0, r]
    pt0, S0, C0 = PT[0], S[0], Cc[0]
    hnew = 0.0
    prev = 0
    tau = 0.0
    up = down = 1.0
    k = np.int64(0)
    while k < nsteps:
        if Z.shape[0] == 1:
            # A lone trajectory's steps up to the next event (a mapped step, a record, a bin's start,
            # the last step) run in a loop of their own, which carries only what they change: in the
            # loop below, the figures they leave alone cost a lone rk4 run with H + p_t 6 ns a step.
            quiet = nsteps - 1 - k
            if every > 0:
                quiet = min(quiet, map_in)
            if records:
                quiet = min(quiet, rec_in - 1)
            if width > 0:
                quiet = min(quiet, bin_in)
            for _ in range(quiet):
                g = first + k
                e, tau, up, down, tk = _step_start(D, P, t0, h, g, k == 0, scaled, prev, tau, up, down, C,
                                                   reusable or ahead, first_from, first_row)
                prev = e
                status, S0, C0, hnew = _lead(D, P, C, Ce, end, tk, t0 + (g + 1) * h - tau, h, y, yold, W, e,
                                             up, down, S0, C0, hnew, want, ahead)
                if status != OK:
                    break
                pt0 = S0 - C0
                hext = hnew + pt0
                if want & WANT_H:
                    hmax = _most(hmax, abs(hext))
                if width > 0:
                    h_min = _least(h_min, hext)
                    h_max = _most(h_max, hext)
                k += 1
            if status != OK:
                done = k
                break
            map_in -= quiet
            if records:
                rec_in -= quiet
            bin_in -= quiet
        g = first + k
        e, tau, up, down, tk = _step_start(D, P, t0, h, g, k == 0, scaled, prev, tau, up, down, C,
                                           reusable or ahead, first_from, first_row)
        prev = e
        mapped = map_in == 0
        if mapped:
            map_in = every
        map_in -= 1
        if mapped:
            for r in range(m):
                zs[r] = y[r]
            _rescale(zs, P, e, down, up)
            status = _tangent(D, P, C, tk, h, zs, pt0, M, TW)
            if status != OK:
                done, in_tangent = k, True
                break
        t1 = t0 + (g + 1) * h
        rec_in -= 1
        recording = records and (rec_in == 0 or k + 1 == nsteps)
        if rec_in == 0:
            rec_in = stride
        status, S0, C0, hnew = _lead(D, P, C, Ce, end, tk, t1 - tau, h, y, yold, W, e, up, down, S0, C0, hnew,
                                     want, ahead)
        if status != OK:
            done = k
            break
        pt0 = S0 - C0
        if recording:
            _record(rec, member0, y, yold, pt0, Zrec, PTrec, dZrec, P)
        by_map = mapped and not records and is_linear(P)
        for i in range(1, Z.shape[0]):
            status, sum_, comp = _member(D, P, C, tk, h, Z, i, z, old, zs, W, e, up, down, S[i], Cc[i],
                                         by_map, M)
            if by_map:  # the step matrix's state alone: its p_t is not carried (_member)
                if not _finite(0.0, z, P):
                    status = OVERFLOW
                    break
                for r in range(m):
                    Z[i, r] = z[r]
            else:
                status = _accept(status, i, z, old, sum_ - comp, Z, PT, rec, recording, Zrec, PTrec, dZrec, P)
                if status != OK:
                    break
                S[i], Cc[i] = sum_, comp
            if volume and 1 <= i <= m + 1:
                _volume_row(X, inc, i, z, old, P)
        if status != OK:
            done = k
            break
        hext = hnew + pt0
        if want & WANT_H:
            hmax = _most(hmax, abs(hext))
        dev = symp = 0.0
        if mapped and want & WANT_MAPS:
            dev, symp, rel = defects(M, B, P)
            dmax, smax, rmax = _most(dmax, dev), _most(smax, symp), _most(rmax, rel)
            if figures:
                F[fmap, 0], F[fmap, 1] = dev, symp
        if mapped:
            fmap += 1
        if mapped and growing:
            growing, gscale, gexp = grow(M, e, A, B, P, gscale, gexp)
        vol = _volume(X, h, P) if volume and (width > 0 or recording and figures) else math.nan
        if recording:
            Trec[rec] = t1
            if figures:
                F[rec - 1, 2] = vol
            rec += 1
        if width > 0:
            if bin_in == 0:
                _flush(env, tb, b, tbin, h_min, h_max, vol_min, vol_max, det_max, symp_max)
                b, tbin, bin_in = b + 1, t1, width
                h_min, h_max, vol_min, vol_max, det_max, symp_max = (env[b, 0], env[b, 1], env[b, 2], env[b, 3],
                                                                     env[b, 4], env[b, 5])
            bin_in -= 1
            h_min = _least(h_min, hext)
            h_max = _most(h_max, hext)
            if volume:
                vol_min = _least(vol_min, vol)
                vol_max = _most(vol_max, vol)
            if mapped:
                det_max = _most(det_max, dev)
                symp_max = _most(symp_max, symp)
        k += 1
    if width > 0:
        _flush(env, tb, b, tbin, h_min, h_max, vol_min, vol_max, det_max, symp_max)
    _store(Z, PT, member0, y, pt0, P)
    S[0], Cc[0] = S0, C0
    acc[0], acc[1], acc[2], acc[3] = hmax, dmax, smax, rmax
    if G.shape[0] > 0:
        if growing:
            _copy(A, G, m)
        gstate[0], gstate[1] = gscale, gexp
        gstate[2] = 1.0 if growing else 0.0
    return status, done, in_tangent, rec


def with_values(P, row):
    """A parameter tuple of P's class with its fields from row (scenes whose fields are all floats;
    P itself for the others)."""


@overload(with_values, jit_options=_INLINE)
def _with_values(P, row):
    cls = P.instance_class
    count = len(P.types)
    if not all(t == types.float64 for t in P.types):
        return lambda P, row: P  # not batched (drive.batchable): its runs never pass rows
    return lambda P, row: cls(*to_fixed_tuple(row, count))


@njit(**JIT)
def survey(D, P, R, t0, first, h, Z, PT, S, Cc, nsteps, every, want, width, acc, env, tb, G,
           gstate, status, scaled, start, stride, Trec, Zrec, PTrec, dZrec, F, Hrec):
    """B = len(Z) runs of the fused loop for the scene (_fused) in one call, its arrays borrowed.

    Run b advances the members Z[b] (p_t PT[b], its compensated sum S[b] and compensation Cc[b])
    with the scene's parameters P, or R[b] where R has rows (a batch over parameter sets: one
    compiled call for a sweep's grid, no Python per point; scenes whose parameters are all
    floats), and reduces into acc[b], G[b], gstate[b]; bins (env, tb) and records (stride, Trec, Zrec,
    PTrec, dZrec, F) are run 0's (a batch asks for none), and so is Hrec: H of each recorded state, where
    it has rows. With `start`, each run's members start from their states at t0 with p_t = -H (START
    where H is not finite there). status[b] = (status, steps completed, 1 if the failure came from
    the tangent map's complex step)."""
    D, P, R, Z, PT, S, Cc, acc, env, tb, G, gstate, status, Trec, Zrec, PTrec, dZrec, F, Hrec = borrow(
        (D, P, R, Z, PT, S, Cc, acc, env, tb, G, gstate, status, Trec, Zrec, PTrec, dZrec, F, Hrec))
    Ce = coef_table(D, P)
    zs = vectors(P, 1, 0.0)[0]
    for b in range(Z.shape[0]):
        Pb = with_values(P, R[b]) if R.shape[0] > 0 else P
        if start:
            e, up, down = coef_at(Pb, t0 + first * h, Ce)
            failed = False
            for i in range(Z.shape[1]):
                H0 = energy_at(Pb, Ce, Z[b, i], zs, e, up, down)
                failed |= not np.isfinite(H0)
                PT[b, i] = S[b, i] = -H0
                Cc[b, i] = 0.0
            if failed:
                status[b, 0], status[b, 1], status[b, 2] = START, 0, 0
                continue
        st, k, tangent_failed, rec = _fused(D, Pb, t0, first, h, Z[b], PT[b], S[b], Cc[b], nsteps,
                                            every, want, width, acc[b], env, tb, G[b], gstate[b], scaled,
                                            stride, Trec, Zrec, PTrec, dZrec, F)
        status[b, 0], status[b, 1], status[b, 2] = st, k, tangent_failed
        if b == 0 and Hrec.shape[0] > 0:
            _energies(Pb, Trec[:rec], Zrec[:rec], Hrec[:rec], Ce, zs)
