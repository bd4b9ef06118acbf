"""The app's Stability map (app.features.stabilitymap) and its heat map, without a server."""
import dataclasses
import math
import tracemalloc

import numpy as np
import panel as pn
import pytest
from bokeh.models import LogColorMapper

from app import jobs, memory
from app.features import stabilitymap as maps
from app.features.stabilitymap import StabilityMap
from app.study import Study, soft_range
from cosymp import sweep
from cosymp import workprecision as wp
from cosymp.scenes import SCENES


@pytest.fixture(scope="module")
def tongue():
    """The modulated scene's default axes (alpha x eps) at 9 x 5 cells, growth of midpoint."""
    s = Study(scene="modulated")
    m = StabilityMap(s, nx=9, ny=5)
    m.start()
    return s, m


def test_each_scene_gets_its_default_axes_and_the_study_names_its_choices():
    s = Study(scene="damped")
    m = StabilityMap(s)
    for scene in SCENES.values():
        s.scene = scene.name
        (xn, x0, x1, xl), (yn, y0, y1, yl) = maps.map_axes(scene)
        assert (m.x, m.x_start, m.x_stop, m.x_log, m.y, m.y_start, m.y_stop, m.y_log) == (xn, x0, x1, xl, yn, y0, y1, yl)
        numeric = [p.name for p in s.scene_obj.params if not p.choices and not isinstance(p.default, str)]
        assert m.param.x.objects == numeric + ["h", "T"]
        assert xn != yn and {xn, yn} <= set(numeric + ["h", "T"]) and x0 < x1 and y0 < y1
        if scene.map_axes is not None:
            assert maps.map_axes(scene) == scene.map_axes
        assert m.measure == maps.first_measure(scene) and m.measure in sweep.MEASURES
    s.scene = "kapitza"
    s.method = "theta"
    assert m.param.x.objects[-1] == "theta" and (m.x, m.y) == ("nu", "a")


def test_the_axis_controls_follow_the_scene_when_their_tab_is_shown_and_write_what_is_typed(monkeypatch):
    """Hidden, a scene change leaves the map's eleven controls as they were (each change would be a
    message and a render in the page); shown, they hold the new scene's axes and measure, and follow
    at once; a value set in one is the map's."""
    s = Study(scene="damped")
    m = StabilityMap(s)
    monkeypatch.setattr(m, "request", lambda: None)  # the map a shown tab computes: tested below
    view = maps.StabilityMapView(s, m)
    layout = view.__panel__()
    selects = {w.label: w for w in layout.select(pn.widgets.Select)}
    x_axis, measure = selects["x axis"], selects["Measure"]
    cells = next(w for w in layout.select(pn.widgets.IntInput) if w.label == "cells in x")
    before = (x_axis.value, list(x_axis.options), measure.value)
    assert before == (m.x, m.param.x.objects, m.measure)
    s.message = None
    cells.value = 1000  # beyond the bounds: BokehJS put it back silently while the box had them
    assert m.nx == cells.value != 1000 and s.message.text.startswith(
        f"cells in x = 1000 is outside {m.param.nx.bounds[0]}…{m.param.nx.bounds[1]}: type a value within them")
    s.scene = "modulated"
    assert (m.x, m.y) == ("alpha", "eps")
    assert (x_axis.value, list(x_axis.options), measure.value) == before, "hidden: not sent"
    s.view = "map"
    view.shown()
    assert (x_axis.value, list(x_axis.options), measure.value) == (m.x, m.param.x.objects, m.measure)
    assert [w.value for w in layout.select(pn.widgets.FloatInput)] == [m.x_start, m.x_stop, m.y_start, m.y_stop]
    cells.value = 12
    assert m.nx == 12
    x_axis.value = "h"
    assert m.x == "h"
    s.scene = "kapitza"
    assert (x_axis.value, list(x_axis.options)) == (m.x, m.param.x.objects), "shown: follows at once"


@pytest.mark.parametrize("scene", list(SCENES))
def test_every_scene_opens_on_a_map_that_computes(scene):
    """The first map of every registered scene (a 3 x 3 grid of it) runs without a failed cell."""
    s = Study(scene=scene)
    m = StabilityMap(s, nx=3, ny=3)
    m.start()
    assert m.status.startswith("done") and m.result.values[m.measure].shape == (3, 3)
    assert (m.result.status == "ok").all(), m.result.failures()


def test_no_axis_varies_a_parameter_the_other_values_leave_without_effect():
    """Charged with a constant beta(t): its map varied w x eps, which then shape nothing (the sidebar
    greys them out); every cell was one colour, "at most one e-fold over T in every cell", over axes
    that say nothing. Now the axes and their menus leave them out, and a typed beta(t) B0 too."""
    s = Study(scene="charged")
    m = StabilityMap(s)
    assert (m.x, m.y) == ("w", "eps") and {"w", "eps", "B0"} <= set(m.param.x.objects)
    s.values = {"beta": "constant"}
    assert {m.x, m.y}.isdisjoint({"w", "eps"}) and m.x != m.y
    assert {"w", "eps"}.isdisjoint(m.param.x.objects) and "B0" in m.param.y.objects
    first = (m.x, m.y)
    m.nx = m.ny = 3
    m.start()
    grid = m.result.values[m.measure]
    assert grid.shape == (3, 3) and (m.result.status == "ok").all() and np.ptp(grid) > 0, "the axes act"
    s.values = {"beta": "1 + 0.1*t"}
    assert "B0" not in m.param.x.objects and {m.x, m.y}.isdisjoint({"w", "eps", "B0"})
    s.values = {"beta": "paper"}
    assert {"w", "eps", "B0"} <= set(m.param.x.objects) and (m.x, m.y) == first, "axes that act are kept"
    sent = []
    m.param.watch(sent.append, "x", what="objects")
    s.values = {"eps": 5.0}
    s.values = {"eps": 6.0}
    assert sent == [], "a value that changes no axis's choices sends the menus nothing"


def test_a_scene_without_a_map_entry_gets_h_against_its_first_parameter():
    scene = SCENES["kapitza"]
    bare = dataclasses.replace(scene, name="bare", map_axes=None)
    (xn, x0, x1, xl), (yn, y0, y1, yl) = maps.map_axes(bare)
    assert (xn, xl, yn, yl) == ("h", True, "w0", False) and x0 < scene.h < x1 and (y0, y1) == soft_range(scene.params[0])


def test_the_map_shows_the_principal_tongue_where_the_theory_puts_it(tongue):
    """At alpha = 2 (inside the principal tongue) growth rises with eps, to about eps/4 at
    eps = 0.8 (finite T = 50: within 30 %); at alpha = 4 (between tongues) it stays near 0."""
    _, m = tongue
    res = m.result
    alpha, eps = (np.array(a.values) for a in res.plan.axes)
    g = res.values["growth"]
    assert g.shape == (9, 5) and (res.status == "ok").all()
    i2, i4 = int(np.argmin(abs(alpha - 2.0))), int(np.argmin(abs(alpha - 4.0)))
    assert alpha[i2] == 2.0 and np.all(np.diff(g[i2]) > 0)
    assert g[i2, -1] == pytest.approx(eps[-1] / 4, rel=0.3)
    assert np.max(np.abs(g[i4])) < 0.1 * g[i2, -1]
    assert m.status.startswith("done") and "alpha 0.5…4.5 × eps 0…0.8" in m.setting


def test_the_map_equals_the_command_lines_sweep(tongue):
    """What the view shows is cosymp.sweep's result for the plan its command line names."""
    _, m = tongue
    cmd = maps.map_command(m.result.plan)
    assert cmd.startswith("cosymp sweep modulated --method midpoint --vary alpha=0.5:4.5:9 --vary eps=0:0.8:5")
    again = sweep.run(sweep.plan("modulated", "midpoint", ["alpha=0.5:4.5:9", "eps=0:0.8:5"], ["growth"],
                                 h=0.1, T=50))
    assert np.array_equal(again.values["growth"], m.result.values["growth"])


def test_clicking_a_cell_opens_its_run_in_the_orbits_view(tongue):
    s, m = tongue
    m.open_cell(3, 4)
    plan = m.result.plan
    assert s.view == "compare" and s.method == "midpoint"
    assert s.values == {"alpha": maps.significant(plan.axes[0].values[3]), "eps": maps.significant(plan.axes[1].values[4])}
    assert s.results.entries[0].comparison.run.setup.values["eps"] == plan.axes[1].values[4]


def test_a_cell_of_an_h_axis_sets_the_step():
    s = Study(scene="decaying")
    m = StabilityMap(s, nx=3, ny=2, measure="error_final")
    m.start()
    assert m.result.plan.axes[0].log and m.result.plan.axes[0].name == "h"
    m.open_cell(2, 1)
    assert s.h == m.result.plan.axes[0].values[2] == 3.0 and s.values == {"lam": 5.0}


def test_a_map_built_before_its_data_has_every_column_its_glyphs_read_and_a_colour_range(tongue):
    """The map is built ahead, empty: its quads read left, right, bottom, top and z from a source
    that held only x and y, and its log colour range was -Infinity (BokehJS warned of each, on every
    page that built the tab)."""
    _, m = tongue
    plot = maps.MapPlot(False, False, lambda i, j: None)
    glyph = plot.fig.renderers[0].glyph
    read = {glyph.left, glyph.right, glyph.bottom, glyph.top, glyph.fill_color.field}
    assert read <= set(plot.source.data) and all(len(v) == 0 for v in plot.source.data.values())
    assert 0 < plot.mapper.low < plot.mapper.high < math.inf
    assert set(maps.cells(m.result)) == set(plot.source.data), "the data it is sent later has the same columns"


def test_the_heat_map_taps_to_the_cell_under_the_click_and_marks_failures(tongue):
    _, m = tongue
    opened = []
    plot = maps.MapPlot(False, False, lambda i, j: opened.append((i, j)))
    plot.set(m.result)
    assert [name for name, _ in plot.hover.tooltips] == ["alpha", "eps", maps.MEASURE_TITLES["growth"]]
    data = plot.source.data
    assert len(data["z"]) == 45 and np.array_equal(np.sort(data["z"]), np.sort(m.result.values["growth"].ravel()))
    x, y = 2.05, 0.39
    k = int(np.flatnonzero((data["left"] <= x) & (x < data["right"]) & (data["bottom"] <= y) & (y < data["top"]))[0])
    plot.source.selected.indices = [k]
    assert opened == [(3, 2)]
    assert "Every one of the 45 runs completed" in maps.map_failures(m.result)
    failed = sweep.run(sweep.plan("modulated", "rk4", ["h=2:3.6:3", "eps=0:0:1"], ["growth"], T=5000))
    assert list(failed.status.ravel() != "ok") == [False, False, True]
    assert "1 of 3 runs failed" in maps.map_failures(failed) and "overflow" in maps.map_failures(failed)
    plot.set(failed)
    assert np.isnan(plot.source.data["z"]).sum() == 1, "a failed cell is drawn in the mapper's NaN colour (black)"
    assert plot.mapper.nan_color == "black"
    # runs that completed but whose reference failed (beta = exp(t) beyond t = 8.87) were counted as failed runs
    unmeasured = sweep.run(sweep.plan("charged", "midpoint", ["T=8:9:2", "x0=0.1:0.1:1"], ["error_final"],
                                      values={"beta": "exp(t)"}))
    said = maps.map_failures(unmeasured)
    assert "runs failed" not in said and "1 of 2 runs have no error</b> (black cells; the runs completed)" in said
    assert "the reference for the error at T" in said


def test_a_map_of_nearly_one_colour_says_so_and_where_to_look(tongue):
    """At the charged scene's paper values (B0 0.05, T 20) every cell of the w x eps map grows alike;
    the tongue map's cells differ by decades and get no such sentence."""
    s = Study(scene="charged")
    m = StabilityMap(s, nx=3, ny=3)
    m.start()
    z = m.result.values["growth"]
    assert z.max() <= maps.UNIFORM * z.min()
    assert "Nearly one colour" in maps.uniform_text(m.result) and f"{z.min():.3g}" in maps.uniform_text(m.result)
    _, tongue_map = tongue
    assert maps.uniform_text(tongue_map.result) == "" and maps.uniform_text(None) == ""


def test_growth_is_coloured_in_e_folds_from_one_over_T_and_round_off_is_one_colour(tongue):
    """Midpoint on the decaying oscillator: every one-step map is a rotation, so the growth is
    round-off (|growth| ~ 1e-16) in every cell; below 1/T (one e-fold over the run) it is the
    lowest colour, not noise drawn as structure, and the title says why. The tongue map spans 1/T to
    its largest growth."""
    flat = sweep.run(sweep.plan("decaying", "midpoint", ["h=0.05:3:4:log", "lam=0.1:5:3"], ["growth"], T=10))
    assert np.abs(flat.values["growth"]).max() < 1e-14
    plot = maps.MapPlot(True, False, lambda i, j: None)
    plot.set(flat)
    assert isinstance(plot.mapper, LogColorMapper) and plot.mapper.low == 0.1
    assert all(colour_index(plot.mapper, z) == 0 for z in plot.source.data["z"])
    assert plot.fig.title.text.endswith("at most one e-fold over T in every cell (growth ≤ 1/T = 0.1)")
    _, m = tongue
    plot.set(m.result)
    assert (plot.mapper.low, plot.mapper.high) == (1 / 50, m.result.values["growth"].max())
    assert "e-fold" not in plot.fig.title.text
    longest = sweep.run(sweep.plan("modulated", "midpoint", ["T=10:40:2", "eps=0:0.8:2"], ["growth"], values={"alpha": 2.0}))
    plot.set(longest)
    assert plot.mapper.low == 1 / 40, "a T axis: one e-fold over the longest run"


def colour_index(mapper, z, n=256):
    """The palette entry BokehJS gives z (its LogColorMapper: below low the first, above high the last)."""
    low, high = mapper.low, mapper.high
    if z <= low:
        return 0
    return min(n - 1, int(n * math.log(z / low) / math.log(high / low)))


def test_kapitza_s_map_shows_where_the_inverted_pendulum_falls_and_where_it_stays_up():
    """Kapitza's first map (growth of its first view's Gauss method over nu x a, from q0 = 3): the
    cells well below a nu = sqrt(2) w0 (the pendulum falls) are coloured a median 50 palette entries
    (of 256) above those well beyond it (it stays up) below the upper instability at a ~ 0.45; on
    the linear scale from the smallest to the largest growth (11 there) they were 3 entries apart.
    (Where the drive is weak, a = 0.03 at nu 10-20, the fallen pendulum swings regularly: its
    growth, 0.03-0.1, is a stable cell's.)"""
    s = Study()
    s.scene = "kapitza"
    m = StabilityMap(s, nx=16, ny=16)
    m.start()
    assert (m.x, m.y, m.measure) == ("nu", "a", "growth")
    plot = maps.MapPlot(False, False, lambda i, j: None)
    plot.set(m.result)
    d = plot.source.data
    colour = np.array([colour_index(plot.mapper, z) for z in d["z"]])
    nu, a = d["x"], d["y"]
    falls = (a > 0) & (a * nu < 0.8 * math.sqrt(2))
    up = (a * nu > 1.25 * math.sqrt(2)) & (a < 0.4)
    assert falls.sum() >= 10 and up.sum() >= 100
    assert np.median(colour[falls]) - np.median(colour[up]) >= 30, (np.median(colour[falls]), np.median(colour[up]))
    assert np.mean(colour[falls] > np.median(colour[up])) >= 0.8


@pytest.mark.parametrize("change, needle", [
    ({"x": "eps", "y": "eps"}, "both vary eps"),
    ({"x_start": -1.0}, "outside"),
    ({"nx": 100, "ny": 100, "x": "T", "x_start": 1e4, "x_stop": 2e4}, "steps in all"),
])
def test_bad_maps_are_a_message_and_the_last_map_stays(tongue, change, needle):
    s, m = tongue
    before = m.result
    m.param.update(**change)
    m.start()
    assert m.result is before and not m.running
    assert s.message.level == "error" and needle in s.message.text, s.message
    m.param.update(x="alpha", y="eps", x_start=0.5, x_stop=4.5, nx=9, ny=5)


def test_the_lease_bounds_the_measured_peak_and_is_given_back(monkeypatch):
    """The charged particle at small steps (runs of many chunks, 4 x 4 maps): the lease is at
    least tracemalloc's peak (numpy's arrays included) and at most 2 MB above it (the fused
    driver keeps nothing per step, so a lease sized by the steps would hold back other runs for
    nothing); it is returned when the map is done (the study keeps its own comparison's lease; it
    is opened on Structure, whose comparison computes its carried loops with it, not after it)."""
    budget = memory.MemoryBudget(cap_bytes=1 << 32)
    monkeypatch.setattr(memory, "BUDGET", budget)
    leased = []
    monkeypatch.setattr(budget, "lease", lambda n, what, lease=budget.lease: leased.append(n) or lease(n, what))
    s = Study(scene="charged", view="structure")
    m = StabilityMap(s)
    m.param.update(x="h", x_start=1e-4, x_stop=2e-4, x_log=False, nx=2, y="B0", y_start=0.05, y_stop=0.1, ny=2)
    s.T = 60.0
    held = budget.used
    tracemalloc.start()
    m.start()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert m.status.startswith("done") and budget.used == held
    print(f"stability map: lease {leased[-1] / 1e6:.0f} MB, peak {peak / 1e6:.0f} MB")
    assert peak <= leased[-1] <= peak + (2 << 20)
    assert math.ceil(60.0 / 1e-4) > wp.CHUNK


def test_the_colour_bar_uses_the_apps_compact_ticks_and_cells_have_no_gaps():
    """The colour bar read 1.000e-12 ... 0.000e+0 (Bokeh's default formatter) beside axes that
    read 1e-12; the cells' edges are drawn in their own colour (white hairlines between them)."""
    from bokeh.models import ColorBar

    from app.plotting import log_formatter, log_ticker

    plot = maps.MapPlot(False, False, lambda i, j: None)
    bar = next(r for r in plot.fig.right if isinstance(r, ColorBar))
    assert bar.formatter.code == log_formatter().code and bar.ticker.major_code == log_ticker().major_code
    glyph = plot.fig.renderers[0].glyph
    assert glyph.line_color == glyph.fill_color and glyph.line_color.transform is plot.mapper


@pytest.mark.slow
def test_a_server_configured_with_a_dask_scheduler_computes_its_maps_there(monkeypatch):
    """COSYMP_DASK_SCHEDULER names a running cluster: the map is computed there (its result says
    where) and its figures are bit-identical to the in-process map's."""
    distributed = pytest.importorskip("distributed")
    import logging


    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                                       silence_logs=logging.ERROR)
    try:
        results = {}
        for where in ("here", cluster.scheduler_address):
            if where == "here":
                monkeypatch.delenv(maps.SCHEDULER_ENV, raising=False)
            else:
                monkeypatch.setenv(maps.SCHEDULER_ENV, where)
            jobs.REMEMBERED.clear()  # computed in both places, not recalled
            m = StabilityMap(Study(scene="modulated"), nx=6, ny=4)
            m.start()
            assert m.status.startswith("done"), m.status
            results[where] = m.result
    finally:
        cluster.close()
    here, there = results["here"], results[cluster.scheduler_address]
    assert "this process" in here.where and cluster.scheduler_address in there.where
    assert there.status.tolist() == here.status.tolist()
    for k in here.plan.measures:
        assert np.array_equal(here.values[k], there.values[k], equal_nan=True), k


def test_a_map_any_page_computed_is_shown_at_once_to_the_next_that_asks(tongue):
    """Deterministic: the same plan gives the same map, so the server computes it once for a class
    (app.jobs.REMEMBERED); another plan is computed."""
    _, m = tongue
    m.start()  # computed again (each test's memory of results starts empty), and remembered
    other = StabilityMap(Study(scene="modulated"), nx=9, ny=5)
    assert other.quick(), "a remembered map is shown in the handler that asks for it"
    other.start()
    assert other.run is None, "nothing computed"
    assert other.result is m.result and other.status.startswith("computed at") and "by this server" in other.status
    other.nx = 8
    assert not other.quick()
    other.start()
    assert other.run is not None and other.status.startswith("done") and other.result.values[other.measure].shape == (8, 5)
    for n in range(2, 2 + StabilityMap.KEEP):  # the server keeps the newest KEEP maps
        other.param.update(nx=n, ny=2)
        other.start()
    kept = [key for kind, key in jobs.REMEMBERED if kind == StabilityMap.KIND]
    assert [k.shape for k in kept] == [(n, 2) for n in range(2, 2 + StabilityMap.KEEP)]


def test_the_map_view_has_its_figure_before_any_map_and_draws_a_recalled_map_ahead(tongue):
    """The heat map's figure is built with the tab (for the axis kinds it opens with) and shown when a
    map comes, so a first visit sends data, not a figure; built ahead, the tab draws a map this server
    computed for the same inputs, and computes none (a new map waits for the visit)."""
    _, m = tongue
    m.start()  # remembered by the server (each test's memory starts empty)
    fresh = StabilityMap(Study(scene="modulated"), nx=9, ny=5)
    view = maps.StabilityMapView(fresh.study, fresh)
    layout = view.__panel__()
    [plot] = view.plots.values()
    assert plot.box in view.box.objects and not plot.box.visible and view.hint.visible
    for step in view.ahead():
        step()
    assert fresh.result is m.result and fresh.run is None, "recalled, not computed"
    assert plot.box.visible and not view.hint.visible and len(plot.source.data["z"]) == 45
    assert view.box.objects == [view.hint, plot.box] and layout is view.__panel__()
    other = StabilityMap(Study(scene="modulated"), nx=7, ny=5)
    ahead = maps.StabilityMapView(other.study, other)
    ahead.__panel__()
    for step in ahead.ahead():
        step()
    assert other.result is None and other.run is None and not other.running, "a new map waits for the tab"
    other.x_log = not other.x_log  # axes of another kind: a figure of its own, shown alone
    other.start()
    ahead.update()
    assert len(ahead.plots) == 2 and [p.box.visible for p in ahead.plots.values()] == [False, True]
