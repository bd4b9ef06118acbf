"""Presets: the cases the scenes declare (scenes.base.Case: the paper's figures with their
printed parameters, the Kapitza pendulum, and the hard cases, where the paper's gentle
parameters are left behind; tests/test_registry.py runs each), as links; each scene's first view,
which its Scene menu entry opens (`first_state`); and the URL that holds the app's state.

A preset is a set of app-state values; its link is the URL that opens the app in that state,
in the one format the app writes: text as it is, numbers and the scene's parameters as JSON,
numbers with at most 10 significant digits.
"""
import json
from dataclasses import dataclass, field
from urllib.parse import urlencode

from cosymp.scenes import cases, first

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


def case_state(scene, case):
    """The app-state values that open a scene's case."""
    return {"scene": scene.name, "method": case.method, "other": case.other, "h": case.h, "T": case.T,
            "values": dict(case.values), "view": case.view}


def first_state(scene):
    """What picking the scene from the Scene menu opens: its first view (Case.first), as the
    comparison's inputs (the shown tab stays)."""
    state = case_state(scene, first(scene))
    del state["view"]
    return state


def _preset(scene, case):
    return Preset(case.name, case.doc, case_state(scene, case), case.T_long, HARD if case.hard else PAPER,
                  case.fails)


def _presets():
    """The paper's figures, then the hard cases, each in registry order. A scene's first view is no
    link: its Scene menu entry opens it (the lead's is the app's own first view)."""
    ordered = sorted((sc for sc in cases() if not sc[1].first), key=lambda sc: sc[1].hard)
    return tuple(_preset(scene, case) for scene, case in ordered)


PRESETS = _presets()
