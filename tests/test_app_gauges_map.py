"""The Gauges tab away from the charged particle, and what the Stability map says it was computed
with: without a server, and in the browser."""
import json
import math
import re
import shlex
import shutil
from urllib.parse import parse_qsl, urlparse

import numpy as np
import pytest
from playwright.sync_api import expect
from served import CHROMIUM, START_TIMEOUT_S, query

from app.features import gauges
from app.features import stabilitymap as maps
from app.features.stabilitymap import StabilityMap, StabilityMapView
from app.presets import PRESETS, URL_NAMES, parse_items
from app.study import Study
from cosymp import cli, sweep
from cosymp.methods import METHODS
from cosymp.scenes import SCENES, first


def in_browser(test):
    """A browser test: slow, and skipped without Chromium."""
    for mark in (pytest.mark.slow, pytest.mark.skipif(not shutil.which(CHROMIUM), reason=f"no Chromium at {CHROMIUM}"),
                 pytest.mark.timeout(START_TIMEOUT_S + 120)):
        test = mark(test)
    return test


GAUGE_FIGURE = next(p for p in PRESETS if p.state["view"] == "gauges")


def test_the_gauge_figure_is_the_paper_figure_link_that_opens_the_gauges_tab():
    assert GAUGE_FIGURE.name.startswith("Fig. gauge") and gauges.gauge_figure().name == GAUGE_FIGURE.name


@pytest.mark.parametrize("scene", [s for s in SCENES if not SCENES[s].has_gauges])
def test_the_gauges_tab_of_another_scene_opens_the_paper_s_gauge_figure(scene):
    """The study ends in the state of the sidebar's link to the figure, whatever it held before: here
    already at the figure's T and without scene values, which alone would not be changes."""
    s = Study(scene=scene, T=GAUGE_FIGURE.state["T"], view="gauges")
    assert s.values == {} and s.T == GAUGE_FIGURE.state["T"]
    gauges.open_gauge_figure(s)
    assert {k: getattr(s, k) for k in GAUGE_FIGURE.state} == GAUGE_FIGURE.state
    assert (s.results.scene, s.results.h, s.results.T) == ("charged", 0.001, 20.0)


@pytest.mark.parametrize("scene", list(SCENES))
def test_the_map_says_every_value_its_cells_share_as_they_run_them(scene):
    """Each scene's first map, at a sidebar h and T of its first view's halves: the status names the
    sidebar's h and T where they are not varied, no value of a varied name (the plan's h is the
    scene's default where h is varied), and every other scene parameter with its value."""
    s = Study()
    s.scene = scene
    case = first(SCENES[scene])
    s.param.update(h=case.h / 2, T=case.T / 2)
    m = StabilityMap(s, nx=2, ny=2)
    plan = m.planned()
    text = m._describe(plan)
    varied = {a.name for a in plan.axes}
    used = {"h": s.h, "T": s.T, **s.scene_obj.values(s.values)}
    if METHODS[s.method].takes_theta:
        used["theta"] = s.theta
    for name, value in used.items():
        if name in varied:
            assert f" {name} = " not in text, (name, text)
        else:
            assert f" {name} = {maps.value_text(value)}," in text + ",", (name, text)
    assert "h" not in varied or f"h = {SCENES[scene].h:g}" not in text


@pytest.mark.parametrize("scene", list(SCENES))
def test_the_map_s_command_line_runs_the_map_shown(scene):
    """`cosymp sweep` given the shown command plans the same grid with the same shared values (it
    refused a varied h also given as --h: 'h' is both given a fixed value and varied)."""
    s = Study()
    s.scene = scene
    m = StabilityMap(s, nx=2, ny=2)
    plan = m.planned()
    args = cli.parser().parse_args(shlex.split(maps.map_command(plan))[1:])
    again = sweep.plan(args.scene, args.method, args.vary, args.measure, dict(args.set), args.theta, args.h, args.T)
    assert (again.axes, again.measures) == (plan.axes, plan.measures)
    assert maps.shared_values(again) == maps.shared_values(plan)


def test_the_map_s_command_line_quotes_a_beta_expression_for_the_shell():
    """An expression of t as the charged particle's beta: the command split as a shell splits it
    gives the same value ('--set beta=0.05*(1 + tanh(t))' was three words and a syntax error)."""
    s = Study()
    s.scene = "charged"
    s.inputs.beta = "0.05*(1 + tanh(t))"
    plan = StabilityMap(s, nx=2, ny=2).planned()
    args = cli.parser().parse_args(shlex.split(maps.map_command(plan))[1:])
    assert dict(args.set)["beta"] == "0.05*(1 + tanh(t))"


def test_a_map_computed_before_a_change_of_the_sidebar_says_so_until_computed_again():
    """The map is computed on Compute map, not on every change of the sidebar: after one, the shown
    map's status names the values it was computed with, and a line says what changed since; its
    cells are not sent again for a change of the inputs alone."""
    s = Study(scene="modulated")
    m = StabilityMap(s, nx=3, ny=2)
    view = StabilityMapView(s, m)
    s.view = "map"
    view.__panel__()
    view.shown()
    shown, h = m.result, s.h
    plot = view._drawn[0]
    cells = plot.source.data
    assert shown is not None and view.since.object == "" and f"h = {h:g}," in m.setting
    s.h = h / 2
    assert m.result is shown and f"h = {h:g}," in m.setting
    assert f"now h = {h / 2:g})" in view.since.object and plot.source.data is cells
    m.start()
    assert m.result is not shown and view.since.object == "" and f"h = {h / 2:g}," in m.setting
    m.nx = 4
    assert "of its axes or measure" in view.since.object


@in_browser
def test_in_the_browser_the_gauges_tab_opens_the_paper_s_gauge_figure(page):
    """From Kapitza's pendulum at the figure's T: the button lands on the figure's state (as its link
    in Paper figures has it) with the Gauges tab shown and its plots drawn."""
    page.open(query(scene="kapitza", T=GAUGE_FIGURE.state["T"], view="gauges"))
    page.page.locator("button:visible", has_text="Open the").click()
    expect(page.page.get_by_label("Step h")).to_have_value(f"{GAUGE_FIGURE.state['h']:g}")
    expect(page.page.locator(".bk-tab.bk-active")).to_have_text("Gauges")
    label = METHODS[GAUGE_FIGURE.state["method"]].label(None)
    expect(page.page.locator("p", has_text="Method:").first).to_contain_text(label)
    page.page.wait_for_url(lambda url: "charged" in url and "symplectic-euler" in url)
    state, bad = parse_items(dict(parse_qsl(urlparse(page.page.url).query)), URL_NAMES)
    assert not bad and {k: state[k] for k in GAUGE_FIGURE.state} == GAUGE_FIGURE.state
    page.page.wait_for_timeout(1500)
    page.shot("gauges-away-opens-the-figure")
    page.check()


CELL_COLOURS_JS = """(title) => {
    // The palette entry BokehJS's own colour mapper gives each cell of the heat map with this title.
    for (const doc of Bokeh.documents) for (const m of doc.all_models) {
        if (!["Figure", "Plot"].includes(m.type) || !m.title || !m.title.text.startsWith(title)) continue;
        const r = m.renderers.find(r => r.glyph && r.glyph.fill_color && r.glyph.fill_color.transform);
        const mapper = r.glyph.fill_color.transform, src = r.data_source;
        const data = src.data instanceof Map ? Object.fromEntries(src.data) : src.data;
        if (!data.z || !data.z.length) return null;
        const palette = mapper.palette.map(c => c.toLowerCase());
        const entry = Array.from(mapper.v_compute(data.z)).map(c => palette.indexOf("#" + (c >>> 8).toString(16).padStart(6, "0")));
        return {x: Array.from(data.x), y: Array.from(data.y), entry, low: mapper.low, n: palette.length};
    }
    return null;
}"""


@in_browser
def test_in_the_browser_kapitza_s_map_colours_the_falling_pendulum_apart_from_the_held_one(page):
    """Kapitza's first view, then its Stability map (30 x 30, as it opens): as BokehJS colours them,
    the cells well below a nu = sqrt(2) w0 (the pendulum falls) are a median 38 palette entries (of
    256) above those well beyond it (it stays up; below the upper instability); on the linear scale
    from the smallest to the largest growth they were 3 entries apart."""
    case = first(SCENES["kapitza"])
    page.open(query(scene="kapitza", method=case.method, vs=case.other, h=case.h, T=case.T, view="map"))
    page.page.locator("b.wpstatus").filter(has_text=re.compile("done in|by this server")).wait_for(timeout=120_000)
    title = f"{maps.MEASURE_TITLES['growth']} of {case.method} on kapitza"
    page.page.wait_for_function(f"() => ({CELL_COLOURS_JS})({json.dumps(title)})", timeout=60_000)
    cells = page.page.evaluate(CELL_COLOURS_JS, title)
    entry, nu, a = (np.array(cells[k]) for k in ("entry", "x", "y"))
    assert len(entry) == 900 and entry.min() >= 0 and cells["low"] == 1 / case.T
    falls = (a > 0) & (a * nu < 0.8 * math.sqrt(2))
    up = (a * nu > 1.25 * math.sqrt(2)) & (a < 0.4)
    assert np.median(entry[falls]) - np.median(entry[up]) >= 30, (np.median(entry[falls]), np.median(entry[up]))
    page.shot("kapitza-map")
    page.check()
