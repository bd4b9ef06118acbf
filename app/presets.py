"""Presets: the paper's figures with their printed parameters, and the Kapitza pendulum.

A preset is a set of app-state values; its link is the URL that opens the app in that state
(the same query the app writes with `pn.state.location.sync`).
"""
import json
from dataclasses import dataclass, field
from urllib.parse import urlencode

from cosymp.scenes import SCENES

LONG_HORIZONS = {"damped": 5e5, "modulated": 2e5}


def query_items(values, names):
    """URL query items of app-state values, serialized as `pn.state.location.sync` does."""
    return {names[k]: v if isinstance(v, str) else json.dumps(v) for k, v in values.items()}


def long_horizon(scene):
    """The paper's long horizon for the scene, else 100 times its default horizon."""
    return LONG_HORIZONS.get(scene, 100.0 * SCENES[scene].T)


@dataclass(frozen=True)
class Preset:
    """name: the figure it reproduces; state: Study parameters; T_long: the long-run horizon."""

    name: str
    doc: str
    state: dict = field(default_factory=dict)
    T_long: float = None

    def query(self, url_names, long_names):
        """The URL query string (with '?') that opens the app in this preset's state."""
        items = query_items(self.state, url_names)
        if self.T_long is not None:
            items.update(query_items({"T_long": self.T_long}, long_names))
        return "?" + urlencode(items)


PRESETS = (
    Preset("Fig. damped: extended Hamiltonian and symplectic form",
           "Caldirola-Kanai oscillator as printed (gamma 0.2, h 0.1, T 50), the paper's symplectic "
           "Euler scheme against RK4.",
           {"scene": "damped", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {"gamma": 0.2}, "view": "compare"}),
    Preset("Fig. damped: volume form (gamma 2e-4, T 5e5)",
           "The paper's long run: gamma 2e-4, h 0.1, 5e6 steps; start it in the Long run view.",
           {"scene": "damped", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {"gamma": 0.0002}, "view": "long"}, T_long=5e5),
    Preset("Fig. time-dependent potential (T 50)",
           "Oscillator with a slowly modulated stiffness (eps 0.0035, alpha 0.0008, h 0.1, T 50).",
           {"scene": "modulated", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {}, "view": "compare"}),
    Preset("Fig. time-dependent potential: long run (T 2e5)",
           "The same oscillator over 2e6 steps; start it in the Long run view.",
           {"scene": "modulated", "method": "symplectic-euler", "other": "rk4", "h": 0.1, "T": 50.0,
            "values": {}, "view": "long"}, T_long=2e5),
    Preset("Fig. gauge (charged, symplectic Euler, h 0.001, T 20)",
           "The charged particle in five gauges: per-gauge runs and transported maps.",
           {"scene": "charged", "method": "symplectic-euler", "other": "rk4", "h": 0.001, "T": 20.0,
            "values": {}, "view": "gauges"}),
    Preset("Kapitza: stabilized inverted pendulum",
           "Start near the top (q0 = 3.0) with a fast-driven pivot (a = 0.1, nu = 40): it stays up.",
           {"scene": "kapitza", "method": "midpoint", "other": "rk4", "h": 0.002, "T": 20.0,
            "values": {"q0": 3.0, "a": 0.1, "nu": 40.0}, "view": "play"}),
)
