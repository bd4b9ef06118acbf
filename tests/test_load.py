"""Load: ten browser sessions move a slider while an eleventh runs a long run of 3e7 steps per method.

`panel serve app` runs on a free 127.0.0.1 port with a small memory cap (COSYMP_MEMORY_CAP_MB=448),
a short unused-session lifetime (a closed tab's session is destroyed within seconds) and its
/liveness endpoint. One headless Chromium holds 11 pages, each in its own browser context, driven
through Playwright's async API (one event loop, the pages work at once):

1. Priming: one default page is opened and closed (Panel keeps its session for good, to write later
   pages' HTML from; the app stops the page itself once its browser has gone); then "idle" RSS and
   threads are taken (the first page's one-time imports and caches are not per-session costs).
2. Pages 1..10 open the app on the damped scene, one after another (a session costs the server ~3 s of its
   event loop to build; opened all at once, pages connect their websocket after the unused-session
   lifetime and the server builds each session twice). Page 1 then makes BASELINE_MOVES moves
   alone: the unloaded latency.
3. Page 0 opens the Long run view on the Kapitza pendulum, gauss6 against rk4 at h = 0.005, to
   T = LONG_T (2e7 steps per method); the tab starts its run when first shown. The run must still be
   running when the load and the refusals are over, to be cancelled: since the long run reduces its
   diagnostics in the compiled loop, the paper's damped run (5e6 steps, once used here) takes a few
   seconds, so the run is a costly one (gauss6's Newton iterations and complex-step tangent maps on a
   nonlinear scene, about 8 us a step alone). Its cost to the server does not depend on the horizon
   (32 MB lease, LONG_BINS bins).
4. The load: pages 1..10 at once each move the gamma slider MOVES times (focus its handle, press
   ArrowRight: +0.01, one recomputation), each move after the previous one settled, bounded by
   MOVE_TIMEOUT_MS per move and MOVES_WALL_S in all; page 0's progress is read every 2 s.
5. Refusals, on page 1, while the long run holds its 32 MB lease: a 1.5e6-step comparison
   (458 MB > the cap: "needs about ... COSYMP_MEMORY_CAP_MB") and a 1.9e6-step one (429 MB, under
   the cap but over the about 410 MB the long run and the pages leave: "free while other runs hold
   the rest"); the
   last good results must stay, RSS must not jump by anything like a refused request (less than
   half the smaller one, 215 MB: the long run keeps growing beside them, and CI saw 103 MB once),
   and a good h then updates the plots.
6. Clean-up: the long run is cancelled (its Cancel button); a comparison larger than what the
   refusal in 5 said was free, by less than the long run's lease, must now be computed (the
   cancelled run gave its lease back; the pages' own leases, each page's carried loops among them,
   vary from machine to machine, so a fixed size was refused by some); all 11 contexts are closed and
   the server's log (PANEL_LOG_LEVEL=info: "Session <id> launching" / "destroyed") is read until
   every session is destroyed; then, every second for FREE_WAIT_S at most, the log is read until
   every page's App has been garbage-collected (the app logs "a page's state was freed" from a
   finalizer; Panel collects garbage 5 s after the last destroyed session) and the threads are
   back; RSS and threads are taken then.

Latency is timed inside each page on the page's own clock (performance.now()), so the Python side
serving 11 pages does not enter it: the move is the keydown event, "update" the first change a
server patch makes to a ColumnDataSource of the page's Bokeh document after it (the plots got the
new data), "settled" the session's busy spinner hidden again (its style; every plot of the move delivered),
or the update itself where the spinner was not shown (a quick comparison is computed in the move's
handler, and all its plots come in one message).
This is more reliable than timing websocket frames from Python: the first PATCH-DOC after a move
is the URL echo of the location sync, which says nothing about the plots, and frame events reach
a Python loop shared by 11 pages late. A move counts as received when its update arrives; gamma
in the page's URL (the server's state) must end at 0.2 + 0.01 x presses, within URL_WAIT_S of the last
move's settling (the URL comes in a message of its own; its lag is reported).

Memory and threads: VmRSS and Threads of the server from /proc/<pid>/status every 0.2 s (no
psutil); server and machine CPU from /proc; event-loop lag as the time /liveness takes to answer.
The app hands freed memory back to the system itself (app/allocator.py: glibc's mmap threshold
fixed at 1 MiB, malloc_trim once a page's state is freed and after a long run or a measurement),
so RSS measures what is live rather than what the allocator keeps.

Bounds, from runs on 2 shared cores (another suite's server and Chromium often running too):
* Cap 448 MB, not 1 GB: the live views refuse more than 2e6 steps and cosymp records at most 2e7
  values per run, so the largest comparison a page can ask for leases 458 MB on the damped scene
  (508 MB for the charged particle): no single request can pass 1 GB. With 448 MB the long run
  (32 MB) and the ten sessions (0.55 MB each) fit and both refusals can be asked for.
* p95 update latency < P95_BOUND_S = 40 s. One session alone: 0.25-0.6 s. Loaded, p95 was
  15-31 s (p50 4.6-9 s): every update costs the server ~1 s of its single event loop (rendering
  three plots), ten sessions and the long run queue there, and Chromium's 11 renderers take most
  of the two cores. 40 s is ~1.5x the worst p95 seen; a starved session (waiting for the long
  run, minutes) or lost updates (MOVE_TIMEOUT_MS) go far past it.
* Peak RSS - RSS with the ten pages open (before the long run) < the cap: the cap is on
  computations, the pages' documents come on top (observed: idle 437-443 MB, when the warm-up
  still compiled datashader; pages open +50-60 MB; peak 763-891 MB, 326-448 MB over
  idle). Before the app gave freed memory back, CI saw a peak 520 MB over idle.
* After close: every page's state freed (the finalizer's log lines = sessions launched, but the kept
  first one); threads
  <= idle + EXECUTOR_THREADS (the asyncio default executor's workers, min(32, cpu + 4), are created
  on demand and reused by every session: not per-session); RSS - idle < AFTER_MARGIN_MB.
  Observed 66-77 MB over idle. Before the app trimmed its heaps, RSS stayed 250-515 MB over idle
  with everything freed (glibc's per-thread heaps); before the slider fix every closed session
  stayed alive (Panel's EditableFloatSlider sits in a global link registry for good). A fixed 8 s
  wait also read RSS before Panel's collection had freed the last page's 330 MB comparison (its
  objects are cycles): hence the polling, and the freed count is read before the RSS window.
* Click on Cancel to "cancelled at" shown < CANCEL_BOUND_S = 20 s: observed 0.7-2.8 s, 12.7 s
  once on the CI machine while the long run still redrew its plots after every 0.3 s chunk (now
  at most once a second).

Everything measured goes to tests/artifacts/load.json and to stdout (run pytest with -s).
"""
import asyncio
import itertools
import json
import os
import re
import shutil
import statistics
import threading
import time
import urllib.request
from urllib.parse import parse_qs, urlparse

import numpy as np
import pytest
from playwright.async_api import TimeoutError as PlaywrightTimeout
from served import ARTIFACTS, CHROMIUM, CHROMIUM_ARGS, START_TIMEOUT_S, TABLE_ROW, served

SERVER_LOG = ARTIFACTS / "load-server.log"

CAP_MB = 448
SESSION_LIFETIME_MS = 5_000    # longer than a page takes from its HTML to its websocket here
CHECK_UNUSED_MS = 500
SLIDER_PAGES = 10
MOVES = 5
BASELINE_MOVES = 3
DAMPED = "?scene=damped"      # the slider pages' scene (the first view is another)
HANDLE_START = "0.2"           # gamma's slider handle (aria-valuenow, one decimal) on the damped page
MOVE_TIMEOUT_MS = 60_000       # per move, for its update and again for its settling
MOVES_WALL_S = 150             # no move starts after this many seconds of the slider phase
LOAD_TIMEOUT_MS = 90_000
SAMPLE_S = 0.2
DESTROY_TIMEOUT_S = 45
P95_BOUND_S = 40.0
FREE_WAIT_S = 60               # after the last session is destroyed, wait this long at most for every page's state to be freed
CANCEL_BOUND_S = 20            # click to "cancelled at" shown
URL_WAIT_S = 10                # after a page's last move settled, for its URL to hold the last gamma
LONG_T = 1e5                   # the long run's horizon: 2e7 steps of h = LONG_H per method (see the docstring)
LONG_H = 0.005
LONG_STALL_S = 60              # longest time the long run's progress (1% steps) may stand still
AFTER_MARGIN_MB = 200
REFUSAL_T = 300.0
OVER_CAP_H = 0.0002            # 1.5e6 steps: 458 MB, over the cap
OVER_FREE_H = 0.00016          # 1.9e6 steps: 429 MB, under the cap, over what the long run and the pages leave free
GOOD_H = 0.05
EXECUTOR_THREADS = min(32, (os.cpu_count() or 1) + 4)
# One thread beyond idle + the executor stayed after close in 2 of 6 runs (10 against 9; never
# more, whatever the number of sessions): unidentified, process-wide, allowed.
OTHER_THREADS = 1

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not shutil.which(CHROMIUM), reason=f"no Chromium at {CHROMIUM} (apt-get install it)"),
    pytest.mark.timeout(START_TIMEOUT_S + 300),
]


TICK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid):
    """CPU seconds (user + system) the process has used, from /proc/<pid>/stat."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def machine_busy():
    """(busy, total) CPU ticks of the whole machine since boot, from /proc/stat."""
    with open("/proc/stat") as f:
        ticks = [int(x) for x in f.readline().split()[1:]]
    idle = ticks[3] + ticks[4]
    return sum(ticks) - idle, sum(ticks)


def proc_status(pid):
    """(RSS in MB, thread count) of a process, from /proc/<pid>/status."""
    rss = threads = None
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) / 1024
            elif line.startswith("Threads:"):
                threads = int(line.split()[1])
    return rss, threads


class Sampler(threading.Thread):
    """Samples (monotonic time, RSS MB, threads) of a process every SAMPLE_S until stopped."""

    def __init__(self, pid):
        super().__init__(daemon=True, name="load-sampler")
        self.pid = pid
        self.samples = []
        self.halt = threading.Event()

    def run(self):
        while not self.halt.is_set():
            try:
                rss, threads = proc_status(self.pid)
            except (OSError, ValueError):
                return
            self.samples.append((time.monotonic(), rss, threads))
            self.halt.wait(SAMPLE_S)

    def between(self, t0, t1=None):
        t1 = time.monotonic() if t1 is None else t1
        return [s for s in list(self.samples) if t0 <= s[0] <= t1]

    def cpu(self):
        """(monotonic time, server CPU seconds, machine busy ticks, machine total ticks) now."""
        return (time.monotonic(), cpu_seconds(self.pid), *machine_busy())

    @staticmethod
    def usage(a, b):
        """Between two cpu() readings: the server's CPU use in cores, and the machine's busy fraction."""
        return {"server_cores": round((b[1] - a[1]) / (b[0] - a[0]), 2),
                "machine_busy": round((b[2] - a[2]) / max(1, b[3] - a[3]), 2)}

    def peak(self, t0, t1=None):
        """(max RSS, max threads) over [t0, t1]."""
        window = self.between(t0, t1)
        return max(s[1] for s in window), max(s[2] for s in window)

    def settled(self, seconds=1.5):
        """(median RSS, max threads) over the last `seconds` (waits for them to pass)."""
        t0 = time.monotonic()
        time.sleep(seconds)
        window = self.between(t0)
        return statistics.median(s[1] for s in window), max(s[2] for s in window)


class LoopProbe(threading.Thread):
    """GETs the server's /liveness (answered by the event loop without any work) every 0.5 s and
    records (monotonic time, seconds to answer): how long the loop was busy before it could."""

    def __init__(self, url):
        super().__init__(daemon=True, name="load-loop-probe")
        self.url = url
        self.lags = []
        self.halt = threading.Event()

    def run(self):
        while not self.halt.is_set():
            t0 = time.monotonic()
            try:
                with urllib.request.urlopen(self.url, timeout=60) as answer:
                    answer.read()
            except OSError:
                pass
            else:
                self.lags.append((t0, time.monotonic() - t0))
            self.halt.wait(0.5)

    def between(self, t0, t1):
        return [lag for t, lag in list(self.lags) if t0 <= t <= t1]


class Sessions:
    """Counts the sessions Panel logs as launched and destroyed (PANEL_LOG_LEVEL=info). The first
    session is never destroyed: Panel keeps it to write later pages' HTML from (Panel's reuse_sessions,
    set by app/warmup.py; the app stops that page itself once its browser has gone, App._watch)."""

    KEPT = 1

    def __init__(self, log_path):
        self.log_path = log_path

    def counts(self):
        text = self.log_path.read_text(errors="replace")
        return (len(set(re.findall(r"Session (\d+) launching", text))),
                len(set(re.findall(r"Session (\d+) destroyed", text))))

    def freed(self):
        """How many pages' App objects were garbage-collected (app.memory.log_when_freed logs each one)."""
        from app.memory import FREED

        return self.log_path.read_text(errors="replace").count(FREED)

    def live(self):
        launched, destroyed = self.counts()
        return launched - destroyed - self.KEPT

    def wait_all_destroyed(self, timeout_s=DESTROY_TIMEOUT_S):
        """Seconds until no session is live, or None if some still are after timeout_s."""
        t0 = time.monotonic()
        while self.live() > 0:
            if time.monotonic() - t0 > timeout_s:
                return None
            time.sleep(0.25)
        return time.monotonic() - t0


@pytest.fixture(scope="module")
def server():
    """`panel serve app --setup app/warmup.py` with the small cap; yields (base URL, pid)."""
    env = {"COSYMP_MEMORY_CAP_MB": str(CAP_MB), "PANEL_LOG_LEVEL": "info", "PYTHONUNBUFFERED": "1"}
    options = ["--check-unused-sessions", str(CHECK_UNUSED_MS), "--unused-session-lifetime", str(SESSION_LIFETIME_MS)]
    with served(SERVER_LOG, env, options) as url_pid:
        yield url_pid


# In-page instrumentation: keydown times, and the times of Bokeh document changes that matter.
INSTRUMENT_JS = """() => {
    const L = window.__load = {keys: [], cds: [], busy: [], settled: [], slider: []};
    document.addEventListener("keydown", () => L.keys.push(performance.now()), true);
    for (const doc of Bokeh.documents) doc.on_change((ev) => {
        const m = ev.model;
        if (!m) return;
        const t = performance.now();
        if (m.type === "ColumnDataSource") L.cds.push(t);
        else if (m.type === "Slider" && ev.attr === "value") L.slider.push([t, m.value]);
        else if (ev.attr === "styles" && (m.css_classes || []).includes("loader"))
            ((m.styles || {}).opacity === "0" ? L.settled : L.busy).push(t);
    });
    return Bokeh.documents.length;
}"""
# [ms from the k-th keydown to the first plot-data change after it] once there is one, else null.
UPDATE_JS = """(k) => {
    const L = window.__load;
    if (L.keys.length <= k) return null;
    const t0 = L.keys[k], u = L.cds.find((t) => t > t0);
    return u === undefined ? null : [u - t0];
}"""
# [ms from the k-th keydown to settled]: the spinner hidden after the first plot-data change, or,
# when the spinner was not shown, that change itself (a quick comparison is computed in the move's
# handler and every plot arrives in that one message).
SETTLED_JS = """(k) => {
    const L = window.__load, t0 = L.keys[k], u = L.cds.find((t) => t > t0);
    if (u === undefined) return null;
    if (!L.busy.some((t) => t > t0 && t <= u)) return [u - t0];
    const s = L.settled.find((t) => t >= u);
    return s === undefined ? null : [s - t0];
}"""
CDS_COUNT_JS = "() => window.__load.cds.length"
# The slider's value changes after the k-th keydown ([ms after it, value]).
SLIDER_AFTER_JS = """(k) => {
    const L = window.__load, t0 = L.keys[k];
    return L.slider.filter(([t]) => t > t0).map(([t, v]) => [Math.round(t - t0), v]);
}"""
# [ms from t0 to the first plot-data change after it].
AFTER_JS = """(t0) => {
    const u = window.__load.cds.find((t) => t > t0);
    return u === undefined ? null : [u - t0];
}"""
NOW_JS = "() => performance.now()"


SENT = {}  # page -> the text frames it sent on its websocket
OUTSIDE = []  # requests of any page that did not go to 127.0.0.1
LOCAL = ("http://127.0.0.1:", "ws://127.0.0.1:", "data:", "blob:")


async def new_page(browser, url, ready):
    """A page in its own context, opened at url, with `ready` (a selector) shown; (context, page, seconds)."""
    t0 = time.monotonic()
    context = await browser.new_context(viewport={"width": 1400, "height": 1600})
    page = await context.new_page()
    page.set_default_timeout(LOAD_TIMEOUT_MS)
    sent = SENT[page] = []
    page.on("request", lambda req: req.url.startswith(LOCAL) or OUTSIDE.append(req.url))
    page.on("websocket", lambda ws: ws.on("framesent", lambda data: sent.append(data if isinstance(data, str) else "")))
    await page.goto(url, wait_until="load")
    await page.wait_for_selector(ready)
    await page.wait_for_function("() => window.Bokeh && Bokeh.documents.length > 0")
    await page.evaluate(INSTRUMENT_JS)
    return context, page, time.monotonic() - t0


async def move_slider(page, moves, deadline):
    """Press ArrowRight on the gamma slider `moves` times (one step of 0.01 each), each after the
    previous move settled; returns per-move update/settled latencies (s), moves made, lost
    updates, all presses so far on the page and gamma in its URL at the end."""
    values = await page.locator(".noUi-handle").evaluate_all("hs => hs.map(h => h.getAttribute('aria-valuenow'))")
    handle = page.locator(".noUi-handle").nth(values.index(HANDLE_START))
    out = {"update_s": [], "settled_s": [], "made": 0, "lost": [], "unsettled": []}
    first = await page.evaluate("() => window.__load.keys.length")
    for k in range(first, first + moves):
        if time.monotonic() > deadline:
            break
        await handle.press("ArrowRight")
        out["made"] += 1
        try:
            got = await page.wait_for_function(UPDATE_JS, arg=k, polling=100, timeout=MOVE_TIMEOUT_MS)
            out["update_s"].append((await got.json_value())[0] / 1000)
        except PlaywrightTimeout as err:  # a lost update is a finding: recorded, asserted on later
            moved = await page.evaluate(SLIDER_AFTER_JS, k)
            sent = [v for _, v in moved if any(f'"new":{json.dumps(v)}' in f for f in SENT[page])]
            out["lost"].append(f"move {k}: {type(err).__name__}: {str(err)[:60]}; slider values after the "
                               f"keydown: {moved}; sent to the server: {sent}; gamma in the URL: {url_gamma(page.url)}")
            continue
        try:
            got = await page.wait_for_function(SETTLED_JS, arg=k, polling=100, timeout=MOVE_TIMEOUT_MS)
            out["settled_s"].append((await got.json_value())[0] / 1000)
        except PlaywrightTimeout as err:
            out["unsettled"].append(f"move {k}: {type(err).__name__}: {str(err)[:120]}")
    out["presses"] = first + out["made"]
    # The URL is written in a message of its own, which may follow the plots' (a move computed in the
    # background): waited for, at most URL_WAIT_S, and how long it lagged is kept.
    want, t_url = 0.2 + 0.01 * out["presses"], time.monotonic()
    while abs(url_gamma(page.url) - want) > 1e-9 and time.monotonic() - t_url < URL_WAIT_S:
        await asyncio.sleep(0.05)
    out["url_lag_s"] = round(time.monotonic() - t_url, 2)
    out["gamma"] = url_gamma(page.url)
    return out


def url_gamma(url):
    """gamma in the page's URL (the app writes its state there; the slider shows one decimal)."""
    values = parse_qs(urlparse(url).query).get("p", ["{}"])[0]
    return json.loads(values).get("gamma", 0.2)


async def watch_progress(page, stop):
    """(seconds, progress %, status line) of the long run every 2 s until stop is set."""
    t0 = time.monotonic()
    seen = []
    while not stop.is_set():
        value = await page.locator("progress").first.get_attribute("value")
        status = await long_status(page)
        seen.append((round(time.monotonic() - t0, 1), int(value or 0), status))
        try:
            await asyncio.wait_for(stop.wait(), 2.0)
        except TimeoutError:
            pass
    return seen


async def long_status(page):
    """The long run's status line (running, cancelled at ..., done: ...)."""
    return await page.locator(f"p.doc:has-text('h = {LONG_H:g}') b").first.inner_text()


def between_free_and_lease(free_text):
    """A step h whose comparison at REFUSAL_T (damped, midpoint against rk4) needs more than the MB
    the refusal's message said were free and less than those plus the long run's lease (by 8 MB
    or more each way), and its size in MB."""
    from app.features.longrun import LONG_RUN_BYTES
    from app.study import comparison_bytes
    from cosymp.integrate import Setup

    lease = LONG_RUN_BYTES / 2**20
    free = int(re.search(r"only (\d+) MB", free_text).group(1))
    setups = [Setup.make("damped", m) for m in ("midpoint", "rk4")]
    sizes = {h: comparison_bytes(setups, h, REFUSAL_T) / 2**20 for h in np.unique(np.round(np.geomspace(1.5e-4, 1e-2, 400), 6))}
    h = min((h for h, mb in sizes.items() if free + 8 <= mb <= free + lease - 8),
            key=lambda h: abs(sizes[h] - free - lease / 2))
    return float(h), sizes[h]


async def accept_after_cancel(page, sampler, free_text):
    """Ask page for a comparison that did not fit while the long run held its lease, by the refusal's
    own count of what was free, and fits once the cancelled run gave the lease back; returns its
    header and size, the page's last messages and the RSS around it."""
    from playwright.async_api import expect

    before, _ = proc_status(sampler.pid)
    h, mb = between_free_and_lease(free_text)
    await enter(page, 0, h)
    want = f"h = {h:g}, T = {REFUSAL_T:g}"
    try:
        await expect(header(page)).to_contain_text(want, timeout=MOVE_TIMEOUT_MS)
    except AssertionError:
        pass
    shown = await header(page).inner_text()
    with_big, _ = await asyncio.to_thread(sampler.settled, 1.5)
    said = await page.locator(".notyf__message").all_inner_texts()
    return {"accepted": want in shown, "header": shown.split("\t")[0], "request_mb": round(mb, 1),
            "rss_before_mb": round(before), "rss_with_it_mb": round(with_big), "messages": said[-2:]}


async def enter(page, index, value):
    """Type value into the index-th sidebar number input (0: h, 1: T) and press Enter."""
    box = page.locator("input.bk-input").nth(index)
    await box.fill(str(value))
    await box.press("Enter")


async def toast(page, *texts):
    """The text of the notification that contains all of texts (waits for it)."""
    loc = page.locator(".notyf__toast")
    for t in texts:
        loc = loc.filter(has_text=t)
    await loc.first.wait_for(timeout=MOVE_TIMEOUT_MS)
    return await loc.first.inner_text()


def header(page):
    """The numbers table's first column title: what the numbers were computed for (h and T)."""
    return page.locator("table.dataframe thead th").first


async def refusals(page, sampler, long_running):
    """On page: a good horizon, then a comparison over the cap (refused), then, while the long run
    holds its lease, one under the cap but over what is free (refused), then a good step again
    (computed). Returns the texts, the RSS around the refusals and the good value's latency."""
    from playwright.async_api import expect

    from app.study import comparison_bytes
    from cosymp.integrate import Setup

    setups = [Setup.make("damped", m) for m in ("midpoint", "rk4")]
    out = {"over_cap_request_mb": round(comparison_bytes(setups, OVER_CAP_H, REFUSAL_T) / 2**20, 1),
           "free_request_mb": round(comparison_bytes(setups, OVER_FREE_H, REFUSAL_T) / 2**20, 1)}
    await enter(page, 1, REFUSAL_T)
    await expect(header(page)).to_contain_text(f"h = 0.1, T = {REFUSAL_T:g}", timeout=MOVE_TIMEOUT_MS)
    t0 = time.monotonic()
    base_rss, _ = proc_status(sampler.pid)
    await enter(page, 0, OVER_CAP_H)
    out["over_cap_text"] = await toast(page, "needs about", "COSYMP_MEMORY_CAP_MB")
    # The box shows the last good h again before the next is typed: the toast and the box's restored
    # value can come in two messages, and a value typed between them was overwritten before Enter
    # (nothing was asked, no toast came: CI at f5a652d).
    await expect(page.locator("input.bk-input").nth(0)).to_have_value("0.1", timeout=MOVE_TIMEOUT_MS)
    out["free_text"] = None
    if long_running:  # without the long run's lease this request would be computed
        await enter(page, 0, OVER_FREE_H)
        out["free_text"] = await toast(page, "needs about", "free while other runs hold the rest")
    await asyncio.sleep(1.0)
    out["kept_last_good"] = f"h = 0.1, T = {REFUSAL_T:g}" in await header(page).inner_text()
    peak, _ = sampler.peak(t0)
    out["rss_before_mb"], out["rss_peak_during_mb"] = round(base_rss), round(peak)
    sent = await page.evaluate(NOW_JS)
    await enter(page, 0, GOOD_H)
    await expect(header(page)).to_contain_text(f"h = {GOOD_H:g}, T = {REFUSAL_T:g}", timeout=MOVE_TIMEOUT_MS)
    got = await page.wait_for_function(AFTER_JS, arg=sent, polling=100, timeout=MOVE_TIMEOUT_MS)
    out["good_value_update_s"] = round((await got.json_value())[0] / 1000, 3)
    return out


async def scenario(base, sampler, sessions, probe=None):
    """The whole load run; returns the figures (asserted by the tests below)."""
    from playwright.async_api import async_playwright

    from app.presets import Preset

    preset = Preset("load: a long run", "", {"scene": "kapitza", "method": "gauss6", "other": "rk4", "h": LONG_H,
                                             "T": 20.0, "values": {}, "view": "long"}, T_long=LONG_T)
    r = {"loadavg_at_start": os.getloadavg(), "cap_mb": CAP_MB, "slider_pages": SLIDER_PAGES, "moves_per_page": MOVES,
         "session_lifetime_ms": SESSION_LIFETIME_MS}
    t_start = time.monotonic()
    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, timeout=60_000)
        try:
            # Priming: the first page's one-time costs, then idle.
            context, _, _ = await new_page(browser, base + DAMPED, TABLE_ROW)
            await context.close()
            r["priming_destroyed_s"] = await asyncio.to_thread(sessions.wait_all_destroyed)
            rss, threads = await asyncio.to_thread(sampler.settled)
            r["idle"] = {"rss_mb": round(rss, 1), "threads": threads}
            t_idle = time.monotonic()

            # Pages 1..10, opened one after another: a page whose websocket connects later than the
            # unused-session lifetime after its HTML gets a second session built (a server-side
            # session costs ~3 s of the event loop; ten opened at once take ~50 s to connect).
            opened = []
            for _ in range(SLIDER_PAGES):
                opened.append(await new_page(browser, base + DAMPED, TABLE_ROW))
            r["page_load_s"] = [round(s, 2) for _, _, s in opened]
            r["live_sessions_after_open"] = sessions.live()

            # Unloaded baseline: BASELINE_MOVES on page 1 alone.
            r["baseline"] = await move_slider(opened[0][1], BASELINE_MOVES, time.monotonic() + MOVES_WALL_S)
            r["latency_baseline_s"] = summary(r["baseline"]["update_s"])
            rss, threads = await asyncio.to_thread(sampler.settled, 1.0)
            r["pages_open"] = {"rss_mb": round(rss, 1), "threads": threads}

            # Page 0: the long run.
            # (the tab starts its run when first shown)
            long_ctx, long_page, _ = await new_page(browser, base + preset.query(),
                                                    "button:has-text('Start long run')")
            await long_page.get_by_text("running").first.wait_for()
            stop = asyncio.Event()
            progress_task = asyncio.create_task(watch_progress(long_page, stop))

            # The load: the ten pages move their sliders at once while the long run runs.
            t_moves = time.monotonic()
            cpu_moves = sampler.cpu()
            long_plots = await long_page.evaluate(CDS_COUNT_JS)
            deadline = t_moves + MOVES_WALL_S
            results = await asyncio.gather(*[move_slider(pg, MOVES, deadline) for _, pg, _ in opened])
            t_moved = time.monotonic()
            r["moves_wall_s"] = round(t_moved - t_moves, 1)
            r["cpu_during_moves"] = sampler.usage(cpu_moves, sampler.cpu())
            r["long_page_plot_updates_during_moves"] = await long_page.evaluate(CDS_COUNT_JS) - long_plots
            if probe is not None:
                r["loop_lag_idle_s"] = summary(probe.between(t_idle - 2, t_idle))
                r["loop_lag_during_moves_s"] = summary(probe.between(t_moves, t_moved))
            r["pages"] = results
            updates = [x for res in results for x in res["update_s"]]
            settled = [x for res in results for x in res["settled_s"]]
            r["latency_update_s"] = summary(updates)
            r["latency_settled_s"] = summary(settled)
            r["peak_during_load"] = dict(zip(("rss_mb", "threads"), map(round, sampler.peak(t_moves))))

            # The refusals, on page 1, while the long run holds its lease.
            status = await long_status(long_page)
            r["long_status_before_refusals"] = status
            r["refusal"] = await refusals(opened[0][1], sampler, long_running=status == "running")

            # Clean-up: cancel the long run, close every page.
            stop.set()
            r["long_progress"] = await progress_task
            r["long_status_before_cancel"] = await long_status(long_page)
            r["cancel_s"] = None
            if r["long_status_before_cancel"] == "running":
                t_cancel = time.monotonic()
                await long_page.locator("button:visible", has_text="Cancel").click()
                await long_page.get_by_text("cancelled at t =").first.wait_for(timeout=MOVE_TIMEOUT_MS)
                r["cancel_s"] = round(time.monotonic() - t_cancel, 2)
            r["cancel_status"] = await long_status(long_page)
            rss, threads = await asyncio.to_thread(sampler.settled, 2.0)
            r["after_cancel"] = {"rss_mb": round(rss, 1), "threads": threads}
            r["after_cancel_request"] = await accept_after_cancel(opened[0][1], sampler, r["refusal"]["free_text"])
            r["peak"] = dict(zip(("rss_mb", "threads"), map(round, sampler.peak(t_idle))))
            t_close = time.monotonic()
            for context, _, _ in opened:
                await context.close()
            await long_ctx.close()
        finally:
            await browser.close()
    r["t_close"], r["t_start"] = t_close, t_start
    r["requests_outside_loopback"] = sorted(set(OUTSIDE))
    return r


def after_close(r, sampler, sessions):
    """Wait (bounded) for every session to be destroyed, then the settled figures."""
    r["destroyed_s"] = sessions.wait_all_destroyed()
    t_close, t_start = r.pop("t_close"), r.pop("t_start")
    r["destroyed_after_close_s"] = round(time.monotonic() - t_close, 1)
    launched, destroyed = sessions.counts()
    r["sessions"] = {"launched": launched, "destroyed": destroyed, "pages_opened": SLIDER_PAGES + 2}
    waited = time.monotonic()
    while True:
        freed = sessions.freed()  # before the window: its RSS is then read after the pages were freed
        rss, threads = sampler.settled(1.0)
        if (freed >= launched - sessions.KEPT and threads <= r["idle"]["threads"] + EXECUTOR_THREADS + OTHER_THREADS) \
                or time.monotonic() - waited > FREE_WAIT_S:
            break
    r["after_close"] = {"rss_mb": round(rss, 1), "threads": threads, "pages_freed": freed,
                        "waited_after_destroyed_s": round(time.monotonic() - waited, 1)}
    r["total_s"] = round(time.monotonic() - t_start, 1)
    r["loadavg_at_end"] = os.getloadavg()


def summary(xs):
    if not xs:
        return {"n": 0}
    q = statistics.quantiles(xs, n=20, method="inclusive") if len(xs) > 1 else [xs[0]] * 19
    return {"n": len(xs), "p50": round(statistics.median(xs), 3), "p95": round(q[18], 3), "max": round(max(xs), 3)}


@pytest.fixture(scope="module")
def load(server):
    base, pid = server
    sampler = Sampler(pid)
    probe = LoopProbe(base.rsplit("/", 1)[0] + "/liveness")
    sampler.start()
    probe.start()
    try:
        sessions = Sessions(SERVER_LOG)
        r = asyncio.run(scenario(base, sampler, sessions, probe))
        after_close(r, sampler, sessions)
    finally:
        sampler.halt.set()
        probe.halt.set()
        sampler.join(timeout=5)
        probe.join(timeout=65)
    r["loop_lag_all_s"] = summary([lag for _, lag in probe.lags])
    r["rss_series"] = [(round(t - sampler.samples[0][0], 1), round(m), n) for t, m, n in sampler.samples[::5]]
    (ARTIFACTS / "load.json").write_text(json.dumps(r, indent=1))
    lat, done = r["latency_update_s"], r["latency_settled_s"]
    print(f"\nload: {SLIDER_PAGES} sessions x {MOVES} moves while a long run to T = {LONG_T:g} (h = {LONG_H:g}) runs; "
          f"update latency p50 {lat.get('p50')} s, p95 {lat.get('p95')} s, max {lat.get('max')} s (n = {lat['n']}); "
          f"settled p50 {done.get('p50')} s, p95 {done.get('p95')} s, max {done.get('max')} s")
    lag = r.get("loop_lag_during_moves_s", {})
    print(f"load: event-loop lag during the moves (/liveness answer time) p50 {lag.get('p50')} s, "
          f"p95 {lag.get('p95')} s, max {lag.get('max')} s; CPU during the moves {r['cpu_during_moves']}")
    alone = r["latency_baseline_s"]
    print(f"load: one session alone (before the long run): update p50 {alone.get('p50')} s, max {alone.get('max')} s; "
          f"page loads {min(r['page_load_s'])}-{max(r['page_load_s'])} s")
    print(f"load: RSS idle {r['idle']['rss_mb']} MB, ten pages open {r['pages_open']['rss_mb']} MB, "
          f"peak {r['peak']['rss_mb']} MB, after cancel "
          f"{r['after_cancel']['rss_mb']} MB, after close {r['after_close']['rss_mb']} MB "
          f"({r['after_close']['pages_freed']} pages' state freed, {r['after_close']['waited_after_destroyed_s']} s "
          f"after the last session was destroyed; cap {CAP_MB} MB); "
          f"threads idle {r['idle']['threads']}, peak {r['peak']['threads']}, after close {r['after_close']['threads']}")
    print(f"load: after the cancel, a comparison larger than was free while the long run ran {r['after_cancel_request']}")
    print(f"load: each page's URL reached its last gamma {[res.get('url_lag_s') for res in r['pages']]} s after "
          "its last move settled")
    print(f"load: refusals {r['refusal'].get('free_text')!r} / {r['refusal'].get('over_cap_text')!r}; "
          f"sessions {r['sessions']}, destroyed {r['destroyed_s']} s after close; total {r['total_s']} s")
    return r


def test_every_session_received_an_update_for_every_move(load):
    lost = {i + 1: res["lost"] for i, res in enumerate(load["pages"]) if res["lost"]}
    short = {i + 1: res["made"] for i, res in enumerate(load["pages"]) if res["made"] < MOVES}
    unsettled = {i + 1: res["unsettled"] for i, res in enumerate(load["pages"]) if res["unsettled"]}
    assert not short, f"moves made within {MOVES_WALL_S} s: {short}"
    assert not lost, lost
    assert not unsettled, unsettled
    assert load["latency_update_s"]["n"] == SLIDER_PAGES * MOVES
    gammas = [(res["gamma"], 0.2 + 0.01 * res["presses"], res["url_lag_s"]) for res in load["pages"]]
    assert all(abs(got - want) < 1e-9 for got, want, _ in gammas), gammas


def test_every_request_stayed_on_the_loopback(load):
    assert load["requests_outside_loopback"] == []


def test_p95_latency_is_bounded(load):
    assert load["latency_update_s"]["p95"] < P95_BOUND_S, load["latency_update_s"]


def test_the_long_run_kept_progressing_during_the_load(load):
    seen = load["long_progress"]
    rose = [seen[0][0]] + [b[0] for a, b in itertools.pairwise(seen) if b[1] > a[1]] + [seen[-1][0]]
    longest = max(b - a for a, b in itertools.pairwise(rose))
    assert seen[-1][1] > seen[0][1] and longest < LONG_STALL_S, (longest, seen)
    assert load["long_page_plot_updates_during_moves"] > 0
    assert load["long_status_before_refusals"] == "running"
    assert load["long_status_before_cancel"] == "running", \
        f"the long run ended before the cancel ({load['long_status_before_cancel']}): raise LONG_T"
    assert load["cancel_status"].startswith("cancelled at t ="), load["cancel_status"]
    assert load["cancel_s"] < CANCEL_BOUND_S, load["cancel_s"]


def test_a_cancelled_run_gives_its_memory_lease_back(load):
    again = load["after_cancel_request"]
    assert again["accepted"], again


def test_memory_stays_under_the_cap(load):
    """The cap is on computations; the open pages' own documents come on top (README)."""
    assert load["peak"]["rss_mb"] - load["pages_open"]["rss_mb"] < CAP_MB, \
        (load["idle"], load["pages_open"], load["peak"])


def test_a_request_over_the_cap_is_refused_and_the_page_still_works(load):
    ref = load["refusal"]
    assert ref["over_cap_request_mb"] > CAP_MB > ref["free_request_mb"]
    assert f"needs about {ref['over_cap_request_mb']:.0f} MB" in ref["over_cap_text"] and f"cap of {CAP_MB} MB" in ref["over_cap_text"]
    assert ref["free_text"] is not None and f"needs about {ref['free_request_mb']:.0f} MB" in ref["free_text"]
    assert ref["kept_last_good"]
    assert ref["rss_peak_during_mb"] - ref["rss_before_mb"] < 0.5 * ref["free_request_mb"], ref
    assert ref["good_value_update_s"] < MOVE_TIMEOUT_MS / 1000


def test_closed_pages_free_their_sessions_threads_and_memory(load):
    assert load["destroyed_s"] is not None, f"sessions still live {DESTROY_TIMEOUT_S} s after the pages closed"
    assert load["after_close"]["threads"] <= load["idle"]["threads"] + EXECUTOR_THREADS + OTHER_THREADS, \
        load["after_close"]
    assert load["after_close"]["pages_freed"] == load["sessions"]["launched"] - Sessions.KEPT, load["after_close"]
    assert load["after_close"]["rss_mb"] - load["idle"]["rss_mb"] < AFTER_MARGIN_MB, (load["idle"], load["after_close"])
