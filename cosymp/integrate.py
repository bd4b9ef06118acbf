"""Runs: checked input, one compiled loop per run or ensemble, results with p_t and H + p_t."""
import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import warm
from .errors import InputError, RunError, as_number, quoted
from .kernels.families import NEWTON, OK, OVERFLOW, SINGULAR, START, Composition, Gauss, Theta
from .kernels.loops import energies, propagate_matrix, propagate_one, vector_field
from .methods import method as get_method
from .scenes import SCENES

MAX_STEPS = 100_000_000
MAX_RECORDED = 20_000_000
_ENTRIES = {}  # (kernel, method, scene parameter class) -> the compiled loop's entry point


def get_scene(name):
    if name not in SCENES:
        raise InputError(f"unknown scene {quoted(name)}: choose one of {', '.join(SCENES)}")
    return SCENES[name]


def check_step(h, T):
    """Number of steps for step h up to horizon T (T/h rounded up, within 1e-9 relative, so that
    h = T/N gives N), or InputError saying what to change (h longer than T included: one step
    would end far past it)."""
    if type(h) is float and type(T) is float and 0.0 < h <= T and T / h <= MAX_STEPS:
        # simulate's common case, two floats that pass, in a few tenths of a microsecond (T/h >= 1)
        ratio = T / h
        return math.ceil(ratio - 1e-9 * ratio) if ratio > 1.0 else 1
    # Anything else: each check with its message.
    h, T = as_number(h, "h"), as_number(T, "T")
    if h <= 0:
        raise InputError(f"h = {h} must be positive: pass a step size h > 0")
    if T <= 0:
        raise InputError(f"T = {T} must be positive: pass a horizon T > 0")
    if not T / h <= MAX_STEPS:  # also a ratio that overflows to inf
        raise InputError(f"T/h = {T / h:.3g} steps exceeds the cap of {MAX_STEPS:.0e}: "
                         f"increase h or shorten T")
    if T / h < 1 - 1e-9:
        raise InputError(f"h = {h:.10g} is longer than the horizon T = {T:.10g}: its one step would end at "
                         f"t = {h:.10g}; choose h <= T or a longer T")
    ratio = T / h
    return max(math.ceil(ratio - 1e-9 * max(1.0, ratio)), 1)


@dataclass
class Setup:
    """A checked (scene, method, parameters) triple, ready to run."""

    scene: object
    method: object
    theta: float
    values: dict
    P: tuple
    data: tuple
    start: np.ndarray
    # Derived, once: |t| beyond which a run needs the scene's scaled steps (Scene.needs_scaling; inf:
    # never), and the compiled loops simulate calls (kernel -> _entry's).
    scaled_beyond: float = field(init=False, repr=False, compare=False)
    loops: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    # `start` as simulate passes it to a loop that only reads it (a writeable array types otherwise
    # than the read-only start, and a copy a run cost 0.3 us)
    first: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        limit = self.scene.kernel.scaled_beyond
        self.scaled_beyond = math.inf if limit is None else limit(self.P)
        self.first = self.start.copy()

    @classmethod
    def make(cls, scene, method, values=None, theta=None):
        scene = get_scene(scene) if isinstance(scene, str) else scene
        method = get_method(method) if isinstance(method, str) else method
        reason = method.refusal(scene)
        if reason:
            raise InputError(reason)
        data = method.data(theta)
        vals = scene.values(values)
        theta = (0.5 if theta is None else float(theta)) if method.takes_theta else None
        q0, p0 = scene.initial(vals)
        start = np.concatenate([q0, p0])[None, :]
        start.flags.writeable = False
        return cls(scene, method, theta, vals, scene.pack(vals), data, start)

    def with_values(self, **changes):
        return Setup.make(self.scene, self.method, {**self.values, **changes}, self.theta)


@dataclass
class Trajectory:
    """Recorded states of N trajectories: t (K,), z = (q, p) (K, N, 2n), pt and H (K, N).

    H_ext = H + p_t is the extended Hamiltonian (0 at the start by the convention
    p_t(0) = -H(z0, 0)). `steps` were completed with step h; record j is step j*stride, and the
    last record is the last step (also where stride does not divide steps).
    `wall_s` is the compiled call's time: the steps and the records' H (its compilation, if any,
    is not counted).
    `failure` holds the message of a run that stopped early (overflow, Newton).
    """

    setup: Setup
    h: float
    stride: int
    t: np.ndarray
    z: np.ndarray
    pt: np.ndarray
    H: np.ndarray
    steps: int
    wall_s: float
    increments: np.ndarray = None
    failure: str = ""

    @property
    def q(self):
        return self.z[..., : self.setup.scene.ndof]

    @property
    def p(self):
        return self.z[..., self.setup.scene.ndof:]

    @property
    def H_ext(self):
        return self.H + self.pt

    @property
    def t_final(self):
        return self.t[-1]

    @property
    def Pi(self):
        """Mechanical momentum (K, N, n) where the scene defines one (Scene.momentum), else None."""
        return self.setup.scene.momentum(self.setup.P, self.t, self.q, self.p)


def initial_states(setup, z0=None):
    """(N, 2n) initial states (a new array): z0 rows if given, else the scene's initial condition."""
    if z0 is None:
        return setup.start.copy()
    z0 = np.array(z0, dtype=float, ndmin=2)
    if z0.shape[1] != 2 * setup.scene.ndof or not np.all(np.isfinite(z0)):
        raise InputError(f"initial states must be finite rows of length {2 * setup.scene.ndof}")
    return np.ascontiguousarray(z0)


def default_stride(steps, members, m, increments=False):
    """simulate's default stride: every step while the records (members x (m + 1) values, three
    times that with increments) fit in MAX_RECORDED values, else the smallest stride that fits."""
    per_record = members * (m + 1) * (3 if increments else 1)
    if (steps + 1) * per_record <= MAX_RECORDED:
        return 1
    stride = math.ceil(steps * per_record / MAX_RECORDED)
    while records(steps, stride) * per_record > MAX_RECORDED:
        stride += 1
    return stride


def records(steps, stride):
    """How many states a run of `steps` steps records: the start, every stride-th step, and the
    final step (one more record when stride does not divide steps)."""
    return steps // stride + 1 + (steps % stride != 0)


START_FAILED = ("H at the start (t = {t0:g}) is not finite: the scene's coefficients or the initial state "
                "overflow there; change the parameters (beta(t), B0, ...) or q0, p0")


def start_pt(setup, Z, t0, pt0=None):
    """p_t of the members Z at t0: pt0 if given, else -H(z, t0) (so H + p_t starts at 0)."""
    PT = np.empty(Z.shape[0])
    if pt0 is not None:
        PT[:] = pt0
        return PT
    H0 = np.empty((1, Z.shape[0]))
    energies(setup.P, np.array([float(t0)]), Z[None], H0)
    if not np.isfinite(H0).all():
        raise InputError(START_FAILED.format(t0=t0))
    PT[:] = -H0[0]
    return PT


UNREAD_PT = np.zeros(1)  # p_t of one trajectory whose loop computes it (propagate_one reads it, never writes)


@functools.cache
def _none(N, m):
    """An empty (0, N, m) array: the increments of a run that records none."""
    return np.empty((0, N, m))


def _entry(kernel, setup, args):
    """The compiled loop for these arguments, called without numba's dispatch (which types every
    argument on every call: 1.5 us, more than a short run's steps). On the first call of a key the
    loop is loaded or compiled by a zero-step call, untimed; the arguments' types never change
    for a key (arrays made here, float64 and C-contiguous)."""
    key = (kernel, setup.method.name, type(setup.P))
    fn = _ENTRIES.get(key)
    if fn is None:
        kernel(*args[:6], 0, *args[7:])
        compiled = kernel.overloads.get(tuple(kernel.typeof_pyval(a) for a in args))
        fn = _ENTRIES[key] = kernel if compiled is None else compiled.entry_point
    setup.loops[kernel] = fn
    return fn


def simulate(setup, h, T, z0=None, stride=None, increments=False, t0=0.0, pt0=None):
    """Run setup's method from t0 for T (rounded up to whole steps of h) on N initial states.

    z0: (N, 2n) states (default: the scene's initial condition); pt0 defaults to -H(z0, t0).
    stride: record every stride-th step (default: every step while the records fit in
    MAX_RECORDED values, else the smallest stride that fits), and always the final step.
    """
    steps = check_step(h, T)
    Z = setup.first if z0 is None else initial_states(setup, z0)
    warm.ensure(setup)
    N, m = Z.shape
    per_record = N * (m + 1) * (3 if increments else 1)
    if stride is None and (steps + 1) * per_record <= MAX_RECORDED:
        stride, K = 1, steps + 1  # default_stride's common case: every step
    else:
        if stride is None:
            stride = default_stride(steps, N, m, increments)
        elif not isinstance(stride, (int, np.integer)) or stride < 1:
            raise InputError(f"stride = {stride} must be a positive whole number")
        K = records(steps, stride)
        if K * per_record > MAX_RECORDED:
            raise InputError(f"recording {K} states of {N} trajectories exceeds the memory cap "
                             f"({MAX_RECORDED:.0e} values): pass a larger stride")
    if N > 1 and not setup.scene.kernel.linear:
        # An ensemble of a nonlinear scene: the fused driver's records, with no figures (the same
        # member steps as propagate_one's).
        from .drive import Drive  # drive builds on this module

        return Drive(setup, h, z0=Z, pt0=pt0, t0=t0, every=0, energy=False, maps=False).record(
            steps, int(stride), increments)[0]
    # One trajectory's loop only reads Z and PT: the setup's start, and p_t shared where it is
    # computed (-H); an ensemble's members are stepped in place, in arrays of their own.
    if N == 1 and pt0 is None:
        PT = UNREAD_PT
    else:
        PT = np.empty(N)
        if pt0 is not None:
            PT[:] = pt0
    Trec, PTrec, H, Zrec = np.empty(K), np.empty((K, N)), np.empty((K, N)), np.empty((K, N, m))
    dZrec = np.empty((K, N, m)) if increments else _none(N, m)
    t0, h = float(t0), float(h)
    end = t0 + steps * h
    scaled = (end if t0 >= 0.0 else max(-t0, abs(end))) > setup.scaled_beyond  # |t| at most: h > 0
    # An ensemble of a linear scene steps by one matrix per step, shared by its members; a single
    # trajectory by member steps, which cost it 1.1-3.6x less than building the step's matrix (no
    # matrix products; measured on every linear scene and family) but for Gauss's, which refine
    # their stages (kernels.families.gauss_step): 0.9-1.4x on damped and modulated (2026-11-29).
    kernel = propagate_matrix if N > 1 else propagate_one
    args = (setup.data, setup.P, t0, h, Z, PT, steps, int(stride), Trec, Zrec, PTrec, dZrec, H, scaled,
            pt0 is None)
    loop = setup.loops.get(kernel) or _entry(kernel, setup, args)
    start = time.perf_counter()
    status, done = loop(*args)
    wall = time.perf_counter() - start
    if status == START:
        raise InputError(START_FAILED.format(t0=t0))
    if status == OK:
        traj = Trajectory(setup, h, stride, Trec, Zrec, PTrec, H, done, wall, dZrec if increments else None)
        return traj
    kept = done // stride + 1
    traj = Trajectory(setup, h, stride, Trec[:kept], Zrec[:kept], PTrec[:kept], H[:kept], done, wall,
                      dZrec[:kept] if increments else None)
    t_fail = t0 + done * h
    state = Zrec[kept - 1]
    if status in (NEWTON, SINGULAR) and done > (kept - 1) * stride:
        # the steps from the last record to the failing one, taken again (all converged): its start
        left = done - (kept - 1) * stride
        state = simulate(setup, h, left * h, z0=state, stride=left, t0=Trec[kept - 1], pt0=0.0).z[-1]
    traj.failure = failure_message(status, round(t0 / h) + done, t_fail, h, _exact_overflows(setup, t_fail, h),
                                   (setup, state))
    raise RunError(traj.failure, t_fail, done, traj)


def exact_flow(exact, z, pt, t0, t1, shortest):
    """(z, p_t) of the exact flow (setup `exact`) carried from t0 (z, pt; None: the scene's initial
    state and p_t = -H there) to t1 in one step, which is exact at any length; a step that fails is
    split in halves down to `shortest`. A long step fails before the state does: the damped
    oscillator's coefficients e^(±γ s) over a step of length s pass floating point at γ s = 709,
    while its state stays finite to γ t = 1420 (a single step from 0 ended its reference at T = 5000
    for γ = 0.2, which reaches 7098). RunError where a step of `shortest` fails: there the state
    itself overflows."""
    try:
        run = simulate(exact, t1 - t0, t1 - t0, z0=z, pt0=pt, t0=t0)
    except RunError:
        if t1 - t0 <= shortest:
            raise
        middle = t0 + 0.5 * (t1 - t0)
        z, pt = exact_flow(exact, z, pt, t0, middle, shortest)
        return exact_flow(exact, z, pt, middle, t1, shortest)
    return run.z[-1], run.pt[-1]


def _exact_overflows(setup, t, h):
    """Whether the scene's exact flow itself leaves floating-point range by t (then no step size
    helps), carried in steps of at most t (exact_flow) down to h where one fails. Not at t = 0:
    a run that fails in its first step started from a finite state."""
    if t <= 0 or not setup.scene.has_flow or setup.method.requires == "flow":
        return False
    try:
        z, _ = exact_flow(Setup.make(setup.scene, "exact", setup.values), None, None, 0.0, t, h)
    except RunError:
        return True
    return not np.all(np.abs(z) < 1e300)


def _reach(D):
    """How far an implicit step of family data D reaches, in units of h times the flow's rate: the
    weight of the new state where H is evaluated (theta: the larger of q's and p's; midpoint 1/2),
    half the longest sub-step of a midpoint composition (composition6's 2.30 h: 1.15), the largest
    row sum of |A| of a Gauss tableau (0.79, 0.89); 1 for any other family."""
    if isinstance(D, Theta):
        return max(D.wq1, D.wp1)
    if isinstance(D, Composition):
        return 0.5 * max(abs(g) for g in D.gammas)
    if isinstance(D, Gauss):
        s = len(D.b)
        return max(sum(abs(D.A[i * s + j]) for j in range(s)) for i in range(s))
    return 1.0


def _below(x):
    """x rounded down to two significant figures."""
    unit = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.floor(x / unit) * unit


def local_rate(setup, Z, t, h, samples=9):
    """The flow's fastest local rate over the step of h from the states Z ((N, 2n) or one state;
    of an ensemble, at most eight members, evenly spread) at t: the largest |eigenvalue| of the
    Jacobian of (dq/dt, dp/dt) in (q, p), by central differences, at `samples` states of each
    explicit Euler step z + s h f(z, t), s in [0, 1] (the region a step's Newton searches), each at
    `samples` times across the step (a fast drive may turn within it). NaN where it is not
    finite. Where h times the rate and the method's reach (_reach) passes 1/2 or so, the
    implicit equations of a step may have no solution near the state, or several, that Newton
    from the state misses, and a smaller h that is not yet small enough can fail sooner (kapitza's
    midpoint at a = 0.3: 0.5 fails in step 46, 0.1 in step 3, 0.045 not at all). A guide, not a
    bound: the eigenvalues of a non-normal Jacobian do not bound the Newton map."""
    m = 2 * setup.scene.ndof
    Z = np.array(Z, dtype=float).reshape(-1, m)
    Z = Z[::-(-len(Z) // 8)]
    J = np.empty((m, m))
    f, plus, minus = np.empty(m + 1), np.empty(m + 1), np.empty(m + 1)
    rate = 0.0
    for z0 in Z:
        vector_field(setup.P, t, z0, f)
        for s in np.linspace(0.0, 1.0, samples):
            z = z0 + s * h * f[:m]
            if not np.all(np.isfinite(z)):
                return math.nan
            for u in np.linspace(0.0, 1.0, samples):
                for j in range(m):
                    d = 1e-6 * max(1.0, abs(z[j]))
                    up, down = z.copy(), z.copy()
                    up[j] += d
                    down[j] -= d
                    vector_field(setup.P, t + u * h, up, plus)
                    vector_field(setup.P, t + u * h, down, minus)
                    J[:, j] = (plus[:m] - minus[:m]) / (2 * d)
                if not np.all(np.isfinite(J)):
                    return math.nan
                rate = max(rate, float(np.max(np.abs(np.linalg.eigvals(J)))))
    return rate


def failure_message(status, step, t, h, exact_overflows=False, at=None):
    """The message of a run that stopped in `step` (from t) with `status`. at = (setup, Z): the
    run's states at the failing step's start (or, in an ensemble, one step on for the members before
    the failing one): for a Newton failure, the flow's fastest local rate over the step from them
    (local_rate) gives an h to try, 1 / (2 rate reach) rounded down, which ran 'Kapitza: Newton
    fails' to T = 100 with each implicit method that fails there (tests/test_hard_cases.py)."""
    where = f"in step {step + 1} (from t = {t:.6g})"
    if status == OVERFLOW and exact_overflows:
        return (f"overflow {where}: the state left floating-point range (|z| > 1.8e308), as the exact solution "
                f"does by then: shorten T below {t:.4g} (no step size helps)")
    if status == OVERFLOW:
        return (f"overflow {where}: the state left floating-point range (|z| > 1.8e308); shorten T, "
                f"or reduce h if the solution should stay bounded")
    if status in (NEWTON, SINGULAR):
        what = "Newton did not converge" if status == NEWTON else "singular Newton matrix"
        if at is not None:
            setup, Z = at
            rate = local_rate(setup, Z, t, h)
            reach = rate * _reach(setup.data)
            guide = _below(0.5 / reach) if 0.0 < reach < math.inf else math.inf
            if guide < h:
                return (f"{what} {where}: the flow's local rate there is {rate:.3g}, h times it {h * rate:.3g}; "
                        f"try h below {guide:.2g} (a guide; a smaller h above it can fail sooner)")
        return f"{what} {where}: reduce h"
    return f"run failed {where}"
