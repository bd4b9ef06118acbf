"""Theta lesson: the paper's lifted θ-method against the naive θ-method at the same θ, on the
sidebar's scene: their one-step defects over θ ∈ [0, 1] (symplectic for every θ in one, only at
θ = 1/2 in the other), and the two runs at the chosen θ."""
import numpy as np
import panel as pn
import param

from cosymp.drive import Drive
from cosymp.errors import RunError
from cosymp.integrate import Setup, check_step

from ..plotting import FLOOR, SLOTS, Curves, Pair, figure, grid, note, pane, vline
from ..study import (
    SECONDS_PER_STEP,
    Runs,
    comparison_bytes,
    expected_quick,
    failure_note,
    loops_bytes,
    note_rate,
    run_pair,
)
from .base import Feature, FeatureView, Follower
from .cloud import Snapshots, loops, undrawn_text
from .common import color_key, loops_text
from .structure import time_plots, update_plots

SWEEP_THETAS = np.linspace(0.0, 1.0, 21)
SWEEP_STEPS = 200
METHODS = ("theta", "theta-naive")
LESSON_THETA = 0.3  # where the two methods differ (at 1/2 they are the same method)
LESSON_SECONDS_PER_STEP = {}  # scene -> what its last lesson in this server took per step (the θ sweep included)

TEXT = ("<p>Both methods evaluate H at an intermediate point of each step. The <b>lifted</b> θ-method (the "
        "paper's cotangent lift) puts q at θ and p at 1 − θ: it is symplectic on every time slice <b>for every "
        "θ</b>. The <b>naive</b> θ-method puts q and p both at θ: symplectic <b>only at θ = 1/2</b>. Move θ and "
        "watch |det M − 1| and the carried area.</p>")
SWEEP_TEXT = ("<p class='doc'>Top: the largest one-step defect over the first steps of the run, for 21 values of "
              "θ (dashed line: the θ of the slider). Below: the two methods at that θ.</p>")


def theta_sweep(setups, h, T):
    """max |det M - 1| and max ||M^T J M - J|| over the first steps, for each θ of SWEEP_THETAS."""
    steps = min(SWEEP_STEPS, check_step(h, T))
    out = {"thetas": SWEEP_THETAS}
    for s in setups:
        det, symp = [], []
        for th in SWEEP_THETAS:
            try:
                drive = Drive(Setup.make(s.scene, s.method, s.values, float(th)), h, energy=False)
                drive.run(steps)
                det.append(drive.det_max_dev)
                symp.append(drive.symp_max_dev)
            except RunError:
                det.append(np.nan)
                symp.append(np.nan)
        out[s.method.name] = {"det": np.array(det), "symp": np.array(symp)}
    return out


class ThetaLesson(Follower):
    """The lifted and the naive θ-method at the study's θ on the study's scene, and the θ sweep of
    their one-step defects (recomputed only when the scene, its parameters or h change)."""

    NAME = "theta"
    KIND = "θ lesson"
    WHAT = "the θ lesson"
    HOLD = True
    WATCHED = ("scene", "h", "T", "values")
    theta = param.Number(default=LESSON_THETA, bounds=(0.0, 1.0), step=0.01, label="θ",
                         doc="θ of both methods (they coincide at θ = 1/2).")
    results = param.ClassSelector(class_=Runs, doc="Lifted and naive runs at the lesson's θ.")
    sweep = param.Dict(default=None, allow_None=True,
                       doc="'thetas', and per method name {'det': max |det M - 1|, 'symp': max |M^T J M - J|} "
                           "at each θ.")

    def __init__(self, study, **params):
        self._sweep_key = None
        self._shown = None
        super().__init__(study, **params)
        self.param.watch(lambda e: self._on_study(), "theta")

    def _inputs(self):
        s = self.study
        setups = tuple(Setup.make(s.scene, m, s.values, self.theta) for m in METHODS)
        s.check_horizon()
        key = (s.scene, tuple(sorted(s.values.items())), float(s.h))
        inputs = (s.scene, setups, float(s.h), float(s.T), key)
        return None if (key, float(s.T), self.theta) == self._shown else inputs

    def _bytes(self, inputs):
        return comparison_bytes(*inputs[1:4]) + loops_bytes(*inputs[1:4])

    def _compute(self, inputs, run):
        scene, setups, h, T, key = inputs
        sweep = None if key == self._sweep_key else theta_sweep(setups, h, T)
        return run_pair(scene, setups, h, T, loops=True), sweep, key  # the lesson draws the loops

    def _finish(self, inputs, result):
        runs, sweep, key = result
        self._shown = (key, inputs[3], inputs[1][0].theta)
        if sweep is not None:
            self._sweep_key = key
        self.param.update(results=runs, **({"sweep": sweep} if sweep is not None else {}))  # one redraw
        note_ = failure_note(runs)
        if note_:
            self.say(note_)

    def quick(self):
        """Whether the lesson is expected to take at most QUICK_S: by the last lesson of this scene in
        this server, else by the sidebar's last comparison with its carried loops (two runs of the same
        steps, the same diagnostics, loops as the lesson's). A quick lesson is computed in the handler of
        the change that asks for it (a first visit of the tab: its eight figures then come with the tab,
        not in a second message)."""
        s = self.study
        rate = LESSON_SECONDS_PER_STEP.get(s.scene, SECONDS_PER_STEP.get((s.scene, s.method, s.other, True)))
        return expected_quick(rate, s.h, s.T)

    def _done_in(self, inputs, elapsed):
        """A live view keeps no status line; its cost per step is noted (`quick`), as the time the
        computation took (see Study._done_in and `note_rate`)."""
        scene, _, h, T, _ = inputs
        note_rate(LESSON_SECONDS_PER_STEP, scene, self.run, check_step(h, T))


class ThetaView(FeatureView):
    NAME = "theta"

    def layout(self):
        lesson = self.state
        self.sweeps = {k: Pair(figure(title, "θ", label, logy=True), dots=True)
                       for k, title, label in (("det", "max |det M_k − 1| over the first steps, against θ",
                                                "max |det M_k − 1|"),
                                               ("symp", "max |M_kᵀ J M_k − J| over the first steps, against θ",
                                                "max |M_kᵀ J M_k − J|"))}
        self.marks = [vline(p.fig) for p in self.sweeps.values()]
        # |H~| and the carried area on log axes from the start: the naive method's drift decades away from
        # the lifted one's at most θ, and a linear figure swapped for a log one at the first data cost the
        # first visit a second figure (0.1-0.7 s of the server's time and a layout in the browser; the
        # area's came whenever the tab was built ahead and its lesson computed at the visit).
        self.plots = {**time_plots(["det", "symp", "area"], log={"area"}),
                      "energy": Curves("|H~| = |H + p_t|", "t", "|H + p_t|", log=True)}
        self.snapshots = {slot: Snapshots(f"{label}: loop at t = 0 (light), T/4, T/2, 3T/4, T (dark)")
                          for slot, label in zip(("A", "B"), ("lifted", "naive"))}
        self.key = note("")
        self.follow(lesson, "results", "sweep", "theta")
        return pn.Column(
            note(TEXT), self.key,
            pn.widgets.FloatSlider.from_param(lesson.param.theta, sizing_mode="stretch_width"),
            note(SWEEP_TEXT),
            grid(*[pane(p.fig) for p in self.sweeps.values()]),
            grid(*[p.panel for p in self.plots.values()]),
            grid(*[pane(s.fig) for s in self.snapshots.values()]),
            sizing_mode="stretch_width")

    def update(self):
        lesson = self.state
        runs, sweep = lesson.results, lesson.sweep
        if sweep is not None:
            for k, p in self.sweeps.items():
                p.colors(METHODS)
                p.set({slot: (sweep["thetas"], np.maximum(sweep[m][k], FLOOR)) for slot, m in zip(SLOTS, METHODS)})
        for mark in self.marks:
            mark.location = lesson.theta
        if runs is None:
            return
        update_plots(self.plots, runs)
        loops(runs, self.snapshots)
        self.key.object = color_key(runs) + loops_text(runs) + undrawn_text(runs)


FEATURE = Feature("theta", "Theta lesson", ThetaView, ThetaLesson, url={"theta": "lesson_theta"})
