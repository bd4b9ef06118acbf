"""The fused driver: runs whose figures are reduced as they go, in one compiled pass.

`Drive` advances one trajectory (member 0), or with 2n + 2 members also the paper's volume
estimator's nearby states, and keeps what `run`, the long run, work-precision and sweeps show:
max |H + p_t|, max |det M_k - 1| and the symplecticity defect (absolute and scale-free) of the
one-step tangent maps, the growth product of those maps, and per-bin envelopes; nothing per
step. A run is cut into compiled calls of at most CHUNK steps (the one chunking policy: each
call's end is a point for progress and cancel).
"""
import math
import time

import numpy as np

from . import warm
from .diagnostics import MapGrowth, log_norms
from .errors import InputError, RunError
from .integrate import (
    MAX_RECORDED,
    Trajectory,
    _exact_overflows,
    check_step,
    failure_message,
    initial_states,
    records,
    simulate,
    start_pt,
)
from .kernels.families import OK
from .kernels.survey import ACC, ENV, WANT_H, WANT_MAPS, survey

CHUNK = 1 << 18
NO_ROWS = np.empty((0, 0))  # survey's R for a run with the setup's own parameters
NO_FIGURES = np.empty((0, 3))  # survey's F for a call without records
DIAG_MAPS = 1 << 16


def map_every(steps, det=True, growth=False):
    """Which steps' tangent maps a run forms: every step for the growth product, every step or
    at most DIAG_MAPS evenly spaced ones for det and symplecticity alone, none otherwise."""
    return 1 if growth else (max(1, math.ceil(steps / DIAG_MAPS)) if det else 0)


class Drive:
    """A run advanced by compiled calls of the fused loop (kernels.survey).

    every: form member 0's tangent map at every `every`-th step (0: never; growth needs 1);
    width: bin width in steps of the envelopes (0: none); growth: keep the product of the maps
    (a diagnostics.MapGrowth); energy, maps: whether to reduce max |H + p_t| (always with bins,
    whose envelopes hold it) and the maps' det and symplecticity (a figure not asked for is NaN
    and costs nothing; without maps or growth no map is formed). Calls of `advance`
    continue the run as one call would (the steps are numbered from the run's start); bins and
    the maps' sampling are counted from the run's first step when each call's length is a
    multiple of `unit` (and so are the nearby members' states, which on a linear scene take the
    step matrix at the mapped steps: kernels.survey._member). Those members' p_t is then not
    carried (no figure reads it): PT[1:] is NaN after such an advance().
    """

    def __init__(self, setup, h, z0=None, pt0=None, t0=0.0, every=1, width=0, growth=False, energy=True,
                 maps=True):
        if growth and every != 1:
            raise ValueError("the growth product needs every step's map (every = 1)")
        self.setup = setup
        self.h = float(h)
        check_step(self.h, self.h)
        warm.ensure(setup)
        self.Z = initial_states(setup, z0)
        self.PT = start_pt(setup, self.Z, t0, pt0)
        self._sum, self._comp = self.PT.copy(), np.zeros_like(self.PT)
        self.t0 = float(t0)
        self.t = self.t0
        self.done = 0
        self.every = int(every) if maps or growth else 0  # maps no figure needs are not formed
        self.width = int(width)
        m = 2 * setup.scene.ndof
        self.growth = MapGrowth(m) if growth else None
        self._G = self.growth.A if growth else np.empty((0, 0))
        self._gstate = self.growth.state if growth else np.zeros(3)
        self.want = (WANT_H if energy or width else 0) | (WANT_MAPS if maps and every else 0)
        self.acc = np.zeros(len(ACC))
        if not self.want & WANT_H:
            self.acc[0] = math.nan
        if not self.want & WANT_MAPS:
            self.acc[1:] = math.nan
        self.failure = ""
        self.unit = math.lcm(max(1, self.every), max(1, self.width))
        self._members_by_map = setup.scene.kernel.linear and len(self.Z) > 1 and self.every > 0

    @property
    def H_ext_max_abs(self):
        return float(self.acc[0])

    @property
    def det_max_dev(self):
        return float(self.acc[1])

    @property
    def symp_max_dev(self):
        return float(self.acc[2])

    @property
    def symp_max_rel(self):
        return float(self.acc[3])

    def advance(self, steps):
        """One compiled call of `steps` steps. Returns this call's bins ({"t": ..., ENV: ...},
        or None without width; a bin without a sampled map has NaN defects). A failure
        (overflow, Newton) stops the run: its message is kept in `failure`, the bins and maxima
        are those of the steps before the failing one, the state is not meaningful (members
        before the failing one have taken that step), and later calls do nothing."""
        if self.failure:
            return {k: np.empty(0) for k in ("t",) + ENV} if self.width else None
        N, m = self.Z.shape
        bins = -(-steps // self.width) if self.width else 0
        env = np.empty((bins, len(ENV)))
        env[:, 0::2] = math.inf
        env[:, 1::2] = -math.inf
        env[:, 4:] = -math.inf  # stays so in a bin without a sampled map: NaN below
        tb = np.empty(bins)
        status, k, in_tangent = self._call(steps, env, tb, *_no_records(N, m))
        if self._members_by_map:
            self.PT[1:] = math.nan
        self.done += k
        self.t = self.t0 + self.done * self.h
        if status != OK:
            self.failure = self._stopped(status, in_tangent)
            bins = -(-k // self.width) if self.width else 0
        if not self.width:
            return None
        env[:, 4:][env[:, 4:] == -math.inf] = math.nan
        out = {"t": tb[:bins]}
        out.update({name: env[:bins, j] for j, name in enumerate(ENV)})
        if N < m + 2:
            out["vol_min"] = out["vol_max"] = np.full(bins, math.nan)
        return out

    def _stopped(self, status, in_tangent):
        """The message of the failure that stopped the run in the step from self.t (the members'
        states in Z: there, or one step on for those before the failing one). A tangent map is
        formed before its step, by the step itself in complex arithmetic (kernels.survey._tangent)
        from the real step's solution (kernels.families.theta_start), so in practice it fails
        only where the step's own Newton fails. One real step from the same state decides: the
        failure is named the step's where that step fails too, the tangent map's where it runs."""
        s = self.setup
        step = round(self.t0 / self.h) + self.done
        if in_tangent:
            try:
                simulate(s, self.h, self.h, z0=self.Z[:1], t0=self.t, pt0=0.0)  # p_t enters no step
            except RunError as err:
                in_tangent = str(err).startswith("overflow")
        msg = failure_message(status, step, self.t, self.h, not in_tangent and _exact_overflows(s, self.t, self.h),
                              (s, self.Z))
        return f"tangent map: {msg}" if in_tangent else msg

    def _call(self, steps, env, tb, stride, Trec, Zrec, PTrec, dZrec, F, H):
        """One call of the fused loop from the run's current state: (status, k, in_tangent)."""
        s = self.setup
        ends = (self.t0 + self.done * self.h, self.t0 + (self.done + steps) * self.h)
        scaled = max(abs(ends[0]), abs(ends[1])) > s.scaled_beyond
        out = np.zeros((1, 3), dtype=np.int64)
        survey(s.data, s.P, NO_ROWS, self.t0, self.done, self.h, self.Z[None], self.PT[None], self._sum[None],
               self._comp[None], steps, self.every, self.want, self.width, self.acc[None], env, tb, self._G[None],
               self._gstate[None], out, scaled, False, stride, Trec, Zrec, PTrec, dZrec, F, H)
        return out[0]

    def record(self, steps, stride, increments=False):
        """`steps` steps in one compiled call (a Drive made with every = stride and no bins),
        recording every member's state at every stride-th step and the last, as `simulate`
        records them (the same steps: member steps), and the figures of each record: returns
        (Trajectory, F) with F (records - 1, 3) as kernels.survey gives it (|det M - 1| and
        ||M^T J M - J|| of the map from each record but the last, the paper's volume estimator
        into each record but the first; NaN columns where the Drive forms no maps or has no
        volume members). A failure raises RunError carrying the Trajectory up to it, as
        simulate's does."""
        if self.width or self.every not in (0, stride) or self.growth is not None:
            raise ValueError("record() needs a Drive with every = stride (or no maps), no bins and no growth")
        if self._members_by_map and self.done:
            raise ValueError("record() cannot continue an advance() of a linear scene's members: their p_t was not carried")
        N, m = self.Z.shape
        K = records(steps, stride)
        if K * N * (m + 1) * (3 if increments else 1) > MAX_RECORDED:
            raise InputError(f"recording {K} states of {N} trajectories exceeds the memory cap "
                             f"({MAX_RECORDED:.0e} values): pass a larger stride")
        Trec, Zrec, PTrec = np.empty(K), np.empty((K, N, m)), np.empty((K, N))
        dZrec = np.empty((K, N, m)) if increments else np.empty((0, N, m))
        F, H = np.full((K - 1, 3), np.nan), np.empty((K, N))
        began = time.perf_counter()
        status, k, in_tangent = self._call(steps, np.empty((0, len(ENV))), np.empty(0), stride, Trec, Zrec, PTrec,
                                           dZrec, F, H)
        wall = time.perf_counter() - began
        kept = K if status == OK else k // stride + 1
        traj = Trajectory(self.setup, self.h, stride, Trec[:kept], Zrec[:kept], PTrec[:kept], H[:kept], int(k), wall,
                          dZrec[:kept] if increments else None)
        self.done += k
        self.t = self.t0 + self.done * self.h
        if status != OK:
            self.failure = traj.failure = self._stopped(status, in_tangent)
            raise RunError(self.failure, self.t, self.done, traj)
        if not self.want & WANT_MAPS:
            F[:, :2] = np.nan
        return traj, F

    def run(self, steps, progress=None, strict=True):
        """advance() in calls of at most CHUNK steps (a multiple of `unit`), progress(done, steps)
        after each; returns the bins concatenated ({} without width). A failure raises RunError,
        or with strict=False ends the run, its bins kept and its message in `failure`."""
        chunk = self.unit * max(1, CHUNK // self.unit)
        parts = []
        start = self.done
        while self.done - start < steps and not self.failure:
            part = self.advance(min(chunk, steps - (self.done - start)))
            if part is not None:
                parts.append(part)
            if progress:
                progress(self.done - start, steps)
        if self.failure and strict:
            raise RunError(self.failure, self.t, self.done)
        return concat(parts)


def concat(parts):
    """Bins of consecutive advance() calls as one dict of arrays ({} for none)."""
    if not parts:
        return {}
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _no_records(N, m):
    """survey's stride and records for a call that records nothing."""
    return 1, np.empty(0), np.empty((0, N, m)), np.empty((0, N)), np.empty((0, N, m)), NO_FIGURES, np.empty((0, N))


def batchable(setup):
    """Whether runs of the setup's scene can be batched over parameter sets (kernels.survey
    builds each set from a row of floats)."""
    return all(isinstance(v, float) for v in setup.P)


def batch_runs(setup, h, steps, R, Z0, with_det=True, growth=False, energy=True):
    """Runs of setup's method, one per row of R (the scene's parameter tuples) from Z0's rows, in
    one compiled call (kernels.survey), each reduced as scan() reduces one run: returns
    {ACC name: (B,) array (NaN where not asked for), "growth": ln sigma_max of each product or
    None, "failed": (B,) bool}. A failed run's figures are not meaningful: run it alone for its
    message."""
    warm.ensure(setup)
    B, m = Z0.shape
    every = map_every(steps, with_det, growth)
    want = (WANT_H if energy else 0) | (WANT_MAPS if with_det and every else 0)
    acc = np.zeros((B, len(ACC)))
    G = np.tile(np.eye(m), (B, 1, 1)) if growth else np.empty((B, 0, 0))
    gstate = np.tile([0.0, 0.0, 1.0], (B, 1))
    status = np.zeros((B, 3), dtype=np.int64)
    R = np.ascontiguousarray(R, dtype=float)
    scaled = any(setup.scene.needs_scaling(setup.scene.Params(*row), steps * h) for row in R)
    Z = np.array(Z0, dtype=float).reshape(B, 1, m)
    PT, S, Cc = np.empty((B, 1)), np.empty((B, 1)), np.empty((B, 1))
    survey(setup.data, setup.P, R, 0.0, 0, float(h), Z, PT, S, Cc, int(steps), every, want, 0, acc,
           np.empty((0, len(ENV))), np.empty(0), G, gstate, status, scaled, True, *_no_records(1, m))
    if not want & WANT_H:
        acc[:, 0] = math.nan
    if not want & WANT_MAPS:
        acc[:, 1:] = math.nan
    out = {name: acc[:, j] for j, name in enumerate(ACC)}
    out["growth"] = log_norms(G, gstate) if growth else None
    out["failed"] = status[:, 0] != OK
    return out
