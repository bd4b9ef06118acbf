"""The app end to end: `panel serve app` on a free 127.0.0.1 port, driven by headless Chromium.

Every page load records every request URL (none may leave 127.0.0.1) and every console error
(there must be none), and saves a screenshot to tests/artifacts/.
"""
import json
import math
import re
import shutil
import time
from urllib.parse import parse_qs, urlparse

import numpy as np
import pytest
from playwright.sync_api import expect
from served import ARTIFACTS, CHROMIUM, SERVER_LOG, START_TIMEOUT_S, TABLE_JS, TABLE_ROW, WAIT_MS, query

from app.features.stabilitymap import MEASURE_TITLES, significant
from app.page import SPARE_READY
from cosymp.scenes import SCENES, first, lead

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not shutil.which(CHROMIUM), reason=f"no Chromium at {CHROMIUM} (apt-get install it)"),
    pytest.mark.timeout(START_TIMEOUT_S + 120),
]


def test_opens_on_the_first_view_and_a_slider_updates_the_plots(page):
    page.open()
    page.page.wait_for_selector(TABLE_ROW)
    page.shot("01-default-page")
    assert page.page.locator("h2:visible").first.inner_text() == SCENES["modulated"].title
    _, lead_case = lead()
    steps = f"{round(lead_case.T / lead_case.h):,}"
    assert ["steps", steps, steps] in page.numbers()
    expect(page.page.locator("p.verdict")).to_contain_text("rk4 drifts, midpoint does not")
    assert page.page.evaluate("[window.cosymp_bokeh_reads, window.cosymp_bokeh_built, window.cosymp_bokeh_layouts, "
                              "window.cosymp_bokeh_sends]") == [True] * 4, \
        "app/static/bokeh_reads.js, bokeh_layouts.js or bokeh_sends.js did not apply"
    page.page.wait_for_function("() => [...document.fonts].some((f) => f.family.replaceAll('\"', '') === "
                                "'cosymp-KaTeX_Main' && f.status === 'loaded')", timeout=10_000)
    assert not page.page.evaluate("[...document.fonts].filter((f) => f.status === 'error').map((f) => f.family)")
    page.check()
    page.open(query(scene="damped"))
    page.page.wait_for_selector(TABLE_ROW)
    assert "Damped oscillator" in page.page.locator("h2:visible").first.inner_text()
    assert ["steps", "500", "500"] in page.numbers()
    before_numbers, before_data = page.numbers(), page.plotted()
    box = page.page.locator(".noUi-handle[aria-valuenow='0.2']").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.page.mouse.move(x, y)
    page.page.mouse.down()
    page.page.mouse.move(x + 60, y, steps=6)
    page.page.mouse.up()
    page.wait_for_numbers_change(before_numbers)
    page.page.wait_for_timeout(1000)
    assert page.plotted() != before_data
    assert "gamma" in page.page.url
    page.shot("02-after-gamma-slider")
    page.check()


def test_a_page_without_settings_gets_a_session_built_before_it_was_asked_for(page):
    """app/page.Spares: once a page without settings has loaded and the server has been idle, a
    session of the first view is built, with its tabs' layouts and the results the server remembers
    (the server's log says so); the next page without settings
    gets it, and works as any page (the first view drawn, its URL written, a scene change, a tab
    whose layout the spare built while it waited); a link with settings gets a session of its own,
    built with them. (Twice at first: the server's very first page is asked for before the app has
    adjusted Panel, and asks for no spare.)"""
    log = SERVER_LOG
    built = re.compile(r"cosymp: spare session (\S+) built")
    page.open()
    page.open()
    deadline = time.monotonic() + 60
    while True:
        spares = built.findall(log.read_text())
        handed = set(re.findall(r"cosymp: a page got spare session (\S+)", log.read_text()))
        waiting = [s for s in spares if s not in handed]
        if waiting and SPARE_READY % waiting[-1] in log.read_text():
            break
        assert time.monotonic() < deadline, "no spare session was built and made ready within 60 s"
        page.page.wait_for_timeout(250)
    page.open()
    assert f"cosymp: a page got spare session {waiting[-1]}" in log.read_text()
    page.page.wait_for_selector(TABLE_ROW)
    assert page.page.locator("h2:visible").first.inner_text() == SCENES["modulated"].title
    page.page.wait_for_function("() => window.location.search.includes('scene=modulated')")
    before = page.numbers()
    page.page.locator("select").first.select_option(label=SCENES["damped"].title)
    page.wait_for_numbers_change(before)
    expect(page.page.locator("h2:visible").first).to_contain_text("Damped oscillator")
    page.page.locator(".bk-tab", has_text="Theta lesson").click()
    page.page.get_by_text("theta-naive").first.wait_for()
    page.check()
    count = log.read_text().count("cosymp: a page got spare session")
    page.open(query(scene="charged"))
    page.page.wait_for_selector(TABLE_ROW)
    assert SCENES["charged"].title in page.page.locator("h2:visible").first.inner_text()
    assert log.read_text().count("cosymp: a page got spare session") == count
    page.check()


def test_switching_scenes_rebuilds_controls_and_plots(page):
    page.open(query(scene="damped"))
    page.page.locator("select").first.select_option(label=SCENES["charged"].title)
    expect(page.page.locator("h2:visible").first).to_contain_text("Charged particle")
    opened = first(SCENES["charged"])  # the menu opens the scene's first view
    page.page.wait_for_function(f"() => JSON.stringify(({TABLE_JS})()).includes('{round(opened.T / opened.h):,}')")
    assert page.page.get_by_text("beta(t): 'paper', 'constant' or an expression of t").count() == 1
    page.page.wait_for_url(lambda url: "scene=charged" in url)
    page.page.wait_for_timeout(1000)
    page.shot("03-charged-compare")
    page.check()


def test_every_control_and_tab_keeps_every_request_local_and_the_console_clean(page):
    """Each scene; in it every parameter's slider moved by a key press and its box typed into, the
    methods and the comparison changed, h typed; then every tab visited twice, on a page that
    records every request (only 127.0.0.1) and every console error (none)."""
    from app.features import FEATURES

    page.open()
    for scene in SCENES.values():
        page.page.locator("select").first.select_option(label=scene.title)
        expect(page.page.locator("h2:visible").first).to_contain_text(scene.title.split(" (")[0][:20])
        sliders = page.page.locator("#sidebar .noUi-handle:visible")
        numeric = 0
        for p in scene.params:
            if p.choices:
                page.page.get_by_label(p.name).select_option(p.choices[-1])
            elif isinstance(p.default, str):
                box = page.page.locator("input[placeholder*='tanh(t)']")
                box.fill("0.05*(1 + tanh(t))")
                box.press("Enter")
            else:
                handle = sliders.nth(numeric)
                handle.focus()
                handle.press("ArrowRight")
                numeric += 1
            page.page.wait_for_timeout(150)
        assert sliders.count() == numeric, scene.name
        for label in ("Method", "Compared with"):
            page.page.get_by_label(label).select_option(label="Gauss-Legendre 4")
            page.page.wait_for_timeout(150)
        h = page.page.get_by_label("Step h")
        h.fill(f"{scene.h / 2:g}")
        h.press("Enter")
        page.page.wait_for_timeout(300)
    for _ in range(2):
        for f in FEATURES:
            # The tabs that measure start on their first visit (kapitza's work-precision and map
            # are heavy): the page may be slow to take a click, which is not what this test is about.
            page.page.locator(".bk-tab", has_text=f.label).first.click(timeout=90_000)
            page.page.wait_for_timeout(400)
    page.page.wait_for_timeout(1000)
    page.shot("00-every-control")
    page.check()


def test_a_reference_too_long_for_a_live_view_follows_its_runs_with_progress(page):
    """Charged at h = 0.6 to T = 30000: the runs (5e4 steps, about 0.5 s) come first, the text under
    the plots says their reference (3e6 rk8 steps, about 2.5 s) is being computed and how far it
    is, and the final errors and the trajectory error follow (before, there was no trajectory
    error at all)."""
    page.open(query(scene="charged", h="0.6"))
    page.page.wait_for_selector(TABLE_ROW)
    horizon = page.page.get_by_label("Horizon T")
    horizon.fill("30000")
    horizon.press("Enter")
    expect(page.page.locator("p.doc", has_text="It is being computed (")).to_contain_text(
        "rk8 at h/60, 3e+06 steps", timeout=WAIT_MS)
    awaiting = page.numbers()
    assert ["steps", "50,000", "50,000"] in awaiting and ["final relative error", "–", "–"] in awaiting
    page.shot("late-reference-computing")
    expect(page.page.locator("p.doc", has_text="against a reference run, rk8 at h/60")).to_be_visible(timeout=WAIT_MS)
    page.wait_for_numbers_change(awaiting)
    final = next(r for r in page.numbers() if r[0] == "final relative error")
    assert all(re.fullmatch(r"[0-9.e+-]+", cell) for cell in final[1:]), final
    page.shot("late-reference-arrived")
    page.check()


def test_a_comparison_that_runs_long_says_so_until_it_ends(page):
    """Kapitza at h = 0.005 to T = 5000 (1e6 steps, seconds): a notice says what is computed while the
    plots still show T = 20, and goes when the new results come (the spinner was the only sign). At
    T = 2000 the run could end between the notice and the look at the table, beside another test."""
    page.open(query(scene="kapitza", h="0.005"))
    page.page.wait_for_selector(TABLE_ROW)
    horizon = page.page.get_by_label("Horizon T")
    horizon.fill("5000")
    horizon.press("Enter")
    notice = page.page.locator(".notyf__message", has_text="Computing h = 0.005 to T = 5000 (1,000,000 steps)")
    expect(notice).to_be_visible(timeout=WAIT_MS)
    assert ["steps", "4,000", "4,000"] in page.numbers(), "the last results, until then"
    page.shot("waiting-notice")
    expect(notice).to_have_count(0, timeout=3 * WAIT_MS)
    assert ["steps", "1,000,000", "1,000,000"] in page.numbers()
    page.check()


def test_a_preset_link_opens_its_figure(page):
    from app.presets import PRESETS

    kapitza = next(p for p in PRESETS if p.name.startswith("Kapitza: stabilized"))
    page.open(kapitza.query())
    assert "Kapitza" in page.page.locator("h2:visible").first.inner_text()
    assert page.page.locator(".bk-tab.bk-active").inner_text() == "Play"
    page.page.locator("button.first").click()
    page.page.locator("button.play").click()
    expect(page.page.locator("p.clock")).not_to_have_text("t = 0 of 20")
    page.page.wait_for_timeout(1500)
    page.page.locator("button.pause").click()
    page.shot("04-kapitza-preset-play")
    gauge = next(p for p in PRESETS if p.name.startswith("Fig. gauge"))
    page.open(gauge.query())
    page.page.get_by_text("The paper's chi does not give the Lorenz condition").first.wait_for()
    page.page.wait_for_timeout(1500)
    page.shot("05-gauge-preset")
    damped = next(p for p in PRESETS if p.name == "Damped beyond floating point")
    page.open(damped.query())
    page.page.locator("details.presets summary").click()
    expect(page.page.get_by_text("each run stops just before")).to_be_visible()
    expect(page.page.locator(".notyf__message").first).to_contain_text("left floating-point range")
    # Both runs' q pass 1e308: the portrait is drawn (its auto ranges were (-inf, inf), an empty plot),
    # and the numbers table keeps both methods' columns in view (the failure message wraps).
    ranges = page.page.evaluate("""() => [...Bokeh.index.all_views()].filter((v) => v.model.type === 'Figure'
        && v.el.isConnected && v.el.getBoundingClientRect().width > 0).map((v) => [v.model.x_range.start,
        v.model.x_range.end, v.model.y_range.start, v.model.y_range.end])""")
    assert len(ranges) == 3 and all(math.isfinite(x) for r in ranges for x in r), ranges
    table = page.page.locator("table.dataframe").first
    assert table.evaluate("(t) => t.getBoundingClientRect().right <= window.innerWidth"), "a column out of view"
    page.shot("05b-hard-case-overflow")
    page.check()


def test_a_link_s_unknown_names_and_markup_are_said_as_text_never_run(page):
    """A misspelt name ('other' for 'vs') was ignored without a word; and the toasts set their
    text as HTML, so markup in a link's value ran in the page."""
    page.page.goto(page.base + "?scene=modulated&other=leapfrog&view=<img src=x onerror=window.pwned=1>",
                   wait_until="load")
    page.page.wait_for_selector("h2")
    unknown = page.page.locator(".notyf__toast", has_text="not a setting of this app").first
    unknown.wait_for()
    assert "the link's other is not a setting" in unknown.inner_text()
    bad_view = page.page.locator(".notyf__toast", has_text="could not be applied").first
    bad_view.wait_for()
    assert "<img src=x onerror=window.pwned=1>" in bad_view.inner_text()
    assert page.page.evaluate("window.pwned") is None
    assert page.page.locator(".notyf__toast img").count() == 0
    page.page.goto(page.base + "?scene=nosuch", wait_until="load")  # said in param's words: "Selector parameter 'Study.scene'"
    page.page.locator(".notyf__toast", has_text=f"scene=nosuch (not one of {', '.join(SCENES)})").first.wait_for()
    page.page.goto(page.base + "?T_long=-5", wait_until="load")  # kept silently, and written back into the link
    page.page.locator(".notyf__toast", has_text="the link's T_long=-5 could not be applied").first.wait_for()
    assert "T_long=-5" not in page.settled_url()


def test_a_bad_beta_is_a_notification_and_the_last_good_state_stays(page):
    page.open(query(scene="charged"))
    page.page.wait_for_selector(TABLE_ROW)
    before = page.numbers()
    beta = page.page.locator("input[placeholder*='tanh(t)']")
    beta.fill("0.05*(1 + sin(t)")
    beta.press("Enter")
    toast = page.page.locator(".notyf__toast").first
    toast.wait_for()
    assert "beta(t)" in toast.inner_text() and "parenthesis" in toast.inner_text()
    page.page.wait_for_timeout(800)
    page.shot("06-bad-beta-notification")
    assert page.numbers() == before
    beta.fill("paper")
    beta.press("Enter")
    h = page.page.locator("input.bk-input").first
    h.fill("-1")
    h.press("Enter")
    page.page.locator(".notyf__toast", has_text="must be positive").first.wait_for()
    assert page.numbers() == before
    page.check()


def test_a_long_run_starts_shows_progress_and_cancels(page):
    # ten times the paper's horizon: its own 5e6 steps per method now end in about two seconds
    page.open(query(scene="damped", method="symplectic-euler", p={"gamma": 0.0002}, view="long", T_long=5e6))
    page.page.get_by_text("running").first.wait_for()  # started by the tab's first showing
    expect(page.page.locator(".colorkey").last).to_contain_text("rk4")
    page.page.wait_for_timeout(1500)
    page.shot("07-long-run-running")
    clicked = time.monotonic()
    page.page.locator("button:visible", has_text="Cancel").click()
    page.page.get_by_text("cancelled at t =").first.wait_for(timeout=10_000)
    assert time.monotonic() - clicked < 10
    page.page.locator(".bk-tab", has_text="Orbits").click()
    page.page.wait_for_selector(TABLE_ROW)
    page.shot("08-long-run-cancelled-then-compare")
    page.check()


def test_theta_lesson_and_shared_link(page):
    page.open(query(scene="decaying", view="theta", lesson_theta=0.4))
    page.page.get_by_text("theta-naive").first.wait_for()
    page.page.wait_for_timeout(2000)
    page.shot("09-theta-lesson")
    assert "lesson_theta=0.4" in page.page.url and "view=theta" in page.page.url
    link = page.page.url
    page.open(link.split("/app", 1)[1])
    assert page.page.locator(".bk-tab.bk-active").inner_text() == "Theta lesson"
    page.check()


# The Bokeh plot view titled `title` (a walk through every view of the page's documents).
PLOT_VIEW_JS = """function plotView(title) {
    const roots = Bokeh.index instanceof Map ? [...Bokeh.index.values()] : Object.values(Bokeh.index);
    const seen = new Set();
    let found = null;
    function walk(v) {
        if (!v || seen.has(v) || found) return;
        seen.add(v);
        if (v.frame && v.renderer_views && v.model.title && v.model.title.text === title) found = v;
        for (const c of (v.child_views ? [...v.child_views] : [])) walk(c);
    }
    for (const r of roots) walk(r);
    return found;
}"""
POINT_JS = """([title, solver, k]) => {
    // Screen position of the k-th point of `solver` in the work-precision plot titled `title`.
    /*plotView*/
    const v = plotView(title);
    if (!v) return null;
    for (const r of v.renderer_views.values()) {
        const src = r.model.data_source;
        const data = !src ? {} : src.data instanceof Map ? Object.fromEntries(src.data) : src.data;
        if (!("run" in data)) continue;
        const mine = [...data.solver.keys()].filter(i => data.solver[i] === solver);
        const i = mine[Math.min(k, mine.length - 1)];
        const box = v.canvas_view.el.getBoundingClientRect();
        return {x: box.left + v.frame.x_scale.compute(data.x[i]), y: box.top + v.frame.y_scale.compute(data.y[i]),
                run: data.run[i], steps: data.steps[i]};
    }
    return null;
}""".replace("/*plotView*/", PLOT_VIEW_JS)
WP_TITLE = "relative error at T against wall time"


def test_work_precision_measures_a_click_opens_the_point_and_long_horizons_cancel(page):
    started = time.monotonic()
    page.open(query(scene="decaying", view="workprecision"))  # the tab measures when first shown
    page.page.locator("b.wpstatus").first.filter(has_text="done in").wait_for(timeout=60_000)
    took = time.monotonic() - started
    page.page.wait_for_function(f"() => document.body && ({POINT_JS})([{WP_TITLE!r}, 'midpoint', 0]) !== null")
    page.page.wait_for_timeout(1000)
    page.shot("10-work-precision")
    assert took < 30, took
    expect(page.page.get_by_text("scipy DOP853 / fastest cosymp").first).to_be_visible()
    point = page.page.evaluate(POINT_JS, [WP_TITLE, "midpoint", 5])
    page.page.mouse.click(point["x"], point["y"])
    expect(page.page.locator(".bk-tab.bk-active")).to_have_text("Orbits")
    page.page.wait_for_url(lambda url: "method=midpoint" in url and "view=compare" in url)
    steps = f"{int(point['steps']):,}"
    row = json.dumps(['steps', steps, steps], separators=(',', ':'))[1:-1]
    page.page.wait_for_function(f"() => JSON.stringify(({TABLE_JS})()).includes({row!r})")
    page.page.wait_for_timeout(1000)
    page.shot("11-work-precision-point-opened")
    page.page.locator(".bk-tab", has_text="Work–precision").click()
    page.page.locator("select:has(option[value='1e+06'])").select_option("1e+06")
    page.page.locator("button", has_text="Start long horizons").click()
    page.page.locator(".wplabel", has_text="to T = 1e+06").wait_for()
    clicked = time.monotonic()
    page.page.locator("button:visible", has_text="Cancel").nth(1).click()
    page.page.get_by_text("cancelled after").first.wait_for(timeout=5_000)
    assert time.monotonic() - clicked < 5
    # Run to the end: the long horizons' figures, built at the first Start, draw the rows, and their
    # stylesheets come from this server (built when the rows came, they were linked from Panel's CDN).
    page.page.locator("select:has(option[value='1e+06'])").select_option("1e+03")
    page.page.locator("button", has_text="Start long horizons").click()
    page.page.locator("b.wpstatus", has_text="done in").nth(1).wait_for(timeout=60_000)
    page.page.wait_for_function(f"() => {{ {PLOT_VIEW_JS}; const v = plotView('relative error at T, at fixed h'); "
                                "return v !== null && v.model.renderers.some((r) => r.data_source.get_length() > 0); }")
    page.check()


MAP_PIXEL_JS = """([title, x, y]) => {
    // Screen position of data point (x, y) in the plot titled `title`.
    /*plotView*/
    const v = plotView(title);
    if (!v) return null;
    const box = v.canvas_view.el.getBoundingClientRect();
    return {x: box.left + v.frame.x_scale.compute(x), y: box.top + v.frame.y_scale.compute(y)};
}""".replace("/*plotView*/", PLOT_VIEW_JS)


VISIBLE_TOOLTIPS_JS = """() => {
    // Bokeh tooltips shown on the page, in every shadow root.
    let shown = 0;
    const walk = (root) => {
        for (const el of root.querySelectorAll("*")) {
            if (el.classList.contains("bk-Tooltip") && el.getBoundingClientRect().width > 0) shown += 1;
            if (el.shadowRoot) walk(el.shadowRoot);
        }
    };
    walk(document);
    return shown;
}"""


def test_stability_map_shows_the_mathieu_tongue_and_a_click_opens_the_cell(page):
    """The default map of the modulated scene (alpha 0.5...4.5 x eps 0...0.8, 30 x 30 cells) is
    computed in the background; a click on the cell nearest (alpha, eps) = (2, 0.6), inside the
    principal tongue, opens that run in the Orbits view with those values, scrolled to its top (it
    kept the map's scroll). The cell's tooltip, shown while the mouse was on it, is gone when the
    map's tab is shown again (it stayed there)."""
    page.open(query(scene="modulated", view="map"))  # computed by the tab's first showing, or recalled
    page.page.locator("b.wpstatus").filter(has_text=re.compile("done in|by this server")).wait_for(timeout=120_000)
    title = f"{MEASURE_TITLES['growth']} of midpoint on modulated"
    page.page.wait_for_function(f"() => ({MAP_PIXEL_JS})([{title!r}, 2.0, 0.6]) !== null")
    page.page.wait_for_timeout(1000)
    page.shot("12-stability-map")
    alphas, epss = np.linspace(0.5, 4.5, 30), np.linspace(0.0, 0.8, 30)
    a, e = alphas[np.argmin(abs(alphas - 2.0))], epss[np.argmin(abs(epss - 0.6))]
    page.page.set_viewport_size({"width": 1400, "height": 800})  # a laptop's: the map's tab scrolls
    page.page.evaluate("() => { document.getElementById('main').scrollTop = 300; }")
    page.page.wait_for_function("() => document.getElementById('main').scrollTop > 0")
    pixel = page.page.evaluate(MAP_PIXEL_JS, [title, a, e])
    page.page.mouse.move(pixel["x"] - 3, pixel["y"])
    page.page.mouse.move(pixel["x"], pixel["y"])
    page.page.wait_for_function(f"() => ({VISIBLE_TOOLTIPS_JS})() == 1")
    page.page.mouse.click(pixel["x"], pixel["y"])
    expect(page.page.locator(".bk-tab.bk-active")).to_have_text("Orbits")
    page.page.wait_for_function("() => document.getElementById('main').scrollTop === 0")
    page.page.wait_for_url(lambda url: "alpha" in url)
    values = json.loads(parse_qs(urlparse(page.page.url).query)["p"][0])
    assert values == {"alpha": significant(a), "eps": significant(e)}
    page.page.locator(".bk-tab", has_text="Stability map").click()
    page.page.locator("b.wpstatus").filter(has_text=re.compile("done in|by this server")).wait_for(timeout=120_000)
    page.page.wait_for_function(f"() => ({MAP_PIXEL_JS})([{title!r}, 2.0, 0.6]) !== null")
    page.page.wait_for_timeout(500)
    assert page.page.evaluate(VISIBLE_TOOLTIPS_JS) == 0
    page.check()


def open_report_offline(browser, path, shot):
    """Open a saved report from disk in a new offline context where every request but the file's
    own is aborted; returns (other requests, console and page errors, data-plots, .uplot count)."""
    url = path.resolve().as_uri()
    ctx = browser.new_context(viewport={"width": 1200, "height": 900}, offline=True)
    blocked, errors = [], []

    def only_the_file(route):
        if route.request.url == url:
            route.continue_()
        else:
            blocked.append(route.request.url)
            route.abort()

    try:
        ctx.route("**/*", only_the_file)
        report = ctx.new_page()
        report.set_default_timeout(WAIT_MS)
        report.on("request", lambda r: r.url != url and blocked.append(r.url))
        report.on("console", lambda m: m.type == "error" and errors.append(m.text))
        report.on("pageerror", lambda e: errors.append(str(e)))
        report.goto(url, wait_until="load")
        report.wait_for_function("document.body.getAttribute('data-plots') !== null")
        plots = report.evaluate("document.body.getAttribute('data-plots')")
        drawn = report.locator(".uplot").count()
        report.screenshot(path=str(ARTIFACTS / shot), full_page=True)
        return sorted(set(blocked)), errors, plots, drawn
    finally:
        ctx.close()


def test_download_report_saves_a_self_contained_file_that_draws_offline(page, browser):
    page.open(query(scene="decaying"))
    page.page.wait_for_selector(TABLE_ROW)
    deadline = time.monotonic() + WAIT_MS / 1000
    while not page.plotted():
        assert time.monotonic() < deadline, "no plotted data"
        page.page.wait_for_timeout(200)
    button = page.page.locator("button", has_text="Download report (HTML)")
    with page.page.expect_download(timeout=60_000) as download:
        button.click()
    path = ARTIFACTS / "app-report.html"
    download.value.save_as(path)
    assert download.value.suggested_filename == "cosymp-decaying-midpoint.html"
    text = path.read_text(encoding="utf-8")
    assert "cosymp report decaying --method midpoint --vs rk4" in text and "-o cosymp-decaying-midpoint.html" in text
    assert "No report" not in text
    page.check()
    blocked, errors, plots, drawn = open_report_offline(browser, path, "app-report.png")
    assert blocked == [] and errors == [], (blocked, errors)
    assert plots == str(drawn) == "7", (plots, drawn)


SENDS_JS = """() => {
  // app/static/bokeh_sends.js on BokehJS's own ClientSession, with a connection that records what
  // is sent and answers only when told.
  const {ClientSession} = Bokeh.require("client/session");
  const {Message} = Bokeh.require("protocol/message");
  const {Document} = Bokeh.require("document");
  const {Slider, Button} = Bokeh.require("models/widgets");
  const {DataRange1d, Range1d} = Bokeh.require("models/ranges");
  const doc = new Document();
  const slider = new Slider({start: 0, end: 10, value: 0, step: 1});
  const button = new Button({subscribed_events: new Set(["button_click"])});  // as a button with a handler
  const auto = new DataRange1d(), fixed = new Range1d({start: 0, end: 1});
  doc.add_root(slider);
  doc.add_root(button);
  doc.add_root(auto);
  doc.add_root(fixed);
  const sent = [];
  const session = new ClientSession({send: (m) => sent.push(m)}, doc);
  const events = (m) => m.content.events.map((e) => e.kind === "ModelChanged" ? `${e.attr}=${e.new}` : e.kind);
  const reply = (type, m, content) => session.handle(new Message({msgtype: type, msgid: `r${m.msgid()}`, reqid: m.msgid()},
                                                                 {}, content));
  const ok = (m) => reply("OK", m, {});
  auto.setv({start: -1, end: 1});  // an auto range's bounds from new data: not sent
  const bounds = sent.length;
  fixed.start = -2;  // another range's: sent, as BokehJS sends it
  const other = sent.map(events);
  ok(sent[0]);
  sent.length = 0;
  slider.value = 1;
  slider.value = 2;
  slider.value_throttled = 2;
  slider.value = 3;
  const before = sent.length;
  button.trigger_event(new (Bokeh.require("core/bokeh_events").ButtonClick)());
  slider.value = 4;
  slider.value = 5;
  ok(sent[0]);
  const second = sent.length;
  ok(sent[0]);  // a late or repeated answer sends nothing twice
  slider.value = 6;
  const third = sent.length;
  reply("ERROR", sent[1], {text: "refused"});
  return {bounds, other, before, second, third, after: sent.length, messages: sent.map(events)};
}"""


def test_a_burst_of_changes_goes_as_one_message_per_answer_in_order_with_superseded_values_left_out(page):
    """app/static/bokeh_sends.js: the first change goes at once; what changes before the server
    answers goes in one message when it does, each property's last value only, but never across a
    click (its handler must see the values set before it); an ERROR answer counts as an answer. An
    auto range's bounds are not sent; another range's are."""
    page.open()
    page.page.wait_for_selector(TABLE_ROW)
    out = page.page.evaluate(SENDS_JS)
    assert out["bounds"] == 0 and out["other"] == [["start=-2"]], out
    assert out["before"] == 1 and out["second"] == 2 and out["third"] == 2 and out["after"] == 3, out
    assert out["messages"] == [["value=1"], ["value_throttled=2", "value=3", "MessageSent", "value=5"], ["value=6"]]
    assert [e for e in page.errors if "refused" in e] == [page.errors.pop()], "BokehJS logs the ERROR answer, as before"
    page.check()


def test_twenty_quick_key_presses_on_a_slider_reach_the_server_in_a_few_messages_and_the_last_value_wins(page):
    """Without app/static/bokeh_sends.js the page sent two messages per press (the slider's value and
    its throttled value), 40, and the server read them one by one long after the last press."""
    page.open(query(scene="damped"))
    page.page.wait_for_selector(TABLE_ROW)
    patches = []
    page.page.on("websocket", lambda ws: ws.on("framesent", lambda frame: patches.append(frame)
                                               if isinstance(frame, str) and '"msgtype":"PATCH-DOC"' in frame else None))
    page.page.reload()  # the listener sees the page's own websocket
    page.page.wait_for_selector(TABLE_ROW)
    handle = page.page.locator(".noUi-handle[aria-valuenow='0.2']").element_handle()
    handle.focus()
    before, sent = page.numbers(), len(patches)
    for _ in range(20):
        page.page.keyboard.press("ArrowRight")
    page.wait_for_numbers_change(before)
    last = float(handle.get_attribute("aria-valuenow"))
    assert last > 0.2
    page.page.wait_for_function("(v) => Math.abs(JSON.parse(new URL(location.href).searchParams.get('p')).gamma - v) "
                                "< 1e-9 * Math.abs(v)", arg=last, timeout=WAIT_MS)
    assert len(patches) - sent < 20, len(patches) - sent
    page.check()


SIZES_JS = """() => {
  // Every shown element's size as its view holds it against the browser's layout of it.
  const {UIElementView} = Bokeh.require("models/ui/ui_element");
  const out = [];
  for (const view of Bokeh.index.all_views()) {
    if (view instanceof UIElementView && view.el.isConnected && view.el.offsetParent !== null) {
      const r = view.el.getBoundingClientRect();
      out.push([view.model.type, view.bbox.width, view.bbox.height, Math.floor(r.width), Math.floor(r.height)]);
    }
  }
  return out;
}"""


def test_the_first_page_s_elements_hold_the_sizes_the_browser_gave_them(page):
    """app/static/bokeh_reads.js reads the sizes of a root's elements together once it is built
    (each element read its own as it was rendered): every shown element must still know its size,
    and the toolbars their tools (a toolbar that read no size put every tool in its overflow menu)."""
    page.open()
    page.page.wait_for_selector(TABLE_ROW)
    page.page.wait_for_timeout(1000)
    sizes = page.page.evaluate(SIZES_JS)
    assert len(sizes) > 50 and {"Figure", "Toolbar", "Slider"} <= {s[0] for s in sizes}
    assert [s for s in sizes if (s[1], s[2]) != (s[3], s[4])] == []
    assert page.page.evaluate("""() => [...Bokeh.index.all_views()].filter((v) => v.model.type === "Toolbar"
        && v.shadow_el.querySelector('.bk-tool-overflow') !== null).length""") == 0
    page.check()


EQUATIONS_JS = """() => {
  // The TeX of every equation shown (KaTeX keeps it in its MathML), and how many equation panes
  // seen before kept their first style element (a pane rendered anew drops it).
  const out = {tex: [], seen: 0, kept: 0};
  for (const view of Bokeh.index.all_views()) {
    if (view.shadow_el == null || !view.el.isConnected || view.shadow_el.querySelector(".katex") === null) continue;
    out.tex.push(...[...view.shadow_el.querySelectorAll("annotation")].map((a) => a.textContent));
    const style = view.shadow_el.querySelector("style");
    if (view.cosymp_test_seen) {
      out.seen += 1;
      out.kept += style.dataset.cosympTest === "1" ? 1 : 0;
    }
    view.cosymp_test_seen = true;
    style.dataset.cosympTest = "1";
  }
  return out;
}"""
TEX_JS = """([tex]) => JSON.stringify([...Bokeh.index.all_views()].filter((v) => v.shadow_el != null && v.el.isConnected)
  .flatMap((v) => [...v.shadow_el.querySelectorAll(".katex annotation")].map((a) => a.textContent)))
  === JSON.stringify(tex)"""


def test_a_scene_change_shows_its_equations_typeset_on_the_server(page):
    """The equations come typeset (plotting.typeset): the page loads no KaTeX script, a scene change
    shows the scene's equations in KaTeX's fonts, and each pane keeps its style elements (its text
    replaced, not the pane rendered anew)."""
    page.open(query(scene="damped"))
    page.page.wait_for_selector(TABLE_ROW)
    assert page.page.evaluate("[typeof window.katex, typeof window.renderMathInElement]") == ["undefined"] * 2
    assert not page.page.evaluate("[...document.scripts].map((s) => s.src).filter((s) => /katex/i.test(s))")
    assert page.page.evaluate(EQUATIONS_JS)["tex"] == list(SCENES["damped"].equations)
    for name in ("charged", "damped", "charged"):
        page.page.locator("select").first.select_option(label=SCENES[name].title)
        page.page.wait_for_function(TEX_JS, arg=[list(SCENES[name].equations)])
        shown = page.page.evaluate(EQUATIONS_JS)
        assert shown["tex"] == list(SCENES[name].equations), name
        assert shown["kept"] == shown["seen"] >= len(SCENES["damped"].equations), (name, shown)
    assert shown["seen"] == len(SCENES["charged"].equations), "every pane of the last scene was seen before and kept"
    page.shot("equations-charged")
    page.check()


STYLE_WRITES_JS = """() => {
  // Writes to <style> elements while every root lays out the page again, nothing having changed.
  const text = Object.getOwnPropertyDescriptor(Node.prototype, "textContent");
  let writes = 0, roots = 0;
  Object.defineProperty(HTMLStyleElement.prototype, "textContent", {configurable: true,
    get() { return text.get.call(this); }, set(value) { writes += 1; text.set.call(this, value); }});
  try {
    for (const view of Bokeh.index.all_views()) {
      if (view.is_layout_root && view.el.isConnected && typeof view.invalidate_layout === "function") {
        view.invalidate_layout();
        roots += 1;
      }
    }
  } finally {
    delete HTMLStyleElement.prototype.textContent;
  }
  return [roots, writes];
}"""


def test_a_layout_writes_only_the_style_sheets_whose_text_changed(page):
    """app/static/bokeh_layouts.js keeps a layout's writes to style sheets and makes only those that
    change a sheet's text (BokehJS clears each sheet and appends its rules again; the browser counts
    a sheet written back to the same text as changed, and each change makes the next style
    recalculation collect the rules of every shadow root). After a scene of another shape, every
    shown element still holds the size the browser gave it."""
    page.open(query(scene="damped"))
    page.page.wait_for_selector(TABLE_ROW)
    page.page.locator("select").first.select_option(label=SCENES["charged"].title)
    expect(page.page.locator("h2:visible").first).to_contain_text("Charged particle")
    page.page.wait_for_timeout(1500)
    roots, writes = page.page.evaluate(STYLE_WRITES_JS)
    assert roots > 0 and writes == 0, (roots, writes)
    sizes = page.page.evaluate(SIZES_JS)
    assert len(sizes) > 50 and "Figure" in {s[0] for s in sizes}
    assert [s for s in sizes if (s[1], s[2]) != (s[3], s[4])] == []
    page.check()


TABS_JS = """() => {
  // Each Tabs: which tab is shown, which tabs' contents are in the document, and its placeholders.
  return [...Bokeh.index.all_views()].filter((v) => v.model.type.endsWith("Tabs") && v.el.isConnected)
    .map((v) => [v.model.active, v.child_views.map((c) => c.el.isConnected),
                 [...v.shadow_el.childNodes].filter((n) => n.nodeType === Node.COMMENT_NODE).length]);
}"""
FIGURES_SHOWN_JS = """() => [...Bokeh.index.all_views()].filter((v) => v.model.type === "Figure"
  && v.el.isConnected && v.el.offsetParent !== null).map((v) => [v.bbox.width, v.bbox.height])"""


def test_only_the_shown_tab_s_contents_are_in_the_document(page):
    """app/static/bokeh_layouts.js takes the contents of the tabs not shown out of the document (a
    placeholder keeps their place): the browser's style recalculations then collect the rules of the
    shown tab's shadow roots only. A tab clicked comes back with its figures drawn at their sizes."""
    from app.features import FEATURES

    labels = [f.label for f in FEATURES]
    page.open()
    page.page.wait_for_selector(TABLE_ROW)
    for label in ("Structure", "Orbits"):
        page.page.locator(".bk-tab", has_text=label).first.click()
        page.page.wait_for_function(f"() => {{ const f = ({FIGURES_SHOWN_JS})(); "
                                    "return f.length >= 3 && f.every(([w, h]) => w > 100 && h > 100); }")
        tabs = page.page.evaluate(TABS_JS)
        assert tabs and all(shown == [i == active for i in range(len(shown))] and spots == len(shown) - 1
                            for active, shown, spots in tabs), tabs
        assert [labels.index(label)] == [active for active, _, _ in tabs], (label, tabs)
    page.shot("tabs-back-to-orbits")
    page.check()


RANGES_JS = """(title) => {
    // [x start, x end, data x min, data x max] of the figures titled `title` (Bokeh's models).
    const out = [];
    for (const doc of Bokeh.documents) for (const m of doc.all_models) {
        if (!m.title || m.title.text !== title || !m.x_range) continue;
        const xs = [];
        for (const r of m.renderers) {
            const d = r.data_source && r.data_source.data;
            const x = d && (d instanceof Map ? d.get("x") : d.x);
            if (x) for (const v of x) if (Number.isFinite(v)) xs.push(v);
        }
        if (xs.length) out.push([m.x_range.start, m.x_range.end, Math.min(...xs), Math.max(...xs)]);
    }
    return out;
}"""


def test_a_figure_shown_again_follows_its_new_data(page):
    """Structure's paper's det estimator is drawn on a log axis for charged and on a linear one for
    modulated and kapitza. Its linear figure, taken out of the page for charged and put back for
    kapitza, came back with modulated's axis, t to 1050, pinned: kapitza's data (t to 25) sat in a
    corner at 1e-12 of a 1e-10 axis, an empty-looking plot. Both figures now stay in the page."""
    title = "paper's estimator: det[X¹ … X²ⁿ⁺¹]"
    page.open()
    page.page.wait_for_selector(TABLE_ROW)
    scene = page.page.locator("select").first
    for tab, name in (("Structure", None), (None, "charged"), ("Orbits", None), (None, "kapitza"), ("Structure", None)):
        if tab:
            page.page.locator(".bk-tab", has_text=tab).first.click()
        else:
            scene.select_option(label=SCENES[name].title)
            expect(page.page.locator("h2:visible").first).to_contain_text(SCENES[name].title.split(" (")[0])
        page.page.wait_for_timeout(3000)
    page.page.wait_for_function(f"() => ({RANGES_JS})({json.dumps(title)}).some(([a, b, lo, hi]) => hi > 24 && hi <= 25)")
    page.shot("structure-kapitza-after-charged")
    for start, end, lo, hi in page.page.evaluate(RANGES_JS, title):
        if 24 < hi <= 25:  # kapitza's T: the figure shown
            assert start <= lo and hi <= end < 2 * hi, (start, end, lo, hi)
    page.check()


PLAYER_JS = """() => { for (const d of Bokeh.documents) for (const m of d.all_models)
    if (m.constructor && m.constructor.__name__ === 'Player') return [m.value, m.interval, m.direction]; }"""


def test_a_speed_picked_while_playing_changes_the_rate_at_once(page):
    """BokehJS's player reads its interval when it starts: a speed picked while playing changed
    nothing until pause and play (90 and 91.5 time units in 3 s at 20 and 5 frames/s)."""
    page.open(query(view="play"))
    speed = page.page.locator("select").filter(has=page.page.locator("option", has_text="5 frames/s")).first
    speed.select_option(label="5 frames/s")
    page.page.wait_for_function(f"() => ({PLAYER_JS})()[1] === 200")
    page.page.locator(".play").first.click()

    def rate():
        first = page.page.evaluate(PLAYER_JS)[0]
        page.page.wait_for_timeout(2000)
        return (page.page.evaluate(PLAYER_JS)[0] - first) / 2

    slow = rate()
    speed.select_option(label="20 frames/s")
    page.page.wait_for_timeout(300)
    fast = rate()
    assert 3 <= slow <= 6 and fast > 2 * slow, (slow, fast)
    page.check()


LOOP_SHAPE_JS = """(title) => {
    // Drawn width over drawn height, in pixels, of the first curve of the plot titled `title`.
    /*plotView*/
    const v = plotView(title);
    if (!v) return null;
    for (const r of v.renderer_views.values()) {
        const src = r.model.data_source;
        const data = !src ? {} : src.data instanceof Map ? Object.fromEntries(src.data) : src.data;
        if (!data.x || data.x.length < 3) continue;
        const px = [...data.x].map((x) => v.frame.x_scale.compute(x));
        const py = [...data.y].map((y) => v.frame.y_scale.compute(y));
        return (Math.max(...px) - Math.min(...px)) / (Math.max(...py) - Math.min(...py));
    }
    return null;
}""".replace("/*plotView*/", PLOT_VIEW_JS)


def test_the_loop_of_initial_states_is_drawn_round(page):
    """Play's loop starts as a circle of initial states; on a wide plot with its own scale on each
    axis it was drawn as an ellipse at t = 0, a deformation no method made. Its axes share one scale."""
    page.open(query(view="play"))
    page.page.wait_for_function(f"() => ({LOOP_SHAPE_JS})('loop of initial states, now') !== null")
    page.page.wait_for_timeout(500)
    assert 0.95 < page.page.evaluate(LOOP_SHAPE_JS, "loop of initial states, now") < 1.05
    page.check()
