"""Static HTML reports: built by the CLI (and the app's state), opened from disk in headless
Chromium with every network request blocked and counted."""
import html
import io
import itertools
import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

from cosymp.cli import main
from cosymp.methods import METHODS, applicable
from cosymp.report import Figure, Report, Section, Series, envelope, render
from cosymp.report.style import FAMILY_MARKERS, METHOD_COLORS, MIN_DISTANCE, method_marker
from cosymp.scenes import SCENES

ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "tests" / "artifacts"
CHROMIUM = os.environ.get("COSYMP_CHROMIUM", "/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
PAPER_MAX_BYTES = 15_000_000


def test_envelope_keeps_extremes_and_bounds_the_size():
    t = np.arange(1_000_001.0)
    y = np.sin(t / 50.0)
    y[123_457] = 7.0
    x, v = envelope(t, y, 4000)
    assert len(x) <= 4000 and np.all(np.diff(x) > 0)
    assert v.max() == 7.0 and v.min() == pytest.approx(-1.0, abs=1e-6)
    assert envelope(t[:10], y[:10])[1].tolist() == y[:10].tolist()


def test_text_is_escaped_and_data_cannot_close_the_script():
    html = render(Report("<b>title</b>", ["a <script>alert(1)</script> b"],
                         [Section("s", [], [Figure("f", "x", "y", [Series("</script><b>", [0, 1], [1, np.nan])])])]))
    assert "<b>title</b>" not in html and "&lt;b&gt;title&lt;/b&gt;" in html
    assert "<script>alert(1)</script>" not in html
    data = re.search(r'<script id="figures" type="application/json">(.*?)</script>', html, re.DOTALL).group(1)
    spec = json.loads(data.replace("<\\/", "</"))
    assert spec[0]["series"][0]["label"] == "</script><b>" and spec[0]["series"][0]["y"] == [1, None]


def test_exact_zeros_on_a_log_axis_are_drawn_at_the_floor_and_said_only_where_asked():
    """Figure.zeros: a structure-preserving method's exact zeros on a log axis are drawn at
    series.zero_floor (a decade below the smallest nonzero value when that is below 1e-17) and the
    caption says where; without it they are left out, and nothing is said."""
    def drawn(zeros, ys):
        fig = Figure("f", "t", "defect", [Series(k, [0, 1, 2], y) for k, y in ys.items()], logy=True,
                     caption="Rigorous.", zeros=zeros)
        page = render(Report("r", [], [Section("s", [], [fig])]))
        data = re.search(r'<script id="figures" type="application/json">(.*?)</script>', page, re.DOTALL).group(1)
        spec = json.loads(data.replace("<\\/", "</"))
        return [s["y"] for s in spec[0]["series"]], re.search(r"<figcaption>(.*?)</figcaption>", page).group(1)

    ys = {"midpoint": [0.0, 0.0, 2e-16], "rk4": [1e-8, 2e-8, 3e-8]}
    assert drawn(True, ys) == ([[1e-17, 1e-17, 2e-16], [1e-8, 2e-8, 3e-8]],
                               "Rigorous. Exact zeros are drawn at 1e-17.")
    assert drawn(False, ys) == ([[None, None, 2e-16], [1e-8, 2e-8, 3e-8]], "Rigorous.")
    assert drawn(True, {"a": [0.0, 3e-40, 1.0]})[0] == [[3e-41, 3e-40, 1.0]], "a decade below the smallest value"
    assert drawn(True, {"a": [1e-9, 2e-9, 3e-9]})[1] == "Rigorous.", "no zero, nothing said"


def open_offline(path, shot, interact=False, js=None):
    """Open a report from disk with the network blocked; returns (requests other than the file,
    console errors, plots drawn, and when asked the second plot's hover readout and its x range
    before and after dragging a zoom box, and what the script js evaluates to)."""
    playwright = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM}")
    url = Path(path).resolve().as_uri()
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        ctx = browser.new_context(viewport={"width": 1200, "height": 900}, offline=True)
        requests, errors = [], []
        ctx.route("**/*", lambda route: route.continue_() if route.request.url == url else route.abort())
        page = ctx.new_page()
        page.on("request", lambda r: requests.append(r.url) if r.url != url else None)
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(url, timeout=120_000)
        page.wait_for_function("document.body.getAttribute('data-plots') !== null", timeout=120_000)
        drawn = page.locator(".uplot canvas").count()
        assert page.locator(".uplot .u-axis").count() == 2 * drawn, "every plot has its x and y axis"
        answers = {}
        if interact:
            plot = page.locator(".uplot").nth(1)
            plot.scroll_into_view_if_needed()
            box = plot.locator(".u-over").bounding_box()
            before = page.evaluate("[cosympPlots[1].scales.x.min, cosympPlots[1].scales.x.max]")
            answers["values shown off the plot"] = plot.locator(".u-legend .u-value").nth(1).is_visible()
            page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
            answers["hover"] = plot.locator(".u-legend .u-value").nth(1).inner_text()
            page.mouse.move(box["x"] + 0.3 * box["width"], box["y"] + 0.3 * box["height"])
            page.mouse.down()
            page.mouse.move(box["x"] + 0.6 * box["width"], box["y"] + 0.7 * box["height"], steps=5)
            page.mouse.up()
            answers["zoom"] = (before, page.evaluate("[cosympPlots[1].scales.x.min, cosympPlots[1].scales.x.max]"))
        if js:
            answers["js"] = page.evaluate(js)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / shot), full_page=True)
        browser.close()
    return requests, errors, drawn, answers


def test_scene_report_from_the_command_line(tmp_path):
    path = tmp_path / "decaying.html"
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", "decaying", "--method", "midpoint", "--vs", "euler", "-o", str(path)], out, err) == 0, err.getvalue()
    text = path.read_text()
    assert "cosymp report decaying --method midpoint --vs euler --h 0.1 --T 10" in text
    assert "max |det M_k − 1|" in text and "integration time (s)" in text
    requests, errors, drawn, answers = open_offline(path, "report-decaying.png", interact=True)
    assert requests == [] and errors == []
    assert drawn == 7
    assert answers["hover"] not in ("", "–")
    assert not answers["values shown off the plot"], "a legend's values read the cursor: no empty boxes without it"
    (x0, x1), (y0, y1) = answers["zoom"]
    assert x0 < y0 < y1 < x1


MARKS_JS = """() => Object.fromEntries(cosympPlots[0].series.slice(1).map((s, i) => {
    const u = cosympPlots[0], x = u.data[i + 1][0][0], y = u.data[i + 1][1][0];
    return [s.label, Array.from(u.ctx.getImageData(Math.round(u.valToPos(x, "x", true)),
                                                   Math.round(u.valToPos(y, "y", true)), 1, 1).data).slice(0, 3)];
}))"""


def test_markers_are_drawn_in_a_parametric_plot(tmp_path):
    """A work-precision plot is parametric: uPlot gave its point painter no points, so no marker was
    drawn. Two single points (a line of one point draws nothing), a square and a triangle."""
    path = tmp_path / "marks.html"
    series = [Series("a", [0.0], [0.0], points=True, color="#ff0000", marker="square"),
              Series("b", [1.0], [1.0], points=True, color="#0000ff", marker="triangle")]
    path.write_text(render(Report("marks", [], [Section("s", [], [Figure("f", "x", "y", series, parametric=True)])])))
    _, errors, drawn, answers = open_offline(path, "report-marks.png", js=MARKS_JS)
    assert errors == [] and drawn == 1
    assert answers["js"] == {"a": [255, 0, 0], "b": [0, 0, 255]}


def test_log_axes_tick_and_label_as_the_app_does(tmp_path):
    """The app's log-axis rule (cosymp/report/logaxis.js): 0.001 to 10000 written out and 1e-4, 1e5
    beyond (the report wrote every decade as a power, 1e0 and 1e2 beside the app's 1 and 100); under
    2 decades 1, 2 and 5 times a power of ten (the report had one tick, 0.001, on an energy error
    from 1.1e-4 to 6.5e-3; the app's ticks stopped at 0.001 too); within a decade round steps."""
    path = tmp_path / "decades.html"
    x = [0.0, 1.0, 2.0, 3.0]
    figures = [Figure("f", "t", "y", [Series("a", x, [1e-5, 1e-2, 1e1, 1e6])], logy=True),
               Figure("g", "t", "y", [Series("a", x, [1e-2, 1e-1, 1e0, 1e4])], logy=True),
               Figure("h", "t", "y", [Series("a", x, [1.1e-4, 1e-3, 3e-3, 6.5e-3])], logy=True),
               Figure("i", "t", "y", [Series("a", x, [2.1e-3, 2.5e-3, 3e-3, 3.9e-3])], logy=True)]
    path.write_text(render(Report("decades", [], [Section("s", [], figures)])))
    _, errors, drawn, answers = open_offline(path, "report-decades.png", js="() => cosympPlots.map(u => u.axes[1]._values)")
    assert errors == [] and drawn == 4
    assert answers["js"] == [["1e-5", "0.001", "0.1", "10", "1000", "1e5"],
                             ["0.01", "0.1", "1", "10", "100", "1000", "10000"],
                             ["1e-4", "2e-4", "5e-4", "0.001", "0.002", "0.005"],
                             ["0.0025", "0.003", "0.0035", "0.004"]]


ORDER_JS = """() => cosympPlots.map(u => ({
    drawn: u.series.slice(1).map(s => [s.label, s.dash ? "dashed" : "solid"]),
    legend: Array.from(u.root.querySelectorAll(".u-legend .u-series")).map(r => r.textContent.replace(/[:–]/g, ""))
        .filter(t => t && t !== "t")}))"""


def test_the_report_draws_the_first_method_over_the_second(tmp_path):
    """As the app does: the first method (A) solid and translucent on top of the second (B), dashed
    (RK4 hid midpoint's whole phase portrait); the legends list A first."""
    path = tmp_path / "modulated.html"
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", "modulated", "--method", "midpoint", "--vs", "rk4", "--T", "20", "-o", str(path)],
                out, err) == 0, err.getvalue()
    spec = json.loads(re.search(r'id="figures" type="application/json">(.*?)</script>', path.read_text(),
                                re.DOTALL).group(1).replace("<\\/", "</"))
    assert all([s["alpha"] for s in f["series"]] == [0.7, 1.0] for f in spec)
    # the reference's own uncertainty, eight decades below both errors here: not drawn (it squeezed them
    # into the plot's top), said instead
    assert "Below every error drawn: the reference&#x27;s own uncertainty" in path.read_text()
    requests, errors, drawn, answers = open_offline(path, "report-order.png", js=ORDER_JS)
    assert requests == [] and errors == [] and drawn == len(spec) == len(answers["js"])
    for plot in answers["js"]:
        assert plot["drawn"] == [["rk4", "dashed"], ["midpoint", "solid"]], "uPlot draws the last on top"
        assert plot["legend"] == ["midpoint", "rk4"]


def test_the_references_uncertainty_is_drawn_beneath_the_errors_where_it_reaches_them(tmp_path):
    """charged, beta(t) = exp(t), T = 8.2: the reference's uncertainty rises through both errors (its
    step too long for the gyration 2e^t). The trajectory error figure draws it, dashed grey, beneath
    the two methods and last in the legend, and only within the errors' range (up to 10x the
    largest: it reaches 1.6e96); the caption says what it is."""
    path = tmp_path / "charged.html"
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", "charged", "--vs", "gauss4", "--set", "beta=exp(t)", "--h", "0.001", "--T", "8.2",
                 "-o", str(path)], out, err) == 0, err.getvalue()
    text = path.read_text()
    spec = json.loads(re.search(r'id="figures" type="application/json">(.*?)</script>', text,
                                re.DOTALL).group(1).replace("<\\/", "</"))
    own = "the reference's own uncertainty"
    error = next(i for i, f in enumerate(spec) if f["title"].startswith("Trajectory error"))
    assert [len(f["series"]) for f in spec] == [3 if i == error else 2 for i in range(len(spec))]
    drawn_own = [y for y in spec[error]["series"][2]["y"] if y is not None]
    largest = max(y for s in spec[error]["series"][:2] for y in s["y"] if y is not None)
    assert drawn_own and max(drawn_own) <= 10 * largest and spec[error]["series"][2]["y"][-1] is None
    assert "The grey line is the reference&#x27;s own uncertainty" in text
    requests, errors, drawn, answers = open_offline(path, "report-own.png", js=ORDER_JS)
    assert requests == [] and errors == [] and drawn == len(spec)
    plot = answers["js"][error]
    assert plot["drawn"] == [[own, "dashed"], ["gauss4", "dashed"], ["midpoint", "solid"]]
    assert plot["legend"] == ["midpoint", "gauss4", own]


def test_the_quick_paper_report_has_every_section():
    """The paper report without its long runs and work-precision diagram (the slow tier renders
    and opens the whole one)."""
    from cosymp.report.paper import paper_report

    report = paper_report(long=False, work_precision=False)
    assert [s.title.split(":")[0] for s in report.sections] == ["Section 4.1", "Section 4.2", "Section 5",
                                                                "Work against precision"]
    for section in report.sections[:3]:
        figures = [i for i in section.items if isinstance(i, Figure)]
        assert figures and all(f.series for f in figures), section.title
        assert all(np.isfinite(np.asarray(s.y, float)).any() for f in figures for s in f.series), section.title


@pytest.mark.slow
def test_paper_report(tmp_path):
    path = tmp_path / "paper.html"
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", "paper", "-o", str(path)], out, err) == 0, err.getvalue()
    size = path.stat().st_size
    assert size < PAPER_MAX_BYTES
    text = path.read_text()
    for needle in ("Section 4.1", "Section 4.2", "Section 5", "T = 500000", "T = 200000", "Work against precision",
                   "Landau", "Lorenz", "Π_x", "scipy-DOP853"):
        assert needle in text, needle
    # At the paper's parameters RK4's drift is still inside symplectic Euler's band at T in both long runs
    # (|H + p_t| 0.068 against 0.095 at 5e5; 0.028 against 0.096 at 2e5): the captions say so.
    assert html.unescape(text).count("is still inside the symplectic scheme's band") == 2
    requests, errors, drawn, _ = open_offline(path, "report-paper.png")
    assert requests == [] and errors == []
    assert drawn == 28


def test_bad_report_input_is_one_line():
    for argv, says in ((["report", "damped", "-o", "x.txt"], "name an .html file"),
                       (["report", "damped", "-o", "/nonexistent/dir/x.html"], "not a writable folder"),
                       (["report", "nowhere", "-o", "x.html"], "unknown scene"),
                       (["report", "damped", "--vs", "boris", "-o", "x.html"], "pushes a charge"),
                       (["report", "damped"], "required")):
        out, err = io.StringIO(), io.StringIO()
        assert main(argv, out, err) == 2
        assert says in err.getvalue() and err.getvalue().count("\n") == 1


def test_a_report_says_what_it_compiles_and_computes_on_stderr(tmp_path, monkeypatch):
    """On a cold cache the paper report printed nothing for minutes: the kernels it needs and the cache
    lacks (here two units said to be missing, one it does not need) are compiled with a line each,
    then a line per stage; stdout keeps its one line."""
    from cosymp import warm

    units = {u.key: u for u in warm.units()}
    monkeypatch.setattr(warm, "missing", lambda: [units["decaying/Theta"], units["kapitza/Gauss"]])
    path = tmp_path / "decaying.html"
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", "decaying", "-o", str(path)], out, err) == 0, err.getvalue()
    assert out.getvalue() == f"report written to {path} ({path.stat().st_size / 1e6:.2f} MB)\n"
    lines = err.getvalue().splitlines()
    assert lines[0].startswith("cosymp: compiling 1 groups of kernels") and "decaying × Theta" in lines[0]
    assert "[  1/1]" in lines[1] and "compiled decaying × Theta" in lines[1]
    assert [line.split("] ", 1)[1] for line in lines[2:]] == [
        "midpoint: run and diagnostics", "midpoint: reference", "rk4: run and diagnostics", "rk4: reference", "done"]


def test_a_kernel_that_fails_to_compile_is_one_line_and_exit_3(monkeypatch):
    from cosymp import warm

    bad = warm.Unit("nowhere/Family", "nowhere", ("none",))
    monkeypatch.setattr(warm, "missing", lambda: [bad])
    monkeypatch.setattr(warm, "unit_keys", lambda scene, methods: [bad.key])
    out, err = io.StringIO(), io.StringIO()
    assert main(["report", "decaying", "-o", "x.html"], out, err) == 3
    last = err.getvalue().splitlines()[-1]
    assert last.startswith("cosymp: 1 of 1 groups of kernels failed to compile, e.g. nowhere/Family")
    assert "Traceback" not in err.getvalue() and out.getvalue() == ""


def test_the_paper_reports_kernels_are_compiled_ahead(monkeypatch):
    """Every setup the paper report runs (its sections, and the work-precision runs on a tiny
    horizon) is in a unit that `cosymp report paper` compiles first."""
    from cosymp import warm
    from cosymp import workprecision as wp
    from cosymp.integrate import Setup
    from cosymp.report.paper import WP_METHODS, kernels, paper_report

    made = set()
    make = Setup.make.__func__

    def recording(cls, *args, **kwargs):
        setup = make(cls, *args, **kwargs)
        made.add(warm.key_of(setup))
        return setup

    monkeypatch.setattr(Setup, "make", classmethod(recording))
    paper_report(long=False, work_precision=False)
    for name in ("damped", "modulated"):
        wp.measure(name, applicable(WP_METHODS, SCENES[name]), T=1.0, hs=[0.5], peers=True, rtols=[1e-3], budget=0.0)
    ahead = {k for scene, methods in kernels().items() for k in warm.unit_keys(scene, methods)}
    assert made <= ahead, made - ahead
    assert {k for scene, methods in kernels(work_precision=False).items() for k in warm.unit_keys(scene, methods)} < ahead


def test_app_report_uses_the_views_runs():
    from app.study import Study, study_report

    study = Study(scene="decaying", method="symplectic-euler")
    text = study_report(study)
    assert "cosymp report decaying --method symplectic-euler --vs rk4" in text and 'id="figures"' in text


def test_a_run_that_stopped_has_no_error_at_T_in_the_report_as_in_the_app():
    """'Kapitza: Newton fails': midpoint stops at t = 22.5 of 100. The app's table shows no final
    error; the report gave 27.3 (the error where it stopped) in the same column."""
    from app.study import Study, study_report

    study = Study(scene="kapitza", method="midpoint", other="rk4", h=0.5, T=100.0,
                  values={"q0": 3.0, "a": 0.3, "nu": 40.0})
    midpoint, rk4 = study.results.entries
    assert midpoint.failure and midpoint.final_error is None and rk4.final_error is not None
    table = study_report(study).split("<caption>Figures over every step")[1].split("</table>")[0]
    rows = {r[0]: r for r in (re.findall(r"<td[^>]*>(.*?)</td>", row) for row in table.split("<tr>")) if r}
    assert rows["midpoint"][4] == "–" and rows["rk4"][4] == f"{rk4.final_error:.3g}", rows


def test_the_volume_estimator_is_named_for_the_scenes_2n_plus_1_increments():
    """The charged particle (two degrees of freedom) has five increments, not three."""
    from cosymp.report.scene import volume_name

    names = {name: volume_name(s) for name, s in SCENES.items()}
    assert names["charged"] == "det[X¹ … X⁵]"
    assert all(v == "det[X¹ X² X³]" for k, v in names.items() if SCENES[k].ndof == 1)


def cie_lab(color):
    """CIE L*a*b* (D65) of an sRGB '#rrggbb'."""
    rgb = [int(color[i:i + 2], 16) / 255 for i in (1, 3, 5)]
    r, g, b = (c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb)
    xyz = ((0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047, 0.2126 * r + 0.7152 * g + 0.0722 * b,
           (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883)
    fx, fy, fz = (t ** (1 / 3) if t > 0.008856 else 7.787 * t + 16 / 116 for t in xyz)
    return 116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)


def ciede2000(lab1, lab2):
    """The CIEDE2000 colour difference of two CIE L*a*b* colours (Sharma, Wu and Dalal, 2005)."""
    (L1, a1, b1), (L2, a2, b2) = lab1, lab2
    C = (math.hypot(a1, b1) + math.hypot(a2, b2)) / 2
    G = 0.5 * (1 - math.sqrt(C ** 7 / (C ** 7 + 25 ** 7)))
    a1, a2 = (1 + G) * a1, (1 + G) * a2
    C1, C2 = math.hypot(a1, b1), math.hypot(a2, b2)
    h1, h2 = (math.degrees(math.atan2(b, a)) % 360 if c else 0.0 for a, b, c in ((a1, b1, C1), (a2, b2, C2)))
    dh = 0.0 if C1 * C2 == 0 else (h2 - h1 + 180) % 360 - 180
    dH = 2 * math.sqrt(C1 * C2) * math.sin(math.radians(dh / 2))
    L, Cm = (L1 + L2) / 2, (C1 + C2) / 2
    if C1 * C2 == 0:
        h = h1 + h2
    elif abs(h1 - h2) <= 180:
        h = (h1 + h2) / 2
    else:
        h = (h1 + h2 + 360) / 2 if h1 + h2 < 360 else (h1 + h2 - 360) / 2
    T = (1 - 0.17 * math.cos(math.radians(h - 30)) + 0.24 * math.cos(math.radians(2 * h))
         + 0.32 * math.cos(math.radians(3 * h + 6)) - 0.20 * math.cos(math.radians(4 * h - 63)))
    SL = 1 + 0.015 * (L - 50) ** 2 / math.sqrt(20 + (L - 50) ** 2)
    SC, SH = 1 + 0.045 * Cm, 1 + 0.015 * Cm * T
    RT = (-math.sin(math.radians(60 * math.exp(-(((h - 275) / 25) ** 2))))
          * 2 * math.sqrt(Cm ** 7 / (Cm ** 7 + 25 ** 7)))
    dL, dC = (L2 - L1) / SL, (C2 - C1) / SC
    return math.sqrt(dL ** 2 + dC ** 2 + (dH / SH) ** 2 + RT * dC * dH / SH)


def distance(a, b):
    return ciede2000(cie_lab(a), cie_lab(b))


def sharing_a_plot():
    """The pairs of methods whose colours can share a plot: every two methods that apply to one
    scene (its work-precision plot shows them all, with scipy's solvers), the exact flow with any
    of them (a comparison pairs it with any method; never with scipy's, it is their reference)."""
    peers = [m for m in METHOD_COLORS if m.startswith("scipy-")]
    pairs = set()
    for scene in SCENES.values():
        applies = applicable(METHODS, scene)
        pairs |= {frozenset(p) for p in itertools.combinations([m for m in applies if m != "exact"] + peers, 2)}
        pairs |= {frozenset(("exact", m)) for m in applies if m != "exact"}
    return pairs


def test_every_method_has_a_colour_far_from_every_method_it_can_share_a_plot_with():
    """CIEDE2000, not CIE76: the previous palette kept every CIE76 distance above 25, and yet rk4
    and composition6 read as one red, symplectic-euler and leapfrog as one teal, gauss4 and boris as
    one green, composition4 and blanes-moan6 as one violet in a work-precision plot; their CIEDE2000
    distances, 11 to 20.5, are all below MIN_DISTANCE."""
    assert set(METHODS) <= set(METHOD_COLORS)
    assert cie_lab("#ffffff") == pytest.approx((100, 0, 0), abs=0.05)
    for lab1, lab2, known in (((50, 2.6772, -79.7751), (50, 0, -82.7485), 2.0425),  # Sharma et al., pairs 1, 7, 17, 25
                              ((50, 0, 0), (50, -1, 2), 2.3669), ((50, 2.5, 0), (73, 25, -18), 27.1492),
                              ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644)):
        assert ciede2000(lab1, lab2) == pytest.approx(known, abs=1e-4)
    alike = {("rk4", "composition6"): ("#e03131", "#d6336c"), ("symplectic-euler", "leapfrog"): ("#15aabf", "#00c6a4"),
             ("gauss4", "boris"): ("#2b8a3e", "#5c940d"), ("composition4", "blanes-moan6"): ("#9775fa", "#bb88cc")}
    for pair, (a, b) in alike.items():
        assert math.dist(cie_lab(a), cie_lab(b)) > 25 and distance(a, b) < MIN_DISTANCE, pair
    pairs = sharing_a_plot()
    assert frozenset(("boris", "leapfrog")) not in pairs and frozenset(("boris", "gauss4")) in pairs
    close = {tuple(sorted(p)): round(distance(*(METHOD_COLORS[m] for m in p)), 1) for p in pairs
             if distance(*(METHOD_COLORS[m] for m in p)) < MIN_DISTANCE}
    assert not close, close


def test_every_family_has_a_marker_of_its_own():
    """Each family of methods (the kernel family of its data) and scipy's solvers have their own
    marker, the same for every member, in the app's work-precision plots and the paper report's."""
    families = {}
    for m in METHODS:
        families.setdefault(type(METHODS[m].data()).__name__, set()).add(method_marker(m))
    assert all(len(markers) == 1 for markers in families.values()), families
    shapes = [next(iter(markers)) for markers in families.values()] + [method_marker("scipy-DOP853")]
    assert len(set(shapes)) == len(shapes) == len(FAMILY_MARKERS)
    assert method_marker("theta(0.3)") == method_marker("midpoint") == "circle" and method_marker("rk4") == "triangle"


def test_the_apps_report_lists_the_parameters_in_effect_and_is_named_for_its_run():
    """A typed beta(t) leaves B0, eps and w without effect (the app disables them): the report's
    table leaves them out and says so; the paper's beta(t) uses all three."""
    from app.study import Study, report_filename, study_report

    def rows(study):
        return re.findall(r"<tr><td>(\w+)</td>", study_report(study).split("<caption>Figures")[0])

    study = Study(scene="charged", T=1.0, values={"beta": "cos(t)"})
    assert {"m", "e", "beta", "gauge"} <= set(rows(study)) and not {"B0", "eps", "w"} & set(rows(study))
    assert "(B0, eps, w: no effect with these values)" in study_report(study)
    study.values = {"beta": "paper"}
    assert {"B0", "eps", "w", "beta"} <= set(rows(study))
    assert report_filename(study) == "cosymp-charged-midpoint.html"
    assert "-o cosymp-charged-midpoint.html" in study_report(study)
