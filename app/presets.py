"""Presets: the paper's figures with their printed parameters, the Kapitza pendulum, and the
hard cases (where the paper's gentle parameters are left behind; tests/test_hard_cases.py
asserts what each shows); and the URL that holds the app's state.

A preset is a set of app-state values; its link is the URL that opens the app in that state,
in the one format the app writes: text as it is, numbers and the scene's parameters as JSON,
numbers with at most 10 significant digits.
"""
import json
import math
from dataclasses import dataclass, field
from urllib.parse import urlencode

LONG_HORIZONS = {"damped": 5e5, "modulated": 2e5}
URL_NAMES = {"scene": "scene", "method": "method", "other": "vs", "theta": "theta", "h": "h", "T": "T",
             "values": "p", "view": "view"}
TEXT = ("scene", "method", "other", "view")


def rounded(v):
    """A value as the URL carries it: floats (also inside a dict) to 10 significant digits."""
    if isinstance(v, float):
        return float(f"{v:.10g}")
    if isinstance(v, dict):
        return {k: rounded(x) for k, x in v.items()}
    return v


def query_items(values, names):
    """URL query items of app-state values (see the module's doc)."""
    return {names[k]: v if k in TEXT else json.dumps(rounded(v), separators=(",", ":")) for k, v in values.items()}


def parse_items(query, names):
    """App-state values from URL query items: ({name: value}, [what could not be read])."""
    out, bad = {}, []
    for k, u in names.items():
        if u not in query:
            continue
        text = query[u]
        if k in TEXT:
            out[k] = text
            continue
        try:
            out[k] = json.loads(text)
        except ValueError:
            bad.append(f"{u}={text[:40]}")
    return out, bad


def long_horizon(scene, T):
    """The Long run's default horizon: 100 times the study's horizon T, at most the paper's long
    horizon for the scene. (The paper's own long runs open from their presets, with their
    parameters: its damped run is at γ = 2e-4, and at the scene's γ = 0.2 a run to its 5e5
    overflows at t ≈ 7000.)"""
    return min(LONG_HORIZONS.get(scene, math.inf), 100.0 * T)


PAPER, HARD = "Paper figures", "Hard cases"


@dataclass(frozen=True)
class Preset:
    """name: the figure or case it opens; doc: what to see; state: Study parameters; T_long: the
    long-run horizon; group: PAPER or HARD; fails: the methods whose live run stops early (with
    its message) by design."""

    name: str
    doc: str
    state: dict = field(default_factory=dict)
    T_long: float = None
    group: str = PAPER
    fails: tuple = ()

    def query(self):
        """The URL query string (with '?') that opens the app in this preset's state."""
        items = query_items(self.state, URL_NAMES)
        if self.T_long is not None:
            items["T_long"] = json.dumps(self.T_long)
        return "?" + urlencode(items)


PRESETS = (
    Preset("What structure preservation buys",
           "The app's first view: a strongly modulated oscillator (ε 0.2, α 0.05) at h 0.2 to T 2000. RK4 "
           "(fourth order, 4 stages per step) starts with the smaller |H + p_t| but loses energy at every step: "
           "it passes the symplectic midpoint rule's band near t = 185 and ends ten times above it, while the "
           "band stays put.",
           {"scene": "modulated", "method": "midpoint", "other": "rk4", "h": 0.2, "T": 2000.0,
            "values": {"eps": 0.2, "alpha": 0.05}, "view": "compare"}),
    Preset("Fig. damped: extended Hamiltonian and symplectic form",
           "The paper's symplectic Euler against RK4 (γ 0.2, h 0.1, T 50): the first-order scheme's H + p_t "
           "oscillates in a fixed band, RK4's starts far smaller; the gap is what the long runs close.",
           {"scene": "damped", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {"gamma": 0.2}, "view": "compare"}),
    Preset("Fig. damped: volume form (gamma 2e-4, T 5e5)",
           "The paper's long run (γ 2e-4, h 0.1, 5e6 steps, in the Long run view): the paper's volume "
           "estimator follows the orbit's slow growth for both methods; |det M − 1| stays at round-off only "
           "for the symplectic scheme.",
           {"scene": "damped", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {"gamma": 0.0002}, "view": "long"}, T_long=5e5),
    Preset("Fig. time-dependent potential (T 50)",
           "A slowly modulated stiffness (ε 0.0035, α 0.0008, h 0.1, T 50): over so short a run both methods "
           "keep H + p_t small; the long run shows RK4 drifting.",
           {"scene": "modulated", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {}, "view": "compare"}),
    Preset("Fig. time-dependent potential: long run (T 2e5)",
           "The same oscillator over 2e6 steps (Long run view): the symplectic scheme's H + p_t stays in its "
           "band while RK4's leaves it linearly.",
           {"scene": "modulated", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {}, "view": "long"}, T_long=2e5),
    Preset("Fig. gauge (charged, symplectic Euler, h 0.001, T 20)",
           "The charged particle in five gauges: q and Π agree across gauges, the canonical p does not; "
           "transported maps agree to round-off, per-gauge runs to the method's order.",
           {"scene": "charged", "method": "symplectic-euler", "other": "rk4", "h": 0.001, "T": 20.0,
            "values": {}, "view": "gauges"}),
    Preset("Kapitza: stabilized inverted pendulum",
           "Started near the top (q0 = 3.0) with a fast-driven pivot (a = 0.1, ν = 40), the pendulum stays up, "
           "wobbling at the drive frequency.",
           {"scene": "kapitza", "method": "midpoint", "other": "rk4", "h": 0.002, "T": 20.0,
            "values": {"q0": 3.0, "a": 0.1, "nu": 40.0}, "view": "play"}),
    Preset("RK4 just past its stability limit",
           "The plain oscillator at h = 2.9 > 2√2: RK4's amplitude grows by |R(2.9i)| = 1.19 per step "
           "(1e76 by T), implicit midpoint stays on its circle with 2 points per period.",
           {"scene": "modulated", "method": "midpoint", "other": "rk4", "h": 2.9, "T": 2900.0,
            "values": {"eps": 0.0}, "view": "compare"}, group=HARD),
    Preset("Explicit Euler at a small step",
           "Explicit Euler spirals out at every h, by √(1 + h²) per step (×148 here at h = 0.05); the "
           "paper's symplectic Euler stays on a closed curve.",
           {"scene": "modulated", "method": "symplectic-euler", "other": "euler", "h": 0.05, "T": 200.0,
            "values": {"eps": 0.0}, "view": "compare"}, group=HARD),
    Preset("Mathieu tongue: parametric resonance",
           "Stiffness 1 + 0.2 sin(2t) is inside the principal tongue: the true solution grows like "
           "e^{0.05 t}, and both methods grow at that rate (e^10 by T).",
           {"scene": "modulated", "method": "midpoint", "other": "rk4", "h": 0.05, "T": 200.0,
            "values": {"eps": 0.2, "alpha": 2.0}, "view": "compare"}, group=HARD),
    Preset("Just outside the tongue",
           "The same depth at alpha = 2.5 is stable: the solution beats but stays bounded, and neither "
           "method reports growth.",
           {"scene": "modulated", "method": "midpoint", "other": "rk4", "h": 0.05, "T": 200.0,
            "values": {"eps": 0.2, "alpha": 2.5}, "view": "compare"}, group=HARD),
    Preset("Stiff field, strong B",
           "beta = 5 (1 + 10 sin 50t) reverses 16 times per unit time and gyrates at up to 110: at "
           "h = 0.01 RK4's orbit departs and its H + p_t reaches 1e5; midpoint keeps the angular "
           "momentum x p_y - y p_x exactly.",
           {"scene": "charged", "method": "midpoint", "other": "rk4", "h": 0.01, "T": 20.0,
            "values": {"B0": 5.0, "eps": 10.0, "w": 50.0}, "view": "compare"}, group=HARD),
    Preset("Stiff field, weak B",
           "beta = 0.05 (1 + 10 sin 50t): slow gyration driven by a fast induced E field; both methods "
           "agree at h = 0.01.",
           {"scene": "charged", "method": "midpoint", "other": "rk4", "h": 0.01, "T": 20.0,
            "values": {"B0": 0.05, "eps": 10.0, "w": 50.0}, "view": "compare"}, group=HARD),
    Preset("Damped across 600 decades",
           "gamma T = 1400: e^{gamma t} reaches 1e608, q 1e304 and p 1e-304. Steps are taken in scaled "
           "coordinates, so both runs reach T, and H + p_t stays bounded.",
           {"scene": "damped", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 7000.0,
            "values": {"gamma": 0.2}, "view": "compare"}, group=HARD),
    Preset("Damped beyond floating point",
           "At t = 7098 the true q passes 1.8e308: each run stops there with a message and shows its "
           "data up to that step.",
           {"scene": "damped", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 7500.0,
            "values": {"gamma": 0.2}, "view": "compare"}, group=HARD, fails=("symplectic-euler", "rk4")),
    Preset("Kapitza: Newton at a large step",
           "h = 0.1 with the drive at nu = 40 (h nu = 4): Newton still converges to round-off every step, "
           "and the pendulum stays up.",
           {"scene": "kapitza", "method": "midpoint", "other": "rk4", "h": 0.1, "T": 20.0,
            "values": {"q0": 3.0, "a": 0.1, "nu": 40.0}, "view": "compare"}, group=HARD),
    Preset("Kapitza: Newton fails",
           "a = 0.3 at h = 0.5: the midpoint equations have no nearby solution; the message names the "
           "step and the data up to it stay.",
           {"scene": "kapitza", "method": "midpoint", "other": "rk4", "h": 0.5, "T": 100.0,
            "values": {"q0": 3.0, "a": 0.3, "nu": 40.0}, "view": "compare"}, group=HARD, fails=("midpoint",)),
    Preset("Ten million steps",
           "The modulated oscillator to T = 1e6 at h = 0.1, 1e7 steps per method in the Long run view "
           "(5-10 s): midpoint's H + p_t stays bounded, RK4's drifts.",
           {"scene": "modulated", "method": "midpoint", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {}, "view": "long"}, T_long=1e6, group=HARD),
)
