"""The app's work-precision and long-horizon measurements (app.features.workprecision) and their
plots, without a server."""
import asyncio
import dataclasses
import html
import itertools
import math
import threading
import time
from types import SimpleNamespace

import numpy as np
import panel as pn
import param
import pytest

from app import memory
from app.features import workprecision as views
from app.features.workprecision import MEASURE_BYTES, LongHorizons, WorkPrecision
from app.study import Study
from cosymp import workprecision as wp


@pytest.fixture(scope="module")
def measured():
    """A small measurement on the decaying scene (rk4 and the lifted θ-method at θ = 0.3, scipy's
    solvers), with the progress it published."""
    s = Study(scene="decaying", theta=0.3)
    m = WorkPrecision(s, methods=["rk4", "theta"])
    seen = []
    m.param.watch(lambda e: seen.append((e.new, m.label)), "progress")
    m.start()
    return s, m, seen


def test_a_measurement_gives_rows_for_every_solver_and_its_progress_reaches_one(measured):
    _, m, seen = measured
    assert m.status.startswith("done") and not m.running and m.progress == 1.0
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and len(set(fractions)) >= 4
    assert any(label.startswith("theta(0.3) h =") for _, label in seen)
    solvers = {r["solver"] for r in m.rows}
    assert solvers == {"rk4", "theta(0.3)", "scipy-RK45", "scipy-DOP853", "scipy-LSODA"}
    assert "decaying" in m.setting and "T = 10" in m.setting and "θ = 0.3" in m.setting
    rk4 = [r for r in m.rows if r["solver"] == "rk4" and r["error"] > 1e-12]
    slope = np.polyfit(np.log([r["h"] for r in rk4]), np.log([r["error"] for r in rk4]), 1)[0]
    assert 3.5 < slope < 4.5
    theta = [r for r in m.rows if r["solver"] == "theta(0.3)"]
    assert all(r["det_max_dev"] < 1e-12 for r in theta)
    peers = [r for r in m.rows if r["kind"] == "scipy"]
    assert all(math.isnan(r["det_max_dev"]) and r["rtol"] > 0 for r in peers)


def shown_items(plot):
    return [item for item in plot.curves.legend.items if item.visible]


def test_the_plots_draw_every_finite_point_and_the_targets_table_names_the_ratios(measured):
    _, m, _ = measured
    plot = views.WorkPrecisionPlot("error", "", lambda row: None)
    plot.set(m.rows)
    curves = plot.curves.source.data
    items = shown_items(plot)
    assert [item.index for item in items] == list(range(len(curves["xs"]))), "the legend lists exactly the lines"
    rows = plot.curves.legend.items
    plot.set([r for r in m.rows if r["solver"] == "rk4"])
    assert plot.curves.legend.items is rows and [i.label.value for i in shown_items(plot)] == ["rk4"], \
        "the legend's rows are kept and changed in place (one dropped made Bokeh walk all of the page's models)"
    plot.set(m.rows)
    assert all(item.renderers == [plot.curves.lines, plot.curves.marks] for item in items)
    keys = plot.curves.keys.data
    assert np.isnan(keys["x"]).all() and len(keys["x"]) == views.Curves.KEYS > len(items), \
        "a legend marker per line, drawn nowhere, and more than any plot's lines from the start"
    assert len(views.WorkPrecisionPlot("error", "", None).curves.keys.data["marker"]) == views.Curves.KEYS
    assert dict(zip([item.label.value for item in items], keys["marker"])) == {
        "rk4": "triangle", "theta(0.3)": "circle", "scipy-RK45": "square", "scipy-DOP853": "square",
        "scipy-LSODA": "square"}
    assert plot.curves.lines in plot.fig.renderers, "the lines are the figure's own, built with it"
    styles = {item.label.value: curves["dash"][item.index] for item in items}
    assert styles["rk4"] == "solid" and styles["scipy-DOP853"] == "dashed"
    points = plot.points.data
    assert len(points["x"]) == len(views.wp_points(m.rows, "error")) == sum(len(x) for x in curves["xs"])
    assert {(r, m) for r, m in zip(points["solver"], points["marker"])} == {
        ("rk4", "triangle"), ("theta(0.3)", "circle"), ("scipy-RK45", "square"), ("scipy-DOP853", "square"),
        ("scipy-LSODA", "square")}, "each point in its family's marker"
    assert set(points) == set(views.POINT_COLUMNS) == set(views.WorkPrecisionPlot("error", "", None).points.data), \
        "the glyph's columns exist before the first data (else 'nonexistent field' console warnings)"
    n_renderers = len(plot.fig.renderers)
    plot.set(m.rows[:3])
    assert len(plot.fig.renderers) == n_renderers, "new data adds no renderer to a figure on the page"
    table = views.targets_table(m.rows)
    assert "scipy DOP853 / fastest cosymp" in table["time to reach"] and "best symplectic / rk4" in table["time to reach"]
    cost = wp.targets(m.rows)["cost"][1e-6]["rk4"]
    assert f"{cost:.2e} s" in table["error 1e-06"]
    assert views.reference_html(m.rows) == "<p class='doc'>Reference: exact flow.</p>"
    rows = [{"reference": "rk8 at h/4", "reference_uncertainty": u} for u in (2e-13, math.inf, 5e-12)]
    assert views.reference_html(rows) == ("<p class='doc'>Reference: rk8 at h/4 (relative uncertainty up to 5.0e-12: "
                                          "errors at most as large are not resolved).</p>"), \
        "an error equal to its reference's uncertainty is not resolved (reference.is_resolved), not only smaller ones"


def test_failed_runs_are_not_plotted_but_listed():
    row = dict.fromkeys(wp.ROW_FIELDS, math.nan)
    good = {**row, "solver": "rk4", "kind": "cosymp", "h": 0.1, "wall_s": 1e-4, "error": 1e-6, "steps": 100,
            "status": "ok"}
    bad = {**row, "solver": "gauss4", "kind": "cosymp", "h": 1.0, "steps": 10, "status": "Newton did not converge"}
    assert views.wp_points([good, bad], "error") == [good]
    assert "1 run failed" in views.failed_html([good, bad]) and "Newton" in views.failed_html([good, bad])


def test_tapping_a_cosymp_point_opens_it_in_the_orbits_view(measured):
    s, m, _ = measured
    s.param.update(method="midpoint", h=0.05, T=3.0, view="workprecision")  # a scene change drops the rows
    plot = views.WorkPrecisionPlot("error", "", m.open_row)
    plot.set(m.rows)
    points = views.wp_points(m.rows, "error")
    k = next(i for i, r in enumerate(points) if r["solver"] == "theta(0.3)" and r["steps"] > 20)
    plot.points.selected.indices = [k]
    row = points[k]
    assert (s.scene, s.method, s.theta, s.view) == ("decaying", "theta", 0.3, "compare")
    assert (s.h, s.T) == (row["h"], 10.0)
    run = s.results.entries[0].comparison.run
    assert len(run.t) - 1 == row["steps"] and run.t[-1] == pytest.approx(10.0)


def test_tapping_a_peer_point_says_it_cannot_be_opened(measured):
    s, m, _ = measured
    before = (s.scene, s.method, s.h, s.view)
    m.open_row(next(r for r in m.rows if r["kind"] == "scipy"))
    assert (s.scene, s.method, s.h, s.view) == before
    assert s.message.level == "info" and "solve_ivp" in s.message.text


def test_cancel_stops_a_measurement_within_a_second():
    s = Study(scene="damped")
    m = WorkPrecision(s)
    asked = []

    def cancel(event):
        if event.new > 0 and not asked:
            asked.append(time.perf_counter())
            m.cancel()

    m.param.watch(cancel, "progress")
    m.start()
    assert m.status.startswith("cancelled") and not m.running
    assert not m.rows or m.setting.endswith("(cancelled: the runs before it)"), "the runs so far stay, said so"
    assert m.join(5)
    assert time.perf_counter() - asked[0] < 1.5


def test_a_cancelled_measurement_frees_its_thread_its_lease_and_its_memory(monkeypatch):
    """Measured on the second of two cancelled measurements (the first loads compiled code and
    caches for good): the worker thread ends, the lease is given back, and the Python heap
    (numpy's arrays included, tracemalloc) returns to within 1 MB of what it was at the start."""
    import threading
    import tracemalloc

    budget = memory.MemoryBudget(cap_bytes=1 << 30)
    monkeypatch.setattr(memory, "BUDGET", budget)
    s = Study(scene="charged")
    for job in (s, s.late, s.carry):  # a thread ends after its results came (the loops' did during the count)
        if job.run is not None and job.run.thread.ident is not None:
            job.run.thread.join(5)
    held = budget.used
    threads = threading.active_count()
    tracemalloc.start()
    figures = []
    for _ in range(2):
        m = WorkPrecision(s)
        before = tracemalloc.get_traced_memory()[0]
        during = []

        def cancel(event, m=m, during=during, before=before):
            if event.new > 0.2 and not during:
                during.append((tracemalloc.get_traced_memory()[0] - before, budget.used - held))
                m.cancel()

        m.param.watch(cancel, "progress")
        m.start()
        assert m.join(10)
        m.run.thread.join(5)
        figures.append((during[0], tracemalloc.get_traced_memory()[0] - before))
        assert m.status.startswith("cancelled") and not m.run.thread.is_alive()
        assert during[0][1] == MEASURE_BYTES and budget.used == held
        assert threading.active_count() == threads
    tracemalloc.stop()
    (used, _), after = figures[1]
    print(f"cancelled measurement: heap +{used / 1e6:.2f} MB while running, +{after / 1e6:.3f} MB after")
    assert used > 0 and after < 1 << 20, figures



@pytest.mark.parametrize("change, needle", [
    ({"methods": []}, "choose at least one method"),
    ({"T": 1.5e5}, "shorten T"),
])
def test_bad_input_is_a_message_and_nothing_starts(change, needle):
    s = Study(scene="decaying")
    m = WorkPrecision(s)
    m.param.update(**change)
    m.start()
    assert not m.running and m.rows == [] and m.status == ""
    assert s.message.level == "error" and needle in s.message.text


def test_an_unexpected_failure_is_a_message_and_the_session_goes_on(monkeypatch):
    s = Study(scene="decaying")
    m = WorkPrecision(s, methods=["rk4"], peers=False)

    def broken(*args, **kwargs):
        return 1 / 0

    monkeypatch.setattr(wp, "measure", broken)
    m.start()
    assert m.status.startswith("failed") and "ZeroDivisionError" in m.status and not m.running
    assert s.message.level == "error" and "work–precision failed" in s.message.text
    monkeypatch.undo()
    m.start()
    assert m.status.startswith("done") and m.rows


def test_the_methods_and_defaults_follow_the_scene():
    s = Study(scene="damped")
    m, lh = WorkPrecision(s), LongHorizons(s)
    assert "boris" not in m.param.methods.objects and "exact" not in m.param.methods.objects
    assert (lh.h, lh.T_max) == (0.1, 1e5)
    s.scene = "charged"
    assert "boris" in m.param.methods.objects and "boris" in m.methods
    assert (lh.h, lh.T_max) == (0.001, 1e3)


def test_the_methods_widgets_follow_the_scene_when_their_tab_is_shown_and_write_the_choice_back(monkeypatch):
    """Hidden, a scene change leaves the tab's two multi-choices as they were (each change of one
    costs the browser a render of it); shown again, they hold the new scene's methods; a choice made
    in one is the measurement's. (The measurement a shown tab starts is left out: about 20 s of
    both cores per scene here, and tested above.)"""
    s = Study(scene="damped")
    m, lh = WorkPrecision(s), LongHorizons(s)
    monkeypatch.setattr(m, "request", lambda: None)
    view = views.WorkPrecisionView(s, SimpleNamespace(measure=m, long=lh))
    wp_choice, long_choice = view.__panel__().select(pn.widgets.MultiChoice)
    before = [(list(w.options), list(w.value)) for w in (wp_choice, long_choice)]
    assert before == [(m.param.methods.objects, m.methods), (lh.param.methods.objects, lh.methods)]
    s.scene = "charged"
    assert "boris" in m.methods and "boris" in m.param.methods.objects
    assert [(list(w.options), list(w.value)) for w in (wp_choice, long_choice)] == before, "hidden: not sent"
    s.view = "workprecision"
    view.shown()
    for w, job in ((wp_choice, m), (long_choice, lh)):
        assert list(w.options) == job.param.methods.objects and "boris" in w.options and list(w.value) == job.methods
    wp_choice.value = ["boris", "rk4"]
    assert m.methods == ["boris", "rk4"]
    s.scene = "kapitza"
    assert "boris" not in wp_choice.options and list(wp_choice.value) == m.methods, "shown: follows at once"


def test_long_horizons_show_linear_error_growth_and_the_fitted_exponents():
    s = Study(scene="damped", values={"gamma": 0.0002})
    lh = LongHorizons(s, methods=["rk4", "gauss4"], T_max=1e4)
    lh.start()
    assert lh.status.startswith("done") and lh.progress == 1.0
    assert sorted({r["T"] for r in lh.rows}) == [T for T in wp.DRIFT_HORIZONS if T <= 1e4]
    for solver in ("rk4", "gauss4"):
        assert 0.8 < wp.growth_exponent(lh.rows, solver) < 1.2
    table = views.growth_table(lh.rows)
    assert f"{wp.growth_exponent(lh.rows, 'rk4'):.2f}" in table["error ∝ T^"]
    plot = views.DriftPlot("error", "")
    plot.set(lh.rows)
    labels = [item.label.value for item in shown_items(plot)]
    assert f"rk4: slope {wp.growth_exponent(lh.rows, 'rk4'):.2f}" in labels
    T1, y1 = (plot.guides[1].data[k] for k in ("x", "y"))
    assert y1[1] / y1[0] == pytest.approx(T1[1] / T1[0])
    T2, y2 = (plot.guides[2].data[k] for k in ("x", "y"))
    assert y2[1] / y2[0] == pytest.approx((T2[1] / T2[0]) ** 2)


def test_long_horizons_past_the_reference_show_the_horizons_before_it():
    """The damped oscillator at γ = 0.2 leaves floating point at t = 7098: the page says, beside the
    rows, where the horizons stop, why, and how to reach the one asked for."""
    s = Study(scene="damped")
    lh = LongHorizons(s, T_max=1e4)
    lh.start()
    top = max(r["T"] for r in lh.rows)
    assert lh.status.startswith("done") and top == 5000
    assert s.message.level == "warning" and f"up to T = {top:g} only" in s.message.text
    assert f"T up to {top:g}" in lh.setting
    assert lh.capped.startswith("Shown up to T = 5000, not to the 10000 asked for: the exact flow leaves floating "
                                "point at t ≈ 7")
    assert "T = 10000 needs parameters with a growth rate 1.5× smaller" in lh.capped
    empty = views.WorkPrecisionView(s, SimpleNamespace(measure=WorkPrecision(s, methods=["rk4"]),
                                                       long=LongHorizons(s)))
    empty.__panel__()
    empty.update()
    assert empty.drift_plots is None and not empty.long_box.objects, "no long horizons: no figures built for them"
    view = views.WorkPrecisionView(s, SimpleNamespace(measure=WorkPrecision(s, methods=["rk4"]), long=lh))
    view.__panel__()
    view.update()
    assert view.long_box.visible and len(view.long_box.objects) == 5
    assert all(len(p.fig.renderers) for p in view.drift_plots) and view.growth.object is not None
    assert html.unescape(view.long_capped.object) == f"<p class='caveat'>{lh.capped}</p>"
    s.scene = "modulated"
    view.update()
    assert lh.capped == "" and view.long_capped.object == ""


def test_growth_at_round_off_is_said_in_the_legend_and_the_table():
    eps = np.finfo(float).eps
    rows = [{"solver": solver, "T": T, "steps": 10 * T, "order": 4, "preserves": "symplectic", "error": 1e-3 * T,
             "reference_uncertainty": 0.0, "H_ext_max_abs": eps * math.sqrt(10 * T) * size, "H_scale": 1.0}
            for solver, size in (("gauss6", 3.0), ("rk4", 1e6)) for T in (100.0, 1e3, 1e4)]
    plot = views.DriftPlot("H_ext_max_abs", "")
    plot.set(rows)
    assert [item.label.value for item in shown_items(plot)] == ["gauss6: at round-off", "rk4: slope 0.50"]
    assert views.growth_table(rows)["max |H~| ∝ T^"] == ["round-off", "0.50"]


@pytest.mark.parametrize("h, needle", [(0.0, "h > 0"), (1e-4, "beyond this view's limit")])
def test_long_horizons_refuse_a_bad_step(h, needle):
    s = Study(scene="damped")
    lh = LongHorizons(s, h=h, T_max=1e4)
    lh.start()
    assert not lh.running and lh.rows == [] and needle in s.message.text


def test_long_horizons_can_be_cancelled():
    s = Study(scene="modulated")
    lh = LongHorizons(s, T_max=1e5)
    asked = []

    def cancel(event):
        if "to T =" in event.new and not asked:
            asked.append(time.perf_counter())
            lh.cancel()

    lh.param.watch(cancel, "label")
    lh.start()
    assert lh.status.startswith("cancelled") and lh.rows == [] and not lh.running
    # Stopped at its next progress report: 0.1-0.3 s alone, 0.58 s once on a CI machine running other
    # tests; the whole measurement takes 1.6 s alone (its status and empty rows say it did not end).
    assert time.perf_counter() - asked[0] < 1.0
    assert lh.join(30)


def test_another_page_opening_the_tab_shows_this_servers_measurement_of_its_inputs_at_once(measured):
    """A measurement is remembered by the server (views.MEASURED): a page whose inputs match shows it
    without measuring, says when it was measured, and Start measures again; other inputs measure."""
    _, m, _ = measured
    same = WorkPrecision(Study(scene="decaying", theta=0.3), methods=["rk4", "theta"])
    assert same.recall() and same.rows == m.rows and same.run is None and not same.running
    assert same.status.startswith("measured at ") and "Start measures again" in same.status
    assert same.setting == m.setting
    other = WorkPrecision(Study(scene="decaying", theta=0.3), methods=["rk4"])
    assert not other.recall() and not other.rows
    assert not WorkPrecision(Study(scene="decaying", theta=0.4), methods=["rk4", "theta"]).recall()


def test_a_measurement_hands_out_its_rows_so_far_after_each_run():
    """cosymp.workprecision.measure(partial=...): the rows so far after every run, each list the
    one before and one more row, the last one the rows returned (the app draws them as they come)."""
    seen = []
    rows = wp.measure("decaying", ["rk4"], T=2.0, peers=True, rtols=(1e-3, 1e-6), max_steps=64, budget=0.0,
                      partial=seen.append)
    assert seen[-1] == rows and len(seen) == len(rows) >= 4
    assert all(a == b[:-1] for a, b in itertools.pairwise(seen))


def test_a_scene_change_drops_the_rows_of_the_old_scene():
    s = Study(scene="decaying")
    m = WorkPrecision(s, methods=["rk4"], peers=False, T=2.0)
    m.start()
    assert m.rows and m.setting.startswith("decaying")
    s.scene = "damped"
    assert not m.rows and not m.setting and m.job is None


def test_the_tab_says_when_the_sidebar_or_its_controls_ask_for_another_measurement_than_the_one_shown(monkeypatch):
    """A measurement starts on its Start button, not on each change: after the sidebar's values or the
    horizon changed, the plots kept the old rows while only the status line named them (the Long run
    and the Stability map said so). Now the tab says what is asked for, until it is measured."""
    s = Study(scene="decaying")
    both = views.Measurements(s)
    m = both.measure
    m.param.update(methods=["rk4"], peers=False, T=2.0)
    m.start()
    view = views.WorkPrecisionView(s, both)
    s.view = view.NAME
    view.__panel__()
    view.shown()
    since = view.since[m]
    assert m.rows and m.since() == "" and since.object == ""
    s.theta = 0.3
    assert m.since() == "", "rk4 takes no θ: its rows are what is asked for"
    m.T = 3.0
    assert "Computed before the latest changes" in since.object and "T = 3" in since.object
    assert "press Start work–precision" in since.object and view.since[both.long].object == ""
    # Start pressed: `running` is set at once, the run begins later in the server's loop (held here), so
    # the notice was read against the last run's inputs ("cancel this one" of the very measurement asked
    # for), or raised AttributeError where the rows shown were recalled (no run yet)
    held, during = [], []
    monkeypatch.setattr(param.parameterized, "async_executor", held.append)
    m.param.watch(lambda e: during.append((e.new, m.since(), since.object)), "status")
    m.start()
    assert m.running and held and m.since() == "" and since.object == ""
    asyncio.run(held[0]())
    assert during and during[0][0].startswith("running") and {d[1:] for d in during} == {("", "")}
    assert not m.running and m.job.T == 3.0 and m.since() == ""
    m.run = None  # rows recalled from the server's memory, then Start
    m.T = 2.0
    m.start()
    assert m.running and m.since() == ""
    m.running, m.run = True, SimpleNamespace(inputs=dataclasses.replace(m._inputs(), T=4.0), cancelled=False,
                                            finished=threading.Event())
    assert "cancel this one, then press Start work–precision" in m.since()
    m.running, m.run = False, None
    m.T = 3.0
    assert since.object == ""
    s.values = {"lam": 0.5}
    assert "lam = 0.5" in m.since()
    s.view = "compare"
    s.values = {}
    assert since.object != "", "a hidden tab's text follows when it is shown"
    s.view = view.NAME
    view.shown()
    assert since.object == ""
