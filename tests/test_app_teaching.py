"""What a newcomer and a teacher see, in the browser: one test per item of the list of things that
got in their way (the first view, readable plots, honest states), on the served app."""
import json
import pathlib
import re
import shutil
from urllib.parse import parse_qs, urlparse

import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from playwright.sync_api import expect
from served import CHROMIUM, START_TIMEOUT_S, TABLE_JS, TABLE_ROW, query

from app.features.stabilitymap import MEASURE_TITLES
from app.presets import PRESETS
from cosymp.report.style import METHOD_COLORS
from cosymp.scenes import lead

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not shutil.which(CHROMIUM), reason=f"no Chromium at {CHROMIUM} (apt-get install it)"),
    pytest.mark.timeout(START_TIMEOUT_S + 120),
]

# Every plot of the page: its title, axes' formatter outputs for given ticks, and its line glyphs
# in drawing order (colour, dash, points).
PLOTS_JS = """() => {
    const out = [], v = (x) => (x && typeof x === "object" && "value" in x) ? x.value : x;
    for (const doc of Bokeh.documents) for (const m of doc.all_models) {
        if (!["Figure", "Plot"].includes(m.type) || !m.title) continue;
        const lines = m.renderers.filter(r => r.glyph && r.glyph.type === "Line").map(r => {
            const src = r.data_source, data = src.data instanceof Map ? Object.fromEntries(src.data) : src.data;
            return {color: v(r.glyph.line_color), dash: v(r.glyph.line_dash), n: (data.x || []).length};
        });
        const mapped = m.renderers.find(r => r.glyph && r.glyph.fill_color && r.glyph.fill_color.transform);
        out.push({title: m.title.text, lines, right: m.right.map(x => x.type), center: m.center.map(x => x.type),
                  y_mapper: mapped ? mapped.glyph.fill_color.transform.type : null});
    }
    return out;
}"""
FORMAT_JS = """(ticks, marker = "places") => {
    for (const doc of Bokeh.documents) for (const m of doc.all_models)
        if (m.type === "CustomJSTickFormatter" && m.code.includes(marker)) return m.doFormat(ticks, {loc: 0});
    return null;
}"""
LOG_AXIS_JS = """([lo, hi]) => {
    for (const doc of Bokeh.documents) for (const m of doc.all_models) {
        if (m.type !== "Figure" || !m.title || m.title.text !== "energy error |H + p_t|") continue;
        const axis = m.left[0], ticks = axis.ticker.get_ticks(lo, hi, m.y_range, 0).major;
        return axis.formatter.doFormat(ticks, {loc: 0});
    }
    return null;
}"""
RANGE_JS = """() => { const out = []; function find(root) {
    for (const el of root.querySelectorAll("input[type=range]")) out.push([+el.min, +el.max, +el.value]);
    for (const el of root.querySelectorAll("*")) if (el.shadowRoot) find(el.shadowRoot); }
    find(document); return out; }"""


def plots(page, title_start):
    return [p for p in page.page.evaluate(PLOTS_JS) if p["title"].startswith(title_start)]


def wait_for_plot(page, title_start, lines=2):
    page.page.wait_for_function(f"() => ({PLOTS_JS})().some(p => p.title.startsWith({json.dumps(title_start)}) && "
                                f"p.lines.filter(l => l.n > 0).length >= {lines})")
    return plots(page, title_start)[0]


def test_01_the_first_view_teaches_and_a_is_drawn_over_b(page):
    """The first view: the verdict in words, RK4's |H + p_t| leaving midpoint's band; the first
    method (A) is drawn solid over the second (B), dashed; a portrait then draws the last part of
    each orbit bold, B's dashes over A (where the orbits fill one band, A hid B)."""
    page.open()
    expect(page.page.locator(".verdict")).to_contain_text("rk4's |H + p_t| leaves midpoint's bounded band")
    energy = wait_for_plot(page, "energy error |H + p_t|")
    portrait = wait_for_plot(page, "phase portrait", lines=4)
    a = (METHOD_COLORS["midpoint"], True)
    b = (METHOD_COLORS["rk4"], False)
    for plot, order in ((energy, [b, a]), (portrait, [b, a, a, b])):
        drawn = [(line["color"], line["dash"] == []) for line in plot["lines"] if line["n"] > 1]
        assert drawn == order
    page.shot("t01-first-view")
    page.check()


def test_02_one_colour_per_method_in_the_app_and_the_report(page):
    page.open(query(scene="decaying", method="gauss4", vs="euler"))
    portrait = wait_for_plot(page, "phase portrait")
    colors = {line["color"] for line in portrait["lines"] if line["n"] > 1}
    assert colors == {METHOD_COLORS["gauss4"], METHOD_COLORS["euler"]}
    with page.page.expect_download(timeout=60_000) as download:
        page.page.locator("button", has_text="Download report (HTML)").click()
    text = pathlib.Path(download.value.path()).read_text(encoding="utf-8")
    spec = json.loads(re.search(r'id="figures" type="application/json">(.*?)</script>', text, re.DOTALL).group(1)
                      .replace("<\\/", "</"))
    series = {s["label"]: s["color"] for f in spec for s in f["series"]}
    assert series["gauss4"] == METHOD_COLORS["gauss4"] and series["euler"] == METHOD_COLORS["euler"]
    page.check()


def test_03_tick_labels_are_compact_and_distinct(page):
    page.open()
    wait_for_plot(page, "phase portrait")

    def fmt(ticks):
        return page.page.evaluate(FORMAT_JS, ticks)

    assert fmt([0, 2e-4, 4e-4]) == ["0", "2e-4", "4e-4"]
    assert fmt([0, 5e4, 1e5]) == ["0", "5e4", "1e5"]
    assert fmt([1 - 2 ** -52, 1, 1 + 2 ** -52]) == ["1−2.22e-16", "1", "1+2.22e-16"]
    assert len(set(fmt([2e-6, 2.0000001e-6, 2.0000002e-6]))) == 3
    assert fmt([0.999997, 0.999998, 0.999999, 1, 1.000001]) == ["1−3e-6", "1−2e-6", "1−1e-6", "1", "1+1e-6"]
    # BokehJS's ticks a few ulps off their round values (the ω(δ¹, δ²)/δ² axis read 1.00000000005, −5e-11)
    assert fmt([0.9999999999000001, 0.99999999995, 1.0000000000000002, 1.00000000005]) == [
        "1−1e-10", "1−5e-11", "1", "1+5e-11"]
    def log_axis(lo, hi):  # the energy error's axis: its ticks over [lo, hi], and their labels
        return page.page.evaluate(LOG_AXIS_JS, [lo, hi])

    # kapitza's energy errors at T = 2000 (gauss4's band 1.2e-4 under rk4's rise to 6.5e-3): Bokeh's
    # ticker stepped linearly under 2 decades, 0.001 ... 0.006, and the band had no label near it
    assert log_axis(1.1e-4, 6.5e-3) == ["2e-4", "5e-4", "0.001", "0.002", "0.005"]
    assert log_axis(1e-17, 1e-2) == ["1e-17", "1e-15", "1e-13", "1e-11", "1e-9", "1e-7", "1e-5", "0.001"]
    assert log_axis(2.1e-3, 3.9e-3) == ["0.0025", "0.003", "0.0035"]
    assert log_axis(0.9995, 1.0021) == ["1", "1.001", "1.002"], "within a factor 1.01: the digits that tell ticks apart"
    page.check()


def test_04_legends_stay_beside_the_data_and_round_off_is_drawn_as_a_bound(page):
    page.open(query(scene="charged", view="gauges"))
    diff = wait_for_plot(page, "|q − q_orig| + |Π − Π_orig|, max per bin", lines=4)
    assert all(0 < line["n"] <= 1200 for line in diff["lines"])
    for p in page.page.evaluate(PLOTS_JS):
        assert "Legend" not in p["center"], f"a legend over the data of {p['title']!r}"
    expect(page.page.locator(".colorkey").first).to_contain_text("coulomb")
    page.check()


def test_05_equations_keep_their_primes_and_summaries_read_as_text(page):
    page.open(query(scene="charged"))
    html = page.page.content()
    katex = page.page.evaluate("""() => { let t = ""; function find(root) { for (const el of root.querySelectorAll(".katex"))
        t += el.textContent + "\\n"; for (const el of root.querySelectorAll("*")) if (el.shadowRoot) find(el.shadowRoot); }
        find(document); return t; }""")
    assert "′" in katex, "A′ = A + ∇χ keeps its prime"
    assert "e^{" not in html and "β(t)" in page.page.locator("h2:visible + p").first.inner_text()
    page.check()


def test_06_the_long_run_of_the_first_view_runs_and_shows_progress(page):
    page.open(query(view="long"))
    progress = page.page.locator("progress").first
    for _ in range(100):
        if float(progress.get_attribute("value") or 0) > 0:
            break
        page.page.wait_for_timeout(200)
    assert float(progress.get_attribute("value") or 0) > 0, "the long run moves its progress bar"
    wait_for_plot(page, "H~ = H + p_t, per-bin min and max")
    assert page.page.locator(".notyf__toast", has_text="reduce h").count() == 0
    key = page.page.locator(".colorkey").last
    assert "stopped" not in key.inner_text() and key.inner_text().count("\n") == 0
    cancel = page.page.locator("button:visible", has_text="Cancel")
    try:
        cancel.click(timeout=3000)
    except PlaywrightTimeout:  # the run ended (1e6 steps per method), between the check and the click
        assert not cancel.is_enabled()
    page.check()


def test_07_a_failure_says_where_the_data_shown_stops(page):
    preset = next(p for p in PRESETS if p.name == "Kapitza: Newton fails")
    page.open(preset.query())
    toast = page.page.locator(".notyf__toast", has_text="Newton did not converge").first
    toast.wait_for()
    t_fail = float(re.search(r"from t = ([0-9.]+)", toast.inner_text()).group(1))
    shown = float(re.search(r"showing data up to t = ([0-9.]+)", toast.inner_text()).group(1))
    assert shown == pytest.approx(t_fail)
    page.check()


def test_08_hard_cases_show_finite_figures_readable_ticks_and_both_orbits(page):
    beyond = next(p for p in PRESETS if p.name == "Damped beyond floating point")
    page.open(beyond.query())
    # The table's rows, labelled: under load its rows were read once while it was drawn (a first cell of '').
    page.page.wait_for_function(f"() => {{ const r = ({TABLE_JS})(); return r.length > 2 && r[0][0] !== ''; }}")
    first_row = page.numbers()[0]
    assert first_row[0] == "max |H + p_t|" and "nan" not in " ".join(first_row) and "–" not in first_row[1:]
    fmt = page.page.evaluate(FORMAT_JS, [0, 5e303, 1e304, 1.5e304])
    assert fmt == ["0", "5e303", "1e304", "1.5e304"], "compact and distinct, however large the values"
    rk4 = next(p for p in PRESETS if p.name == "RK4 just past its stability limit")
    page.open(rk4.query())
    a, b = wait_for_plot(page, "A: phase portrait", lines=1), wait_for_plot(page, "B: phase portrait", lines=1)
    assert a["lines"] and b["lines"], "orbits decades apart in size are drawn in portraits of their own"
    page.check()


def test_09_an_out_of_range_typed_value_is_refused_and_the_box_goes_back(page):
    page.open(query(scene="damped"))
    page.page.wait_for_selector(TABLE_ROW)
    box = page.page.locator("input.bk-input").nth(4)  # h, T, then the boxes of m, w0, gamma
    assert box.input_value() == "0.2"
    box.fill("1000000")
    box.press("Enter")
    page.page.locator(".notyf__toast", has_text="outside [-10, 10]").first.wait_for()
    expect(box).to_have_value("0.2")
    assert "gamma" not in page.settled_url()
    page.check()


def test_10_the_url_holds_only_valid_state_in_one_format(page):
    page.open(query(scene="damped"))
    page.page.wait_for_selector(TABLE_ROW)
    h = page.page.get_by_label("Step h")
    h.fill("0")
    h.press("Enter")
    page.page.locator(".notyf__toast", has_text="must be positive").first.wait_for()
    assert parse_qs(urlparse(page.settled_url()).query)["h"] == ["0.1"]
    beta_page = query(scene="charged")
    page.open(beta_page)
    beta = page.page.locator("input[placeholder*='tanh(t)']")
    beta.fill("sin(")
    beta.press("Enter")
    page.page.locator(".notyf__toast", has_text="beta(t)").first.wait_for()
    assert "sin(" not in page.settled_url()
    slider = page.page.locator("#sidebar .noUi-handle:visible").nth(2)
    slider.focus()
    slider.press("ArrowRight")
    page.page.wait_for_url(lambda url: "B0" in url)
    assert json.loads(parse_qs(urlparse(page.page.url).query)["p"][0]).keys() == {"B0"}
    page.check()


def test_11_play_opens_at_its_start(page):
    page.open(query(view="play"))
    expect(page.page.locator("p.clock")).to_have_text(f"t = 0 of {lead()[1].T:g}")
    assert page.page.evaluate(RANGE_JS) == [[0, 200, 0]]
    page.check()


def test_12_the_damped_map_shows_the_energy_error_on_a_sequential_log_scale(page):
    page.open(query(scene="damped", view="map"))
    page.page.locator("b.wpstatus").filter(has_text=re.compile("done in|by this server")).wait_for(timeout=120_000)
    # The status and the redrawn map reach the page in separate messages: wait for the map itself.
    heat = wait_for_plot(page, f"{MEASURE_TITLES['H_ext_max_abs']} of midpoint on damped", lines=0)
    assert heat["y_mapper"] == "LogColorMapper"
    page.check()


def test_13_the_theta_lesson_opens_where_the_methods_differ(page):
    page.open(query(view="theta"))
    expect(page.page.locator(".colorkey").first).to_contain_text("θ = 0.3")
    page.check()


def test_14_copy_link_says_what_happened(page):
    page.open()
    button = page.page.locator("button", has_text="Copy link to this view")
    button.click()
    expect(page.page.locator("button", has_text=re.compile(r"Link copied|Copy failed|Not allowed"))).to_be_visible()
    page.check()


def test_15_a_link_with_a_bad_step_shows_the_first_view_and_says_so(page):
    for bad in ("?h=-1", "?T=1e300"):
        page.open(bad)
        page.page.locator(".notyf__toast").first.wait_for()
        page.page.wait_for_selector(TABLE_ROW)
        wait_for_plot(page, "phase portrait")
        expect(page.page.get_by_label("Step h")).to_have_value(f"{lead()[1].h:g}")
    page.check()
