"""Play: the comparison animated. The orbit is traced up to the current frame (both methods' whole
orbits beneath in light grey, the same for both: in the methods' colours, A's many overlapping
revolutions built up into what looked like an orbit already traced, and B's dashes were lost), the
carried loop moves, and a cursor marks the time on H~ and on the loop's area.
A new frame sends only the traced part, the loop and the cursors' positions."""
from functools import partial

import numpy as np
import panel as pn
import param

from ..plotting import Pair, drawable, figure, grid, note, pane, path, push, reset_ranges, vline
from .base import Feature, FeatureView
from .cloud import closed
from .common import color_key, comparisons, loops_text, names, phase_axes, record_at, stops_text, zcols
from .structure import time_plots, update_plots

FAINT = "#dee2e6"  # the whole orbits beneath the traced part

TRACE_POINTS = 2000


class Playback(param.Parameterized):
    """The animation's position (frame of FRAMES) and speed (frames per second)."""

    FRAMES = 200
    frame = param.Integer(default=0, bounds=(0, 200), doc="Current frame: 0 the start, FRAMES the whole run.")
    fps = param.Selector(default=20, objects={"5 frames/s": 5, "10 frames/s": 10, "20 frames/s": 20,
                                              "40 frames/s": 40}, doc="Playback speed.")

    @property
    def fraction(self):
        return self.frame / self.FRAMES

    def release(self):
        """Nothing runs in the background."""


def traced(x, y, k):
    """The part of an orbit up to its record k (at most TRACE_POINTS points), and that record (None:
    the whole orbit, and no record: the run stopped before now)."""
    end = len(x) - 1 if k is None else k
    step = max(1, len(x) // TRACE_POINTS)
    now = slice(0) if k is None else slice(k, k + 1)
    return (np.append(x[:end:step], x[end:end + 1]), np.append(y[:end:step], y[end:end + 1])), (x[now], y[now])


class PlayView(FeatureView):
    NAME = "play"

    def layout(self):
        pb = self.state
        self.orbit_fig = figure("orbit, traced (dot: now)", "q", "p")
        self.faint = Pair(self.orbit_fig, width=1)
        for line in self.faint.lines.values():
            line.glyph.update(line_color=FAINT, line_alpha=0.6, line_dash="solid")
        self.trace = Pair(self.orbit_fig, width=2)
        self.now = Pair(self.orbit_fig, width=0, start=True)
        # equal scales: a circle of initial states is drawn round, so that what deforms it is the method
        self.loop = Pair(figure("loop of initial states, now", "q1", "p1", aspect=True), width=2)
        self.plots = time_plots(["energy", "area"])
        self.cursors = []
        for p in self.plots.values():
            p.decorate(lambda fig: self.cursors.append(vline(fig)))
        self.key = note("")
        self.clock = note("", width=220, sizing_mode=None)
        self._scene = None
        # (Panel 1.9's player sets its slider's value before its maximum when drawn, so a first value
        # above 100 would show halfway: the animation opens at its start.)
        player = pn.widgets.Player(name="Frame", start=0, end=Playback.FRAMES, value=pb.frame, loop_policy="once",
                                   interval=int(1000 / pb.fps), show_value=False, show_loop_controls=False, width=420)
        player.param.watch(lambda e: setattr(pb, "frame", e.new), "value")
        pb.param.watch(lambda e: e.new != player.value and setattr(player, "value", e.new), "frame")
        pb.param.watch(partial(self._speed, player), "fps")
        self.follow(self.study, "results")
        pb.param.watch(self._on_frame, "frame")
        return pn.Column(
            pn.Row(player, pn.widgets.Select.from_param(pb.param.fps, name="Speed", width=140), self.clock),
            self.key,
            grid(pane(self.orbit_fig), pane(self.loop.fig)),
            grid(*[p.panel for p in self.plots.values()]),
            sizing_mode="stretch_width")

    @staticmethod
    def _speed(player, event):
        """The player's interval; while it plays, it is paused and played again in the next message:
        BokehJS's player reads its interval when it starts playing (a speed picked meanwhile changed
        nothing until pause and play)."""
        player.interval = int(1000 / event.new)
        direction = player.direction
        if direction:
            player.direction = 0
            pn.state.curdoc.add_next_tick_callback(lambda: setattr(player, "direction", direction))

    def _on_frame(self, event):
        if self.visible and self._layout is not None and not self._stale:
            push(self.frame)

    def update(self):
        runs = self.study.results
        if runs is None:
            return
        if runs.scene != self._scene:
            for fig in (self.orbit_fig, self.loop.fig):
                reset_ranges(fig)
            i, j, xl, yl, _ = phase_axes(runs.scene)[0]
            self.orbit_fig.xaxis.axis_label, self.orbit_fig.yaxis.axis_label = xl, yl
            self._scene = runs.scene
        i, j = phase_axes(runs.scene)[0][:2]
        self.orbits = {slot: (c.run.t, *map(drawable, zcols(c.run, i, j))) for slot, c in comparisons(runs).items()}
        for p in (self.trace, self.now, self.loop):
            p.colors(names(runs))
        self.faint.set({slot: path(x, y) for slot, (_, x, y) in self.orbits.items()})
        update_plots(self.plots, runs)
        self.key.object = color_key(runs) + stops_text(runs) + loops_text(runs)
        self.frame()

    def frame(self):
        """The frame's time, the same on both runs and loops: each drawn up to its record nearest it
        (a run or loop that stopped before it: traced to its end, with no dot or loop now)."""
        runs = self.study.results
        cs = comparisons(runs)
        now = max((c.run.t[-1] for c in cs.values()), default=0.0) * self.state.fraction
        ends = {slot: traced(x, y, record_at(t, now)) for slot, (t, x, y) in self.orbits.items()}
        self.trace.set({slot: line for slot, (line, _) in ends.items()})
        self.now.set({slot: dot for slot, (_, dot) in ends.items()})
        loops = {}
        for slot, c in cs.items():
            k = None if c.cloud is None else record_at(c.cloud.t, now)
            if k is not None:
                loops[slot] = closed(c.cloud.q[k, :, 0], c.cloud.p[k, :, 0])
        self.loop.set(loops)
        for cursor in self.cursors:
            cursor.location = now
        self.clock.object = f"<p class='clock'>t = {now:.4g} of {runs.T:g}</p>"


FEATURE = Feature("play", "Play", PlayView, lambda study: Playback())
