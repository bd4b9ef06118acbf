"""What a scene is: parameters with defaults, bounds and docs, equations, and its jitted core."""
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..errors import InputError, quoted
from ..kernels.dispatch import INLINE, register


@njit(**INLINE)
def unscaled(P, t):
    """The scaling exponent of a scene whose coefficients stay in range: 0 (see SceneKernel)."""
    return 0


@njit(**INLINE)
def unshifted(P, e):
    """The time shift of a scene without scaling: 0."""
    return 0.0


@njit(**INLINE)
def free_drift(P, t0, tau, z):
    """The drift of a separable scene with T = p^2/2 (one degree of freedom): q += tau p; p_t stays."""
    z[0] += tau * z[1]
    return -0.0


@dataclass(frozen=True)
class Param:
    """A scene parameter. Numeric unless choices is set; initial marks an initial condition."""

    name: str
    default: object
    doc: str
    bounds: tuple = (-math.inf, math.inf)
    initial: bool = False
    choices: tuple = ()

    def check(self, value):
        """The value as the scene stores it, or InputError saying what to change."""
        if self.choices:
            if value not in self.choices:
                raise InputError(f"unknown {self.name} {quoted(value)}: choose one of {', '.join(self.choices)}")
            return value
        try:
            x = float(value)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{self.name} must be a number, got {quoted(value)}") from None
        lo, hi = self.bounds
        if not math.isfinite(x) or not lo <= x <= hi:
            raise InputError(f"{self.name} = {quoted(value)} is outside [{lo:g}, {hi:g}]: {self.doc}")
        return x


@dataclass(frozen=True)
class SceneKernel:
    """The jitted functions the compiled loops dispatch to (see cosymp.kernels.dispatch).

    scaling(P, t) -> e and shift(P, e) -> tau declare a symmetry that keeps a step's arithmetic in
    floating-point range: H(q, p, t) = H(2^-e q, 2^e p, t - tau) for the step from t (tau depends
    on e alone, so a loop computes it only where e changes: kernels.loops._scale). The loops then take that
    step on the scaled state (q 2^-e, p 2^e) with coefficients at t - tau, and scale back. The
    scaling is symplectic and constant within the step, and powers of two are exact, so every
    method takes the same step up to rounding; only values that would overflow (coefficients e^{gamma t} of the
    damped scene) stay finite while the state does.

    scaled_beyond(P) (Python) gives the |t| up to which a step needs no scaling (the coefficients
    and the state stay far inside floating-point range): a run whose range stays below it takes
    plain steps (Scene.needs_scaling), which cost less. None: never scaled.

    A separable scene, H = T(p, t) + V(q, t), also gives the exact flows the splitting methods
    compose, each returning its p_t increment: kick(P, C, j, tau, z), the flow of V for a time tau
    at the time of row j (p moves), and drift(P, t0, tau, z), the flow of T + p_t from t0 to
    t0 + tau (q and t move).

    A near-integrable scene, H = H0 + (H - H0) with H0's flow in closed form and H - H0 small,
    gives the flows the near-integrable splittings compose: rotate(P, t0, tau, z), the flow of
    H0 + p_t from t0 to t0 + tau, and nudge(P, C, j, tau, z), the flow of H - H0 for a time tau at
    the time of row j, each returning its p_t increment.

    energy_coef(P, t, C, j) fills only what energy reads of row j, where that costs less than coef
    (H after every step, at a time where the step has no row: kernels.survey._energy_after; the
    modulated oscillator's sin(αt) without its cos). None: coef.

    diagonal: H is quadratic (scenes.quadratic) with S(t) and dS/dt diagonal, so that its forms skip
    the couplings, which are zero.
    """

    ndof: int
    ncoef: int
    linear: bool
    coef: Callable
    energy: Callable
    grad: Callable
    hess: Callable
    dhdt: Callable
    flow: Callable = None
    vecpot: Callable = None
    efield: Callable = None
    bfield: Callable = None
    scaling: Callable = unscaled
    shift: Callable = unshifted
    kick: Callable = None
    drift: Callable = None
    rotate: Callable = None
    nudge: Callable = None
    scaled_beyond: Callable = None
    energy_coef: Callable = None
    diagonal: bool = False


@dataclass(frozen=True)
class Case:
    """A run worth opening, declared by its scene: one of the paper's figures, a hard case
    (hard=True: where the paper's gentle parameters are left behind), or the scene's first view.
    The app offers the figures and hard cases as links, and tests/test_registry.py runs every case.

    method, other: the method and the one it is compared with; h, T, values: the run (values
    differ from the scene's defaults); view: what shows it ('compare', 'long', 'gauges' or
    'play'); T_long: the long run's horizon; fails: the methods whose run stops early by design
    (with its message); first: the scene's first view, what the app opens when the scene is picked
    from its Scene menu (one case per scene, shown in Orbits: a structure-preserving method whose
    |H + p_t| stays in a bounded band while the other's drifts out of it within T, at a live
    view's cost; its doc says what to look for); lead: the app's first view (one case of all the
    scenes', also its scene's first).
    """

    name: str
    doc: str
    method: str
    other: str
    h: float
    T: float
    values: dict = field(default_factory=dict)
    view: str = "compare"
    T_long: float = None
    hard: bool = False
    fails: tuple = ()
    first: bool = False
    lead: bool = False


@dataclass(frozen=True)
class Paper:
    """Where a scene is in the paper's numerical sections, as `cosymp report paper` recomputes
    them: the section's title, the values its figures print (beside the scene's h and T), and
    its long run's values and horizon (T_long None: no long run)."""

    section: str
    values: dict = field(default_factory=dict)
    long_values: dict = field(default_factory=dict)
    T_long: float = None


@dataclass(frozen=True, eq=False)
class Scene:
    """A time-dependent Hamiltonian system H(q, p, t), defined once, with all that cosymp's
    command line, reports and app need of it (nothing outside scenes/ names a scene). A scene is
    one object: equal only to itself, and hashable whatever its declarations hold.

    `pack` turns checked values into the kernel's parameter tuple (an instance of `Params`,
    whose class selects the kernel: defining a scene registers its kernel with the compiled
    loops); `initial` gives (q0, p0) in the scene's own coordinates.

    Declarations: `rank`, where the registry lists it (by rank, then name: the app's menu, the
    reports, the tests); `paper` (Paper, or None); `cases` (Case tuple); `map_axes`, the Stability
    map's first axes ((name, start, stop, log) for x and y; None: h around the scene's step by
    its first parameter) and `map_measure`, the measure it opens on; `still_after(P)`, for a scene
    whose Hamiltonian dies out, the time after which its flow no longer moves a state visibly (the
    long run's horizon ends there: beyond it every method's figures are flat). Hooks of a scene with
    gauges: `gauges` ({name: gauge}, the values of its 'gauge' parameter), `mechanical(P, t, q,
    p)`, the gauge-invariant momentum, `gauge_map(P, t, q, p, pt, inverse=False)`, the map
    G_chi from the original gauge to the one in P, and `gauge_jacobian(P_from, P_to, t)`, the
    Jacobian in z of the change of gauge G_to o G_from^-1 at times t. A near-integrable scene
    (kernel.rotate) declares `strong`: values at which H - H0 is as large as H0, where the
    near-integrable splittings show their order in h alone (their error is a series in the size
    of H - H0 as well).
    """

    name: str
    title: str
    summary: str
    look_for: str
    equations: tuple
    params: tuple
    kernel: SceneKernel
    Params: type
    h: float
    T: float
    time_scale: float
    coordinates: tuple = ("q",)
    notes: tuple = field(default_factory=tuple)
    paper: Paper = None
    cases: tuple = ()
    map_axes: tuple = None
    map_measure: str = "growth"
    still_after: Callable = None
    gauges: dict = None
    mechanical: Callable = None
    gauge_map: Callable = None
    gauge_jacobian: Callable = None
    strong: dict = None
    rank: int = 100

    def __post_init__(self):
        register(self.Params, self.kernel)

    @property
    def ndof(self):
        return self.kernel.ndof

    @property
    def has_flow(self):
        return self.kernel.flow is not None

    @property
    def has_fields(self):
        return self.kernel.efield is not None

    @property
    def separable(self):
        return self.kernel.kick is not None

    @property
    def near_integrable(self):
        return self.kernel.rotate is not None

    @property
    def has_gauges(self):
        return self.gauges is not None

    @property
    def T_long(self):
        """The paper's long horizon for the scene, or None."""
        return None if self.paper is None else self.paper.T_long

    def momentum(self, P, t, q, p):
        """The mechanical momentum of states (q, p) at times t where the scene defines one
        (charged: p - e A), else None."""
        return None if self.mechanical is None else self.mechanical(P, t, q, p)

    def long_horizon(self, T, values=None):
        """The long run's horizon for a study to T: 100 T, at most the paper's long horizon
        (T_long) and, but never below T, the time after which the flow is still (`still_after`)."""
        horizon = min(math.inf if self.T_long is None else self.T_long, 100.0 * T)
        if self.still_after is not None:
            horizon = min(horizon, max(T, self.still_after(self.pack(self.values(values)))))
        return horizon

    def needs_scaling(self, P, t_max):
        """Whether a run reaching |t| = t_max needs the scaled steps (decided per run, before it starts)."""
        limit = self.kernel.scaled_beyond
        return limit is not None and t_max > limit(P)

    def values(self, overrides=None):
        """Defaults updated by overrides, each checked; unknown names are refused."""
        known = {p.name: p for p in self.params}
        vals = {p.name: p.default for p in self.params}
        for name, value in (overrides or {}).items():
            if name not in known:
                raise InputError(f"scene '{self.name}' has no parameter {quoted(name)}: "
                                 f"use one of {', '.join(known)}")
            vals[name] = known[name].check(value)
        return vals

    def shown_equations(self, vals):
        """The equations as these values make them (checked values, as `values` returns)."""
        return self.equations

    def unused(self, vals):
        """The parameters these values leave without effect."""
        return ()

    def check_horizon(self, vals, T):
        """InputError where these values make the scene's coefficients singular within [0, T] (none
        here: the scenes' own coefficients are smooth; a typed beta(t) may not be)."""

    def pack(self, vals):
        return self.Params(*(float(vals[f]) for f in self.Params._fields))

    def initial(self, vals):
        n = self.ndof
        names = [p.name for p in self.params if p.initial]
        z = np.array([vals[k] for k in names], dtype=float)
        return z[:n], z[n:]
