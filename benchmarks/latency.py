"""Browser latency of the cosymp app: how long after an input every visible plot shows the new data.

    python benchmarks/latency.py [--repo DIR] [--url URL] [--repeats N] [--skip-load] [--only PART...] [--json FILE]

Without --url it serves the app of the repository DIR (default: the one holding this script) the
way the README does (`python -m panel serve app --setup app/warmup.py` on a free loopback port,
cwd and PYTHONPATH = DIR, with this interpreter), waits for /liveness (up to 600 s: a cold numba
cache compiles first) and stops the server at the end. Headless Chromium (/usr/bin/chromium) is
driven with Playwright's sync API; every page gets its own browser context.

How a page is timed (all in the page, on its performance.now() clock, so the Python side and the
Playwright round trips do not enter the numbers):

* Inputs: capture-phase listeners on window record keydown, pointerdown/move/up and input events
  (Panel renders its widgets in shadow DOM; these events are composed, so they reach window).
* Counted events: every Bokeh document of the page (`Bokeh.documents`) is hooked with
  `doc.on_change(callback)` as soon as it exists. Patches from the server do reach that callback
  (BokehJS applies them with setv/stream_to/patch_to and sync = false; checked in the live page:
  the app's plot updates arrive as ColumnDataSource.data, Range1d and Figure events, tab contents
  and rebuilt layouts as Tabs.tabs and Column.children). An event counts when it came from the
  server (sync false) and changes what is shown: it sets, streams or patches a data source of a
  shown plot (images included), sets a property of a shown plot's part (the Plot, its renderers,
  glyphs, ranges, scales, tickers, formatters, colour mappers, data sources), adds, removes or
  replaces models in a shown component (a property set to models: new plots may come in them), or
  adds or removes roots. (The app builds hidden tabs ahead and fills their plots while the page is
  idle; those messages change nothing shown.) Layout read-backs from the browser
  (Figure.inner_width, sync true), widget values, HTML text and the busy spinner do not count.
  A "drawn" event is added at the paint of a Plot view that shows it visible and finished, the
  first such paint since the input (a new page's plots, the new plots of a rebuilt layout or a
  tab, and hidden plots shown again, such as a tab built earlier or the figures of another
  scene's shape, which may get their data while hidden): BokehJS's PlotView paint is hooked, and
  the plots shown and finished at the input are the starting point. Nothing polls every view (a
  poller that did took a third of the main thread on a page with 1,500 views, slowing what it
  measured).
* Each counted event also records the next requestAnimationFrame callback after it: its paint.
  (After a layout swap that frame can come 0.4-2 s later: the main thread is building views.)
* Settled: at least one counted event after the input; then the last counted event painted, no
  Bokeh root view still building (every root view's has_finished(): new models get their views
  asynchronously after the event that brought them), no counted event for 2 s after that paint,
  and every visible plot different from its fingerprint taken before the input (its data sources'
  columns, sampled, and its ranges; a plot that is new counts as different). The settled time is
  the paint of the last counted event. Why not just "no event for 600 ms": without the fingerprint
  condition that rule stopped in most scene changes while the server was still computing (the
  scene text had been swapped, no plot had changed yet), and even with it, in about one scene
  change in ten, the data reached the old plots and the layout was rebuilt with the new scene's
  plots more than 600 ms later. The table shows how many updates paused for more than 600 ms
  (between a counted event's paint and the next one). The last counted event must come within
  20 s of the input, else the result is "nochange" (no counted event), "timeout" (events still
  arriving) or "plots unchanged" (quiet, but a visible plot is as it was), reported as such and
  never as a number.
* First change: the first counted event after the input that changes a plot itself (data, plot
  part or drawn; not a layout swap). For a fresh page: the first plot drawn, from navigation start.
* Before each input the page must be quiet (no counted event for 600 ms after the last paint, no
  view building), else the measurement is reported as not quiet.

Actions: fresh pages at the app's own first view (navigation to first plot drawn / settled; on a
server this run started, its very first page apart: see run_first_page), then on a page opened at ?scene=damped: the scene changed to each scene and back to damped, the method
changed (midpoint -> gauss4 -> symplectic-euler -> midpoint), the gamma slider dragged (first move
to first change, last move to settled), θ moved by 20 ArrowRight presses with the Lifted theta-
method (first press to first change, last press to settled); the first visit of each tab on a fresh
page at the first view (once the page is quiet, and READ_S seconds later: the app builds tabs
ahead while the page is idle); and a load: ten damped pages each move gamma by one key press at most every 2 s (closed loop: a move waits
until the page's previous move settled, so each latency belongs to one move and a slow server gets
fewer moves) for 60 s while an eleventh page runs a long run (LONG_QUERY); its progress bar (a
<progress>) is read every 5 s and its counted events are kept (the run redraws its plots as chunks
arrive).

Widgets are found by their visible label text, not by the app's classes: the nearest <select> or
role=slider element to a visible element whose whole text is the label (or "label: value"), the
distance measured up and down the composed tree (across shadow roots). Options are chosen by
what their text contains (the scene and method titles). A locator that fails saves a screenshot
and the action is reported as failed.
"""
import argparse
import collections
import contextlib
import json
import os
import pathlib
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request

from playwright.sync_api import Error as PlaywrightError
from playwright.sync_api import sync_playwright

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
VIEWPORT = {"width": 1400, "height": 1600}
START_TIMEOUT_S = 600        # a cold numba cache compiles every kernel before the server answers
PAGE_TIMEOUT_MS = 120_000    # navigation to the first plot drawn and settled
QUIET_MS = 600               # quiet before an input; a longer gap within an update is a "pause"
SETTLE_TIMEOUT_MS = 20_000   # from the input
QUIET_TIMEOUT_MS = 60_000    # waiting for a quiet page before an input
CONFIRM_MS = 2_000           # settled: no counted event for this long after the last one's paint

SCENE_HOME = "damped"        # interactions and the load start here (?scene=damped; the first view may differ)
# Scene -> text its option shows (lower case; the key itself matches an option value or text too).
SCENES = {"decaying": ["decaying"], "modulated": ["modulated", "time-dependent potential"],
          "charged": ["charged"], "kapitza": ["kapitza"], "damped": ["damped"]}
METHODS = {"midpoint": ["implicit midpoint"], "gauss4": ["gauss-legendre 4"],
           "symplectic-euler": ["symplectic euler"], "theta": ["lifted theta"]}
METHOD_SEQUENCE = ["gauss4", "symplectic-euler", "midpoint"]   # from the default, midpoint
TABS = ["Structure", "Cloud", "Gauges", "Theta lesson", "Play", "Long run", "Work–precision",
        "Stability map"]
DRAG_MOVES, DRAG_STEP_PX, DRAG_PAUSE_S = 5, 6, 0.1
THETA_PRESSES = 20

PARTS = ("first", "interactions", "tabs", "load")
LOAD_PAGES = 10
LOAD_SECONDS = 60
READ_S = 5                   # a tab's first visit is also timed this long after the page is quiet
LOAD_INTERVAL_S = 2.0
LOAD_MOVE_TIMEOUT_MS = 60_000
LOAD_POLL_S = 0.25           # how often a page with a move under way is asked whether it settled
LOAD_PROGRESS_EVERY_S = 5.0
LONG_RECENT_S = 10           # the long run counts as progressing if its page got plot events this recently
# The long run beside the load: tests/test_load.py's, gauss6 against rk4 on the Kapitza pendulum at h =
# 0.005 to T = 1e5 (2e7 steps per method, minutes: Newton iterations and complex-step tangent maps). The
# paper's damped run, used before, now ends in seconds, before the load starts.
# The page opens at Orbits and the run starts when the Long run tab is shown: a page opened at
# view=long would be waited for until settled, and the run redraws until it ends, so it would end
# before the load began.
LONG_QUERY = {"scene": "kapitza", "method": "gauss6", "vs": "rk4", "h": "0.005", "T": "20", "T_long": "1e5"}

# Installed in every page before its scripts run (see the module docstring).
INSTRUMENT_JS = """(() => {
  if (window.__latency) return;
  const QUIET = QUIET_MS, CONFIRM = CONFIRM_MS;
  const VISIBLE = {visibilityProperty: true, opacityProperty: true};
  const PART_NAMES = ["DataSource", "CDSView", "Plot", "Renderer", "Glyph", "Range", "Scale", "Ticker",
                      "TickFormatter", "ColorMapper"];
  const L = window.__latency = {inputs: [], events: [], lastEvent: -Infinity,
                                before: {}};
  for (const type of ["keydown", "pointerdown", "pointermove", "pointerup", "input"])
    window.addEventListener(type, () => L.inputs.push([type, performance.now()]), true);

  // Counted events: [time, what, paint time (the next animation frame), changes a plot itself].
  const record = (what, plot, painted) => {
    const e = [performance.now(), what, null, plot];
    if (painted) e[2] = e[0];
    else requestAnimationFrame(() => { e[2] = performance.now(); });
    L.events.push(e);
    L.lastEvent = e[0];
  };
  let parts = null;
  const isModel = (v) => v != null && typeof v === "object" && typeof v.id === "string"
                         && typeof v.attach_document === "function";
  const hasModels = (v, depth) => isModel(v) || (depth < 3 && (
      Array.isArray(v) ? v.some((x) => hasModels(x, depth + 1))
      : v instanceof Map ? [...v.values()].some((x) => hasModels(x, depth + 1)) : false));
  // What is shown when a message is applied: the models of the shown plots (each plot and every
  // model it refers to), and the models with a shown view. Taken once per message (it reads the
  // page's layout), while its first event is handled.
  let seen = null;
  const seeing = () => {
    if (seen === null) {
      const inPlots = new Set(), withView = new Set();
      for (const v of plotViews()) {
        inPlots.add(v.model);
        for (const m of v.model.references()) inPlots.add(m);
      }
      for (const v of Bokeh.index.all_views()) if (v.el instanceof Element && shown(v.el)) withView.add(v.model);
      seen = {inPlots, withView};
      queueMicrotask(() => { seen = null; });
    }
    return seen;
  };
  const onChange = (e) => {
    if (e.sync !== false) return;   // made in the browser, not applied from the server
    if (["ColumnsStreamed", "ColumnsPatched", "ColumnDataChanged"].includes(e.kind)) {
      if (seeing().inPlots.has(e.model)) record(e.kind, true, false);
    } else if (["RootAdded", "RootRemoved"].includes(e.kind)) {
      record(e.kind, false, false);
    } else if (e.kind === "ModelChanged") {
      const part = parts.some((c) => e.model instanceof c), graph = hasModels(e.value, 0);
      const {inPlots, withView} = (part || graph) ? seeing() : {};
      const counts = part ? inPlots.has(e.model) : graph && withView.has(e.model);
      if (counts) record((graph ? "models:" : "") + e.model.type + "." + e.attr, part, false);
    }
  };
  // Shown: laid out, and not hidden by display, visibility (inactive Bokeh tabs) or opacity.
  const shown = (el) => {
    if (!el.isConnected || !el.checkVisibility(VISIBLE)) return false;
    const r = el.getBoundingClientRect();
    return r.width > 0 && r.height > 0;
  };
  const plotViews = () => {
    const Plot = Bokeh.Models.get("Plot");
    return [...Bokeh.index.all_views()].filter((v) => v.model instanceof Plot && shown(v.el));
  };
  // True while a root view has views that are not built and painted yet (new models being shown).
  const building = () => window.Bokeh !== undefined && Bokeh.index !== undefined
                         && ![...Bokeh.index].every((v) => v.has_finished());
  // The plot views shown and painted at the poller's last look: a plot counts as drawn when it joins.
  const hooked = new WeakSet();
  let showing = new WeakSet();
  // A plot counts as drawn at the paint that shows it finished, the first since the input (arm):
  // PlotView's paint is hooked, so that only plots that paint are looked at. (Looking at every view
  // every frame, as before, took a third of the main thread while a tab with 1,500 views was shown,
  // and so slowed what it measured.) A plot that paints before it has finished is looked at again
  // every frame until it has.
  const pending = new Set();
  const drawn = (v) => {
    if (!v.el.isConnected || showing.has(v) || !shown(v.el)) return true;
    if (!v.has_finished()) return false;
    showing.add(v);
    record("drawn:" + v.model.type, true, true);
    return true;
  };
  const hookPaint = (B) => {
    const PlotView = B.require("models/plots/plot").PlotView, paint = PlotView.prototype._actual_paint;
    PlotView.prototype._actual_paint = function (...args) {
      const out = paint.apply(this, args);
      if (drawn(this)) pending.delete(this);
      else pending.add(this);
      return out;
    };
  };
  // Hook BokehJS (every frame until it is loaded) and new documents (every 50 ms); every frame while
  // a painted plot has not finished.
  const tick = () => {
    const B = window.Bokeh;
    if (B && B.documents && B.index && B.Models && typeof B.require === "function") {
      if (parts === null) {
        parts = PART_NAMES.map((n) => B.Models.get(n)).filter((c) => c != null);
        hookPaint(B);
        const Plot = B.Models.get("Plot");  // plots painted before the hook
        for (const v of B.index.all_views()) if (v.model instanceof Plot && !drawn(v)) pending.add(v);
      }
      for (const doc of B.documents) if (!hooked.has(doc)) {
        hooked.add(doc);
        doc.on_change(onChange, false);
        record("document", false, false);
      }
      for (const v of [...pending]) if (drawn(v)) pending.delete(v);
    }
    if (pending.size || parts === null) requestAnimationFrame(tick);
    else setTimeout(tick, 50);
  };
  requestAnimationFrame(tick);

  // {plot model id: fingerprint} of the visible plots: their data columns (sampled) and ranges.
  const digest = (col) => {
    if (col == null || typeof col !== "object") return String(col);
    const n = col.length ?? 0, stride = Math.max(1, Math.floor(n / 2000));
    let sum = 0;
    const nested = [];
    for (let i = 0; i < n; i += stride) {
      const x = col[i];
      if (typeof x === "number") sum += Number.isFinite(x) ? x * (1 + (i % 7)) : 1;
      else if (x != null && typeof x === "object" && nested.length < 4) nested.push(digest(x));
      else sum += String(x).length;
    }
    return n + ":" + sum.toPrecision(12) + (nested.length ? "[" + nested.join(",") + "]" : "");
  };
  L.plots = () => {
    const out = {};
    for (const v of plotViews()) {
      const columns = [];
      for (const r of v.model.renderers) {
        const data = r.data_source && r.data_source.data;
        if (data == null) continue;
        for (const [k, col] of (data instanceof Map ? data : Object.entries(data)))
          columns.push(k + "=" + digest(col));
      }
      for (const range of [v.model.x_range, v.model.y_range]) columns.push(range.start + "," + range.end);
      out[v.model.id] = columns.join("|");
    }
    return out;
  };
  // Before an input: remember the plots and which are shown and finished (a plot shown after it, as
  // a tab built earlier and hidden, counts as drawn when it paints); returns the time to look for
  // inputs from.
  L.arm = () => {
    L.before = L.plots();
    showing = new WeakSet(plotViews().filter((v) => v.has_finished()));
    return performance.now();
  };

  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  // When the page became quiet (the last counted event painted, no view building), or null.
  const quietSince = () => {
    if (building()) return null;
    const last = L.events[L.events.length - 1];
    return last === undefined ? -Infinity : last[2];
  };
  L.lastInputOf = (type) => {
    for (let i = L.inputs.length - 1; i >= 0; i--) if (L.inputs[i][0] === type) return L.inputs[i][1];
    return null;
  };
  L.inputsAfter = (t0) => L.inputs.filter((e) => e[1] > t0);
  // The counted events after t0, and their state: settled (the last one painted at most `timeout`
  // ms after t0, then CONFIRM ms with no counted event and no view building, a plot drawn if
  // needDrawn, and every visible plot different from its fingerprint at arm() if needChanged),
  // pending, or, at timeout + CONFIRM ms: nochange (no counted event), plots unchanged (quiet, but
  // a visible plot is as before) or timeout (still changing). pauses: gaps of more than QUIET ms
  // between a counted event's paint and the next one (where a plain QUIET rule would have stopped).
  L.status = (t0, timeout, needDrawn, needChanged) => {
    const now = performance.now();
    let i = L.events.length;
    while (i > 0 && L.events[i - 1][0] > t0) i--;
    const after = L.events.slice(i), last = after[after.length - 1];
    const plotEvents = after.filter((e) => e[3]), drawnAfter = after.filter((e) => e[1].startsWith("drawn"));
    const out = {n: after.length, first: plotEvents.length ? plotEvents[0][0] : null,
                 first_drawn: drawnAfter.length ? drawnAfter[0][0] : null,
                 last: last ? last[0] : null, paint: last ? last[2] : null, now,
                 pauses: after.filter((e, k) => k > 0 && e[0] - (after[k - 1][2] ?? after[k - 1][0]) > QUIET)
                              .length};
    const since = quietSince(), timedOut = now - t0 >= timeout + CONFIRM;
    const quiet = last !== undefined && (!needDrawn || drawnAfter.length > 0) && since !== null
                  && now - since >= CONFIRM;
    if (quiet || timedOut) {
      const plots = L.plots(), ids = Object.keys(plots);
      out.plots_visible = ids.length;
      out.plots_changed = ids.filter((id) => L.before[id] !== plots[id]).length;
    }
    const settled = quiet && last[2] - t0 <= timeout
                    && (!needChanged || out.plots_changed === out.plots_visible);
    out.state = settled ? "settled" : !timedOut ? "pending" : last === undefined ? "nochange"
                : quiet && out.plots_changed < out.plots_visible ? "plots unchanged" : "timeout";
    return out;
  };
  L.waitSettled = async (t0, timeout, needDrawn, needChanged) => {
    for (;;) {
      const s = L.status(t0, timeout, needDrawn, needChanged);
      if (s.state !== "pending") return s;
      await sleep(20);
    }
  };
  L.waitQuiet = async (timeout) => {
    const t0 = performance.now();
    for (;;) {
      const since = quietSince();
      if (since !== null && performance.now() - since >= QUIET) return true;
      if (performance.now() - t0 > timeout) return false;
      await sleep(20);
    }
  };
})();""".replace("QUIET_MS", str(QUIET_MS)).replace("CONFIRM_MS", str(CONFIRM_MS))

# The visible element matching `selector` nearest to a visible element whose whole (light-DOM)
# text matches `pattern`: fewest steps up from both to a common ancestor, across shadow roots.
NEAREST_JS = """([pattern, selector]) => {
  const re = new RegExp(pattern);
  const all = [];
  const walk = (root) => {
    for (const el of root.querySelectorAll("*")) {
      all.push(el);
      if (el.shadowRoot) walk(el.shadowRoot);
    }
  };
  walk(document);
  const shown = (el) => {
    if (!el.checkVisibility({visibilityProperty: true, opacityProperty: true})) return false;
    const r = el.getBoundingClientRect();
    return r.width > 0 && r.height > 0;
  };
  const text = (el) => (el.textContent || "").replace(/\\s+/g, " ").trim();
  const matching = all.filter((el) => re.test(text(el)) && shown(el));
  const labels = matching.filter((el) => !matching.some((o) => o !== el && el.contains(o)));
  const up = (el) => el.parentNode instanceof ShadowRoot ? el.parentNode.host : el.parentElement;
  const targets = all.filter((el) => el.matches(selector) && shown(el));
  let best = null;
  for (const label of labels) {
    const chain = [];
    for (let x = label; x; x = up(x)) chain.push(x);
    for (const t of targets) {
      let d = 0;
      for (let x = t; x; x = up(x), d++) {
        const i = chain.indexOf(x);
        if (i >= 0) {
          if (best === null || i + d < best.score) best = {score: i + d, el: t};
          break;
        }
      }
    }
  }
  return best && best.el;
}"""

# Values of the options of a <select> whose value or text is the key, or whose text contains a needle.
OPTIONS_JS = """(sel, [key, needles]) => [...sel.options]
  .filter((o) => o.value === key || o.text.trim() === key
                 || needles.some((n) => o.text.toLowerCase().includes(n)))
  .map((o) => o.value)"""
OPTION_TEXTS_JS = "(sel) => [...sel.options].map((o) => o.text.trim())"
PROGRESS_JS = """() => {
  const walk = (root) => {
    for (const el of root.querySelectorAll("*")) {
      if (el.tagName === "PROGRESS" && el.checkVisibility({visibilityProperty: true, opacityProperty: true}))
        return el;
      const inner = el.shadowRoot && walk(el.shadowRoot);
      if (inner) return inner;
    }
    return null;
  };
  const p = walk(document);
  return p && p.hasAttribute("value") ? p.value / p.max : null;
}"""


class Located(LookupError):
    """A widget or tab was not found by its label (a screenshot was saved)."""


# ---------------------------------------------------------------------------- server


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def served(repo):
    """`panel serve app --setup app/warmup.py` from repo on a free port; yields the app's URL."""
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(repo)}
    with tempfile.NamedTemporaryFile("w", prefix="latency-server-", suffix=".log", delete=False) as log:
        yield from _serving(repo, port, env, log)


def _serving(repo, port, env, log):
    proc = subprocess.Popen([sys.executable, "-m", "panel", "serve", "app", "--setup", "app/warmup.py",
                             "--address", "127.0.0.1", "--port", str(port),
                             "--allow-websocket-origin", f"127.0.0.1:{port}", "--liveness"],
                            cwd=repo, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        t0 = time.monotonic()
        print(f"server: starting from {repo} on port {port} (log {log.name})", flush=True)
        while True:
            if proc.poll() is not None:
                raise SystemExit(f"panel serve exited with {proc.returncode}; see {log.name}")
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/liveness", timeout=5):
                    break
            except OSError:
                if time.monotonic() - t0 > START_TIMEOUT_S:
                    raise SystemExit(f"panel serve did not answer within {START_TIMEOUT_S} s; see {log.name}")
                time.sleep(0.5)
        print(f"server: answering after {time.monotonic() - t0:.0f} s", flush=True)
        yield f"http://127.0.0.1:{port}/app"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=15)


def revision(repo):
    try:
        return subprocess.run(["git", "-C", str(repo), "describe", "--always", "--dirty"],
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


# ---------------------------------------------------------------------------- pages


def open_page(browser, url):
    """A fresh page (own context) at url, waited until settled; (context, page, its load measurement:
    from navigation start to the first plot drawn and to settled)."""
    context = browser.new_context(viewport=VIEWPORT)
    context.add_init_script(INSTRUMENT_JS)
    page = context.new_page()
    page.set_default_timeout(60_000)
    page.goto(url)
    s = page.evaluate("([to]) => __latency.waitSettled(0, to, true, true)", [PAGE_TIMEOUT_MS])
    return context, page, timings({**s, "first": s["first_drawn"]}, 0, 0)


def timings(s, t_first, t_settle):
    """A measurement from a status s of a page: ms from t_first to the first plot change and from
    t_settle to settled, counted events, pauses and plots."""
    return {"state": s["state"], "first_ms": None if s["first"] is None else s["first"] - t_first,
            "settled_ms": s["paint"] - t_settle if s["state"] == "settled" else None,
            "events": s["n"], "pauses": s["pauses"],
            "plots_visible": s.get("plots_visible"), "plots_changed": s.get("plots_changed")}


def screenshot(page, what):
    name = f"latency-{re.sub(r'[^A-Za-z0-9]+', '-', what)}-{time.time():.0f}.png"
    path = pathlib.Path(tempfile.gettempdir()) / name
    with contextlib.suppress(PlaywrightError):
        page.screenshot(path=str(path))
    return path


def control(page, label, selector):
    """The visible `selector` element nearest to the visible text `label` (or "label: value")."""
    pattern = "^" + re.escape(label) + r"(\s*:.*)?$"
    el = page.evaluate_handle(NEAREST_JS, [pattern, selector]).as_element()
    if el is None:
        raise Located(f"no visible {selector} near a label {label!r}; screenshot {screenshot(page, label)}")
    return el


def choose(page, label, key, needles):
    """Select the option for key in the <select> labelled label; returns a function that does it."""
    select = control(page, label, "select")
    values = select.evaluate(OPTIONS_JS, [key, needles])
    if len(values) != 1:
        raise Located(f"{label}: {len(values)} options match {key!r} {needles} among "
                      f"{select.evaluate(OPTION_TEXTS_JS)}; screenshot {screenshot(page, label)}")
    return lambda: select.select_option(value=values[0])


def tab(page, name):
    """The visible tab header whose text is name."""
    found = page.get_by_text(name, exact=True)
    for i in range(found.count()):
        if found.nth(i).is_visible():
            return found.nth(i)
    raise Located(f"no visible tab {name!r}; screenshot {screenshot(page, name)}")


def measure(page, act, first_input, settle_input=None):
    """Wait for a quiet page, fingerprint its plots, run act(), and time the plots' change.

    first_input / settle_input pick, from the [type, time] inputs act() caused, the time the first
    change and the settle are measured from (settle_input defaults to first_input)."""
    quiet = page.evaluate("([to]) => __latency.waitQuiet(to)", [QUIET_TIMEOUT_MS])
    mark = page.evaluate("() => __latency.arm()")
    act()
    inputs = page.evaluate("(m) => __latency.inputsAfter(m)", mark)
    t_first = first_input(inputs)
    t_settle = (settle_input or first_input)(inputs)
    if t_first is None or t_settle is None:
        return {"state": "no input event", "inputs": inputs}
    s = page.evaluate("([t, to]) => __latency.waitSettled(t, to, false, true)", [t_first, SETTLE_TIMEOUT_MS])
    out = timings(s, t_first, t_settle)
    if not quiet:
        out["state"] = f"not quiet before the input ({out['state']})"
    return out


def first_of(kind):
    return lambda inputs: next((t for k, t in inputs if k == kind), None)


def last_of(kind):
    return lambda inputs: next((t for k, t in reversed(inputs) if k == kind), None)


def drag_moves(inputs):
    """(first, last) pointermove between the pointerdown and the pointerup."""
    down = next((t for k, t in inputs if k == "pointerdown"), None)
    up = next((t for k, t in inputs if k == "pointerup"), None)
    if down is None:
        return None, None
    moves = [t for k, t in inputs if k == "pointermove" and down < t < (up or float("inf"))]
    return (moves[0], moves[-1]) if moves else (None, None)


# ---------------------------------------------------------------------------- actions


def home(url):
    return url + "?" + urllib.parse.urlencode({"scene": SCENE_HOME})


def start_long_run(page, timeout_s=60):
    """Wait until the long run is running; press its Start button only if the app did not start it
    when the tab was first shown (the app before issue 15 waited for the press)."""
    start = page.locator("button", has_text="Start long run")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if page.get_by_text("running").count():
            return
        if start.count() and start.first.is_enabled():
            start.first.click()
            return
        page.wait_for_timeout(250)
    raise RuntimeError("the long run neither started by itself nor offered an enabled Start button")


def run_first_page(browser, url, repeats, record, fresh=False):
    """Fresh pages at the first view, one at a time. On a server this run started (fresh), its very
    first page is timed apart: Panel builds, in that page's request, the session it writes every
    later page's HTML from (1.5-2 s more), and the app's spare sessions (app/page.Spares) start
    with the next page."""
    if fresh:
        context, _, load = open_page(browser, url)
        record("server's first page", "", 0, load)
        context.close()
    for r in range(repeats):
        context, _, load = open_page(browser, url)
        record("first page", "", r, load)
        context.close()


def run_interactions(browser, url, repeats, record):
    """Per repeat, on one fresh page: every scene and back, the methods, the gamma drag, θ keys."""
    for r in range(repeats):
        context, page, _ = open_page(browser, home(url))
        try:
            for scene in [s for s in SCENES if s != SCENE_HOME]:
                for target in (scene, SCENE_HOME):
                    attempt(page, record, "scene", target, r,
                            lambda page=page, target=target: measure(
                                page, choose(page, "Scene", target, SCENES[target]), first_of("input")))
            for method in METHOD_SEQUENCE:
                attempt(page, record, "method", method, r,
                        lambda page=page, method=method: measure(
                            page, choose(page, "Method", method, METHODS[method]), first_of("input")))
            attempt(page, record, "drag gamma", "", r, lambda page=page: drag(page, "gamma"))
            attempt(page, record, f"theta x{THETA_PRESSES} keys", "", r, lambda page=page: theta_keys(page))
        finally:
            context.close()


def attempt(page, record, action, item, repeat, fn):
    try:
        result = fn()
    except (Located, PlaywrightError) as err:
        result = {"state": "error", "error": str(err).splitlines()[0][:300]}
    record(action, item, repeat, result)


def drag(page, label):
    """Mouse down on the slider's handle, DRAG_MOVES moves to the right, mouse up."""
    box = control(page, label, "[role=slider]").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)

    def act():
        page.mouse.down()
        for i in range(1, DRAG_MOVES + 1):
            time.sleep(DRAG_PAUSE_S)
            page.mouse.move(x + i * DRAG_STEP_PX, y)
        page.mouse.up()

    return measure(page, act, lambda inputs: drag_moves(inputs)[0], lambda inputs: drag_moves(inputs)[1])


def theta_keys(page):
    """Lifted theta-method (at θ = 1/2 it may draw what midpoint drew: waited for, not timed), then
    THETA_PRESSES ArrowRight presses on the θ slider's handle."""
    mark = page.evaluate("() => __latency.arm()")
    choose(page, "Method", "theta", METHODS["theta"])()
    page.evaluate("([t, to]) => __latency.waitSettled(t, to, false, false)", [mark, SETTLE_TIMEOUT_MS])
    handle = control(page, "θ", "[role=slider]")
    handle.focus()

    def act():
        for _ in range(THETA_PRESSES):
            page.keyboard.press("ArrowRight")

    return measure(page, act, first_of("keydown"), last_of("keydown"))


def run_tabs(browser, url, repeats, record):
    """Each tab's first visit on a fresh page: at once (the page quiet), and after READ_S more seconds
    of reading the first view, in which the app builds tabs ahead."""
    for r in range(repeats):
        for name in TABS:
            for wait_s in (0, READ_S):
                context, page, _ = open_page(browser, url)
                try:
                    page.wait_for_timeout(wait_s * 1000)
                    attempt(page, record, "tab", name if not wait_s else f"{name} after {wait_s} s", r,
                            lambda page=page, name=name: measure(page, tab(page, name).click,
                                                                 first_of("pointerdown")))
                finally:
                    context.close()


class Mover:
    """A load page: one gamma key press at a time, the next when the last settled and 2 s passed."""

    def __init__(self, page):
        self.page = page
        self.handle = control(page, "gamma", "[role=slider]")
        self.next_at = self.next_poll = 0.0   # time.monotonic() of the next move, of the next look
        self.pending = None                   # in-page time of the move under way
        self.moves = []

    def step(self, now, moving):
        """Start a move if it is time, or collect the one under way; True while one is under way."""
        if self.pending is not None and now < self.next_poll:
            return True
        if self.pending is None:
            if moving and now >= self.next_at:
                key = "ArrowRight" if len(self.moves) % 2 == 0 else "ArrowLeft"   # gamma stays near 0.2
                self.page.evaluate("() => __latency.arm()")
                try:
                    self.handle.press(key)
                except PlaywrightError:   # the slider was redrawn: find it again
                    self.handle = control(self.page, "gamma", "[role=slider]")
                    self.handle.press(key)
                self.pending = self.page.evaluate("() => __latency.lastInputOf('keydown')")
                self.next_at = now + LOAD_INTERVAL_S
            return self.pending is not None
        s = self.page.evaluate("([t, to]) => __latency.status(t, to, false, true)",
                               [self.pending, LOAD_MOVE_TIMEOUT_MS])
        if s["state"] == "pending":
            self.next_poll = now + LOAD_POLL_S
            return True
        self.moves.append(timings(s, self.pending, self.pending))
        self.pending = None
        return False


def run_load(browser, url):
    """LOAD_PAGES pages move gamma for LOAD_SECONDS while another page runs the long run."""
    contexts = []
    try:
        movers = []
        for _ in range(LOAD_PAGES):
            context, page, _ = open_page(browser, home(url))
            contexts.append(context)
            movers.append(Mover(page))
        long_context, long_page, _ = open_page(browser, url + "?" + urllib.parse.urlencode(LONG_QUERY))
        contexts.append(long_context)
        tab(long_page, "Long run").click()
        start_long_run(long_page)
        long_page.wait_for_timeout(2000)
        long_mark = long_page.evaluate("() => performance.now()")
        t0 = time.monotonic()
        for i, m in enumerate(movers):
            m.next_at = t0 + i * LOAD_INTERVAL_S / LOAD_PAGES
        progress, next_progress = [], t0
        busy = True
        while busy or time.monotonic() - t0 < LOAD_SECONDS:
            now = time.monotonic()
            moving = now - t0 < LOAD_SECONDS
            if now >= next_progress:
                progress.append((round(now - t0, 1), long_page.evaluate(PROGRESS_JS)))
                next_progress = now + LOAD_PROGRESS_EVERY_S
            busy = [m.step(now, moving) for m in movers]   # every mover steps
            busy = any(busy)
            time.sleep(0.05)
        progress.append((round(time.monotonic() - t0, 1), long_page.evaluate(PROGRESS_JS)))
        long_events, long_end = long_page.evaluate(
            "(t0) => [__latency.events.filter((e) => e[0] > t0).map((e) => Math.round(e[0] - t0)),"
            " Math.round(performance.now() - t0)]", long_mark)
        return {"pages": [m.moves for m in movers], "long_progress": progress,
                "long_plot_event_ms": long_events, "long_window_ms": long_end,
                "wall_s": round(time.monotonic() - t0, 1)}
    finally:
        for context in contexts:
            with contextlib.suppress(PlaywrightError):
                context.close()


# ---------------------------------------------------------------------------- report


def loadavg(values):
    return " ".join(f"{x:.2f}" for x in values)


def fmt(ms):
    return "-" if ms is None else f"{ms:.0f}"


def row(name, results):
    ok = [r for r in results if r["state"] == "settled"]
    failed = [r for r in results if r["state"] != "settled"]
    firsts = [r["first_ms"] for r in results if r.get("first_ms") is not None]
    settled = [r["settled_ms"] for r in ok]
    worst_settled = fmt(max(settled)) if settled else "-"
    if failed:
        worst_settled = ", ".join(sorted({r["state"] for r in failed}))
    plots = sorted({f"{r['plots_changed']}/{r['plots_visible']}" for r in results
                    if r.get("plots_visible") is not None})
    paused = sum(r["pauses"] > 0 for r in ok)
    return [name, f"{len(ok)}/{len(results)}",
            f"{fmt(statistics.median(firsts)) if firsts else '-'} / {fmt(max(firsts)) if firsts else '-'}",
            f"{fmt(statistics.median(settled)) if settled else '-'} / {worst_settled}",
            " ".join(plots) or "-", f"{paused}/{len(ok)}"]


def table(measurements):
    groups = {}
    for m in measurements:
        groups.setdefault((m["action"], m["item"]), []).append(m)
    rows = [["action", "ok/repeats", "first change median / worst", "settled median / worst (ms)",
             "plots changed/visible", "paused > 600 ms"]]
    for action in dict.fromkeys(a for a, _ in groups):
        items = [(i, rs) for (a, i), rs in groups.items() if a == action]
        for item, rs in items:
            rows.append(row(f"{action} -> {item}" if item else action, rs))
        if len(items) > 1:
            rows.append(row(f"{action} (all)", [r for _, rs in items for r in rs]))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = [" | ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
    lines.insert(1, "-+-".join("-" * w for w in widths))
    return "\n".join(lines)


def percentile(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, max(0, round(q * (len(xs) - 1))))]


def load_summary(load):
    moves = [m for page in load["pages"] for m in page]
    settled = [m["settled_ms"] for m in moves if m["state"] == "settled"]
    firsts = [m["first_ms"] for m in moves if m["first_ms"] is not None]
    others = collections.Counter(m["state"] for m in moves if m["state"] != "settled")
    lines = [f"load: {LOAD_PAGES} pages, each one gamma key press at a time, >= {LOAD_INTERVAL_S:g} s apart "
             f"and after its last settled, for {LOAD_SECONDS} s ({load['wall_s']} s with the last moves' "
             f"settling): {len(moves)} moves, {len(firsts)} got a plot update, {len(settled)} settled"
             + "".join(f", {n} {state} after {LOAD_MOVE_TIMEOUT_MS / 1000:g} s"
                       for state, n in others.items())]
    for name, xs in (("first change", firsts), ("settled", settled)):
        if xs:
            lines.append(f"load: move to {name}: p50 {percentile(xs, 0.5):.0f} ms, "
                         f"p95 {percentile(xs, 0.95):.0f} ms, max {max(xs):.0f} ms (n = {len(xs)})")
    progress = [(t, p) for t, p in load["long_progress"] if p is not None]
    events, end = load["long_plot_event_ms"], load["long_window_ms"]
    recent = [t for t in events if t > end - LONG_RECENT_S * 1000]
    shown = f"{progress[0][1]:.0%} -> {progress[-1][1]:.0%}" if progress else "no <progress> shown"
    lines.append(f"load: long run progress {shown} over {end / 1000:.0f} s, {len(events)} counted events on "
                 f"its page ({len(recent)} in the last {LONG_RECENT_S} s): "
                 + ("still progressing" if recent or (len(progress) > 1 and progress[-1][1] > progress[-2][1])
                    else "NOT progressing at the end"))
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=pathlib.Path, default=pathlib.Path(__file__).resolve().parent.parent,
                        help="repository whose app is served (default: the one holding this script)")
    parser.add_argument("--url", help="an app already served, without a query "
                                      "(e.g. http://127.0.0.1:5006/app); --repo is then unused")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--skip-load", action="store_true", help="skip the 11-page load")
    parser.add_argument("--only", nargs="+", choices=PARTS, help="run only these parts (default: all)")
    parser.add_argument("--json", type=pathlib.Path, help="write every raw timing here")
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit("terminated"))   # stop the server on the way out
    repo = args.repo.resolve()
    report = {"loadavg_start": os.getloadavg(), "repeats": args.repeats, "url": args.url,
              "repo": None if args.url else str(repo), "revision": None if args.url else revision(repo),
              "cpus": os.cpu_count(), "measurements": []}
    print(f"load average at start: {loadavg(report['loadavg_start'])} ({os.cpu_count()} CPUs)")

    def record(action, item, repeat, result):
        report["measurements"].append({"action": action, "item": item, "repeat": repeat, **result})
        print(f"  {action} {item} #{repeat + 1}: {result['state']}, first {fmt(result.get('first_ms'))} ms, "
              f"settled {fmt(result.get('settled_ms'))} ms, {result.get('plots_changed', '-')}/"
              f"{result.get('plots_visible', '-')} plots changed, {result.get('pauses', '-')} pauses"
              + (f" ({result['error']})" if "error" in result else ""), flush=True)

    with contextlib.ExitStack() as stack:
        url = args.url or stack.enter_context(served(repo))
        report["url"] = url
        p = stack.enter_context(sync_playwright())
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        stack.callback(browser.close)
        parts = set(args.only or PARTS) - ({"load"} if args.skip_load else set())
        if "first" in parts:
            run_first_page(browser, url, args.repeats, record, fresh=not args.url)
        for part, run in (("interactions", run_interactions), ("tabs", run_tabs)):
            if part in parts:
                run(browser, url, args.repeats, record)
        if "load" in parts:
            print("load: opening the pages", flush=True)
            report["load"] = run_load(browser, url)
    report["loadavg_end"] = os.getloadavg()

    print(f"\n{url}" + (f" (repository {repo} at {report['revision']})" if not args.url else ""))
    print(table(report["measurements"]))
    if "load" in report:
        print(load_summary(report["load"]))
    failures = [m for m in report["measurements"] if m["state"] != "settled"]
    for m in failures:
        print(f"not measured: {m['action']} {m['item']} #{m['repeat'] + 1}: {m['state']} "
              f"{m.get('error', '')}")
    print(f"load average at start: {loadavg(report['loadavg_start'])}; "
          f"at end: {loadavg(report['loadavg_end'])}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))
        print(f"raw timings: {args.json}")


if __name__ == "__main__":
    main()
