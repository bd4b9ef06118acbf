"""The method registry: a method is data for one of the generic family kernels.

Every method acts on the extended state (q, t, p, p_t); t advances by exactly h per step.
"""
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import numpy as np

from .errors import InputError, as_number, quoted
from .kernels.families import Boris, Composition, Exact, Explicit, Gauss, Perturbed, Splitting, Theta
from .kernels.registry import FAMILIES
from .kernels.stack import MAX_OFFSETS, MAX_STAGES


def _floats(x):
    return np.ascontiguousarray(np.ravel(x), dtype=float)


def _fixed(x, kind=float):
    """Numbers as a tuple, whose length is part of its numba type: a loop compiled for it knows the
    count at compile time and unrolls it (the Gauss methods' stages, and so the size of their
    Newton solve: 1.5-1.8x faster steps; Euler's and RK4's: 1.1-1.35x. Measured with cosymp
    bench and benchmarks/plain.py; the time offsets of Theta, Boris and Exact, see kernels.families)."""
    return tuple(kind(v) for v in np.ravel(x))


FIXED_STAGES = 4
"""Explicit tableaus of at most this many stages are tuples. RK8's 12 stages stay arrays: unrolled,
its 66 stage couplings cost more than they save (modulated 175 -> 275 ns a step)."""


def _explicit(A, b, c):
    offsets, stage = np.unique(np.asarray(c, float), return_inverse=True)
    if len(b) <= FIXED_STAGES:
        return Explicit(_fixed(A), _fixed(b), _fixed(stage, int), _fixed(offsets))
    return Explicit(_floats(A), _floats(b), stage.astype(np.int64), offsets)


def _lifted(theta):
    """The paper's cotangent lift of R_d(q, v) = (q - theta v, q + (1 - theta) v):
    q at theta, p at 1 - theta, t at t_k + theta h (PHYSICS.md section 2)."""
    return Theta(1.0 - theta, theta, theta, 1.0 - theta, _fixed([theta]))


def _naive(theta):
    """The ordinary theta-method: q, p and t all at the same theta point."""
    return Theta(1.0 - theta, theta, 1.0 - theta, theta, _fixed([theta]))


def _composition(gammas):
    gammas = np.asarray(gammas, float)
    starts = np.concatenate(([0.0], np.cumsum(gammas)[:-1]))
    return Composition(_floats(gammas), _floats(starts + 0.5 * gammas))


def _triple_jump(inner, order):
    """Yoshida's symmetric triple jump: raises a symmetric method of order `order` by two."""
    g1 = 1.0 / (2.0 - 2.0 ** (1.0 / (order + 1)))
    g0 = 1.0 - 2.0 * g1
    return [g * x for g in (g1, g0, g1) for x in inner]


def _splitting(a, b):
    """Splitting data from drift and kick coefficients (kick b[i], then drift a[i]). Each set sums
    to 1; the round-off of that sum (published coefficients have 15 digits) goes to the middle one."""
    a, b = np.array(a, float), np.array(b, float)
    assert len(a) == len(b) and abs(a.sum() - 1.0) < 1e-13 and abs(b.sum() - 1.0) < 1e-13
    for x in (a, b):
        x[len(x) // 2] += 1.0 - x.sum()
    times = np.concatenate(([0.0], np.cumsum(a)[:-1]))
    times[np.isclose(times, 1.0, rtol=0.0, atol=1e-14)] = 1.0
    offsets, kick = np.unique(np.where(b != 0.0, times, times[np.flatnonzero(b)[0]]), return_inverse=True)
    return Splitting(_floats(a), _floats(b), kick.astype(np.int64), _floats(offsets))


LEAPFROG = ((0.5, 0.5), (0.0, 1.0))
"""Störmer-Verlet as splitting coefficients (drifts a, kicks b): half drift, kick, half drift."""


def _flows(a, b):
    """The sequence of a splitting's flows, ('kick' or 'drift', coefficient), empty ones left out."""
    return [f for i in range(len(a)) for f in (("kick", b[i]), ("drift", a[i])) if f[1] != 0.0]


def compose(base, gammas):
    """The symmetric composition of a symmetric base step: sub-steps of sizes gammas[i] h (the
    gammas sum to 1 and read the same backwards), as data of the base's family.

    base: the midpoint rule's data (Theta at 1/2), giving a Composition of midpoint sub-steps; or
    a symmetric splitting's coefficients (drifts a, kicks b), giving Splitting data in which a
    sub-step that starts with a drift has it merged into the previous sub-step's last drift."""
    gammas = np.asarray(gammas, float)
    assert np.allclose(gammas, gammas[::-1], rtol=0.0, atol=1e-15), "compositions need symmetric coefficients"
    if isinstance(base, Theta):
        assert base.wq0 == base.wq1 == base.wp0 == base.wp1 == 0.5, "compose the midpoint rule (theta 1/2)"
        data = _composition(gammas)
    else:
        a, b = (np.asarray(x, float) for x in base)
        flows = _flows(a, b)
        assert flows == flows[::-1], "compose a symmetric splitting (its flows read the same backwards)"
        drifts, kicks = [], []
        for g in gammas:
            for i in range(len(a)):
                if kicks and b[i] == 0.0:
                    drifts[-1] += g * a[i]
                else:
                    drifts.append(g * a[i])
                    kicks.append(g * b[i])
        data = _splitting(drifts, kicks)
    assert len(data.offsets) <= MAX_OFFSETS, "raise kernels.stack's bounds"
    return data


# Blanes & Moan, J. Comput. Appl. Math. 142 (2002) 313-330, Table 3: symmetric symplectic
# Runge-Kutta-Nystrom methods in kick-drift form (b: kicks, a: drifts, the last drift empty).
# They need [V, [V, [V, T + p_t]]] = 0, which holds when T is quadratic in p (any t dependence).
SRKN6B = ([0.245298957184271, 0.604872665711080, -0.350171622895351, -0.350171622895351,
           0.604872665711080, 0.245298957184271, 0.0],
          [0.0829844064174052, 0.396309801498368, -0.0390563049223486, 0.1195241940131508,
           -0.0390563049223486, 0.396309801498368, 0.0829844064174052])
# SRKN^a_14 of the same table, order 6 in 14 stages, drift first (the first kick empty). Each
# half's middle coefficient follows from the sums (a: 1, b: 1/2).
_SRKN14A_A = [0.0378593198406116, 0.102635633102435, -0.0258678882665587, 0.314241403071447, -0.130144459517415,
              0.106417700369543, -0.00879424312851058]
_SRKN14A_B = [0.09171915262446165, 0.183983170005006, -0.05653436583288827, 0.004914688774712854,
              0.143761127168358, 0.328567693746804]
SRKN14A = ([*_SRKN14A_A, 1.0 - 2.0 * sum(_SRKN14A_A), *_SRKN14A_A[::-1]],
           [0.0, *_SRKN14A_B, 0.5 - sum(_SRKN14A_B), 0.5 - sum(_SRKN14A_B), *_SRKN14A_B[::-1]])


# Blanes, Casas, Farres, Laskar, Makazaga & Murua, Appl. Numer. Math. 68 (2013) 58-72: ABA864, the
# symmetric splitting A B A ... A of generalized order (8, 6, 4) for H = A + eps B: its error is
# O(eps h^8 + eps^2 h^6 + eps^3 h^4). As (drifts a: the flows of A, kicks b: of eps B), kick b[i]
# then drift a[i], the first kick empty.
_ABA864_A = [0.0711334264982231177779387300061549964174, 0.241153427956640098736487795326289649618,
             0.521411761772814789212136078067994229991, -0.333698616227678005726562603400438876027]
_ABA864_B = [0.183083687472197221961703757166430291072, 0.310782859898574869507522291054262796375,
             -0.0265646185119588006972121379164987592663, 0.0653961422823734184559721793911134363710]
ABA864 = ([*_ABA864_A, *_ABA864_A[::-1]], [0.0, *_ABA864_B, *_ABA864_B[-2::-1]])


def _mirrored(half, middle):
    """The coefficients of a symmetric composition from its first half and its middle one."""
    return [*half, middle, *half[::-1]]


# McLachlan's symmetric composition of order 8 in 15 stages with an optimised error constant,
# SIAM J. Sci. Comput. 16 (1995) 151-168 (as tabulated in OrdinaryDiffEq.jl, McAte8). It raises any
# symmetric step of order 2 to order 8: here the extended leapfrog.
MCLACHLAN8 = _mirrored([0.74167036435061295344822780, -0.40910082580003159399730010, 0.19075471029623837995387626,
                        -0.57386247111608226665638773, 0.29906418130365592384446354, 0.33462491824529818378495798,
                        0.31529309239676659663205666], -0.79688793935291635401978884)


def _rk4():
    A = np.zeros((4, 4))
    A[1, 0] = A[2, 1] = 0.5
    A[3, 2] = 1.0
    return _explicit(A, [1 / 6, 1 / 3, 1 / 3, 1 / 6], [0.0, 0.5, 0.5, 1.0])


def _rk8():
    """DOP853's eighth-order tableau (taken from scipy), used at a fixed step."""
    from scipy.integrate._ivp import dop853_coefficients as d

    s = d.N_STAGES
    return _explicit(d.A[:s, :s], d.B, d.C[:s])


def _gauss4():
    r = math.sqrt(3.0) / 6.0
    A = np.array([[0.25, 0.25 - r], [0.25 + r, 0.25]])
    return Gauss(_fixed(A), _fixed([0.5, 0.5]), _fixed([0.5 - r, 0.5 + r]))


def _gauss6():
    r = math.sqrt(15.0)
    A = np.array([[5 / 36, 2 / 9 - r / 15, 5 / 36 - r / 30],
                  [5 / 36 + r / 24, 2 / 9, 5 / 36 - r / 24],
                  [5 / 36 + r / 30, 2 / 9 + r / 15, 5 / 36]])
    return Gauss(_fixed(A), _fixed([5 / 18, 4 / 9, 5 / 18]), _fixed([0.5 - r / 10, 0.5, 0.5 + r / 10]))


def _theta(value):
    """theta as a float: numbers and numeric text are taken, anything else is refused."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise InputError(f"theta = {quoted(value)} is not a number: pass --theta between 0 and 1") from None
    return as_number(value, "theta")


@dataclass(frozen=True)
class Method:
    """A named method. `build(theta)` gives the family data the kernels run."""

    name: str
    title: str
    doc: str
    order: int
    preserves: str
    build: Callable
    takes_theta: bool = False
    requires: str = ""

    def label(self, theta=None):
        """The method's name, with its θ for the methods that take one (a plot legend's label)."""
        return f"{self.name} (θ = {theta:g})" if self.takes_theta else self.name

    def order_at(self, theta):
        if self.takes_theta:
            return 2 if theta == 0.5 else 1
        return self.order

    def preserves_at(self, theta):
        if self.name == "theta-naive" and theta != 0.5:
            return "none"
        return self.preserves

    def refusal(self, scene, titles=False):
        """None if the method applies to the scene, else the reason it does not: naming the method
        and scenes as the command line does, or with `titles` as the app's menus do."""
        method = self.title if titles else f"method '{self.name}'"
        named = f"“{scene.title}”" if titles else f"scene '{scene.name}'"

        def on(attr):
            return ", ".join(f"“{s.title}”" if titles else s.name for s in _with(attr))

        if self.requires == "separable" and not scene.separable:
            return (f"{method} splits H = T(p, t) + V(q, t) and {named} is not separable: use it on "
                    f"{on('separable')}")
        if self.requires == "integrable" and not scene.near_integrable:
            return (f"{method} splits H = H0 + (H - H0), H0's flow in closed form and H - H0 small, and {named} "
                    f"declares no such H0: use it on {on('near_integrable')}")
        if self.requires == "flow" and not scene.has_flow:
            return f"{method} needs a closed-form flow and {named} has none: use it on {on('has_flow')}"
        if self.requires == "fields" and not scene.has_fields:
            return f"{method} pushes a charge in E and B fields; {named} has none: use it on {on('has_fields')}"
        return None

    def data(self, theta=None):
        if self.takes_theta:
            theta = 0.5 if theta is None else _theta(theta)
            if not 0.0 <= theta <= 1.0:
                raise InputError(f"theta = {theta} is outside [0, 1]: pass --theta between 0 and 1")
            return _data(self.name, float(theta))
        if theta is not None:
            raise InputError(f"method '{self.name}' takes no theta ({THETA_APPLIES}): use one of them, or drop theta")
        return _data(self.name, None)


def _with(attr):
    from .scenes import SCENES

    return [s for s in SCENES.values() if getattr(s, attr)]


@cache
def _data(name, theta):
    m = METHODS[name]
    data = m.build(theta) if m.takes_theta else m.build()
    stages = len(getattr(data, "b", ()))
    assert type(data) in FAMILIES, f"register the family of {name} in kernels.registry"
    assert len(data.offsets) <= MAX_OFFSETS and stages <= MAX_STAGES, "raise kernels.stack's bounds"
    return data


_TJ4 = _triple_jump([1.0], 2)

METHODS = {m.name: m for m in (
    Method("euler", "Explicit Euler", "explicit Euler on the extended ODE (non-preserving; the usual method to compare with)",
           1, "none", lambda: _explicit([[0.0]], [1.0], [0.0])),
    Method("rk4", "Classical RK4", "classical fourth-order Runge-Kutta (non-preserving; the usual method to compare with)",
           4, "none", _rk4),
    Method("rk8", "RK8 (DOP853 tableau)", "explicit order-8 Runge-Kutta, DOP853's tableau at a fixed "
           "step; the reference integrator for scenes without a closed-form flow", 8, "none", _rk8),
    Method("theta", "Lifted theta-method", "the paper's cotangent-lifted discretization map: q at "
           "theta, p at 1 - theta; slice-symplectic for every theta in [0, 1]", 1, "symplectic",
           _lifted, takes_theta=True),
    Method("midpoint", "Implicit midpoint", "the lifted theta-method at theta = 1/2", 2, "symplectic",
           lambda: _lifted(0.5)),
    Method("symplectic-euler", "Symplectic Euler (paper's scheme)", "the lifted theta-method at "
           "theta = 0: q, t at step k, p at k+1 (the paper's eq. euler-type)", 1, "symplectic",
           lambda: _lifted(0.0)),
    Method("theta-naive", "Naive theta-method", "the ordinary theta-method: q, p, t all at theta; "
           "symplectic only at theta = 1/2", 1, "symplectic", _naive, takes_theta=True),
    Method("gauss4", "Gauss-Legendre 4", "2-stage Gauss-Legendre collocation, order 4, symplectic",
           4, "symplectic", _gauss4),
    Method("gauss6", "Gauss-Legendre 6", "3-stage Gauss-Legendre collocation, order 6, symplectic; three "
           "stages per step where the order-6 composition takes nine midpoint steps", 6, "symplectic", _gauss6),
    Method("composition4", "Midpoint triple jump (order 4)", "symmetric composition of 3 midpoint "
           "steps (Yoshida's triple jump)", 4, "symplectic", lambda: compose(_lifted(0.5), _TJ4)),
    Method("composition6", "Midpoint composition (order 6)", "the triple jump applied to the order-4 "
           "composition: 9 midpoint steps", 6, "symplectic",
           lambda: compose(_lifted(0.5), _triple_jump(_TJ4, 4))),
    Method("boris", "Boris push", "the standard charged-particle pusher (drift-kick-drift, fields at "
           "the half step); volume-preserving, gauge-independent", 2, "volume",
           lambda: Boris(_fixed([0.0, 0.5, 1.0])), requires="fields"),
    Method("leapfrog", "Störmer-Verlet leapfrog", "explicit splitting of a separable H: half drift (T and "
           "t), kick (V), half drift; symplectic on the extended phase space, one force per step", 2,
           "symplectic", lambda: compose(LEAPFROG, [1.0]), requires="separable"),
    Method("yoshida4", "Yoshida 4 (leapfrog triple jump)", "Yoshida's triple jump of the leapfrog: 3 "
           "forces per step", 4, "symplectic", lambda: compose(LEAPFROG, _TJ4), requires="separable"),
    Method("yoshida6", "Yoshida 6 (triple jump of Yoshida 4)", "the triple jump applied to Yoshida 4: "
           "9 forces per step", 6, "symplectic", lambda: compose(LEAPFROG, _triple_jump(_TJ4, 4)),
           requires="separable"),
    Method("blanes-moan4", "Blanes-Moan SRKN 4", "Blanes & Moan's optimised order-4 Runge-Kutta-Nystrom "
           "splitting (2002, SRKN6b): 7 forces per step here (the last and the next step's first are not "
           "merged)", 4, "symplectic",
           lambda: _splitting(*SRKN6B), requires="separable"),
    Method("blanes-moan6", "Blanes-Moan SRKN 6", "Blanes & Moan's optimised order-6 Runge-Kutta-Nystrom "
           "splitting (2002, SRKN14a): 14 forces per step", 6, "symplectic",
           lambda: _splitting(*SRKN14A), requires="separable"),
    Method("mclachlan8", "McLachlan 8 (15 leapfrogs)", "McLachlan's optimised symmetric composition of 15 "
           "leapfrog steps (1995), order 8: 15 forces per step", 8, "symplectic",
           lambda: compose(LEAPFROG, MCLACHLAN8), requires="separable"),
    Method("aba864", "ABA864 (near-integrable splitting)", "Blanes, Casas, Farres, Laskar, Makazaga & "
           "Murua's splitting (2013) of H = H0 + (H - H0): 8 exact flows of H0 (the unperturbed oscillator "
           "and t), 7 kicks of the small H - H0 per step; order 4, error O(eps h^8 + eps^2 h^6 + eps^3 h^4) "
           "for a perturbation of size eps", 4, "symplectic",
           lambda: Perturbed(*_splitting(*ABA864)), requires="integrable"),
    Method("exact", "Exact flow", "the scene's closed-form flow", 0, "exact",
           lambda: Exact(_fixed([0.0, 1.0])), requires="flow"),
)}

THETA_APPLIES = "theta applies to the methods " + " and ".join(f"'{m.name}'" for m in METHODS.values() if m.takes_theta)


def applicable(names, scene):
    """The names among `names` whose methods apply to `scene`, in their order."""
    return [m for m in names if METHODS[m].refusal(scene) is None]


def method(name):
    if name not in METHODS:
        raise InputError(f"unknown method {quoted(name)}: choose one of {', '.join(METHODS)}")
    return METHODS[name]
