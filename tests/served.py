"""The app served by `panel serve app --setup app/warmup.py` on a free loopback port, for the
browser tests (test_app_e2e.py, test_app_teaching.py, test_load.py), with the Chromium they drive:
one server and one browser for the session, and a page that records its requests and console."""
import contextlib
import json
import os
import pathlib
import socket
import subprocess
import sys
import time
import urllib.request
from urllib.parse import urlencode

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "tests" / "artifacts"
CHROMIUM = os.environ.get("COSYMP_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
PANEL = str(pathlib.Path(sys.executable).with_name("panel"))  # the command the environment installed
START_TIMEOUT_S = 600  # a cold numba cache compiles every kernel first (1-3 min quiet, more under load)
# The session server's log, one per pytest-xdist worker: each worker that runs a browser test serves
# its own app, and two servers writing one file truncated each other's lines (a test reading the
# log for the spare sessions found none).
SERVER_LOG = ARTIFACTS / f"server-{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.log"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def served(log_path, env=None, options=()):
    """Serve the app with extra environment and `panel serve` options, logging to log_path;
    yields (base URL of the app, server pid) once its /liveness endpoint answers (asking for the
    app itself would build a session)."""
    port = free_port()
    ARTIFACTS.mkdir(exist_ok=True)
    env = {**os.environ, **(env or {})}
    # Started as the README starts it: the environment's `panel` command, from the repository, with
    # nothing added to the import path (`python -m panel` put the repository on it, and so hid a
    # setup module that imported the app package, which `panel serve` cannot import).
    with open(log_path, "w") as log:
        proc = subprocess.Popen([PANEL, "serve", "app", "--setup", "app/warmup.py",
                                 "--address", "127.0.0.1", "--port", str(port),
                                 "--allow-websocket-origin", f"127.0.0.1:{port}", "--liveness", *options],
                                cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            _wait_until_serving(proc, port, log_path)
            yield f"http://127.0.0.1:{port}/app", proc.pid
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=15)


def _wait_until_serving(proc, port, log_path):
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        if proc.poll() is not None:
            pytest.fail(f"panel serve exited with {proc.returncode}; see {log_path}")
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/liveness", timeout=5):
                return
        except OSError:
            if time.monotonic() > deadline:
                pytest.fail(f"panel serve did not answer within {START_TIMEOUT_S} s")
            time.sleep(0.5)


WAIT_MS = 20_000
URL_QUIET_MS = 1000  # the app writes a change into the URL 250 ms after it (app.main.URL_MS)



class Page:
    """A browser page that records requests, console errors and BokehJS's warnings."""

    def __init__(self, browser, base):
        self.base = base
        self.requests = []
        self.errors = []
        self.warnings = []
        self.page = browser.new_page(viewport={"width": 1400, "height": 2000})
        self.page.set_default_timeout(WAIT_MS)
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("console", lambda m: m.type == "error" and self.errors.append(m.text))
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        # BokehJS's own warnings (app/static/bokeh_quiet.js keeps figures without data quiet)
        self.page.on("console", lambda m: m.type == "warning" and "[bokeh" in m.text and self.warnings.append(m.text))

    def open(self, query=""):
        self.page.goto(self.base + query, wait_until="load")
        self.page.wait_for_selector(".bk-tab.bk-active")
        self.page.wait_for_selector("h2")

    def settled_url(self):
        """The page's URL once the app has written what it would into it: for a check that a
        refused value never reaches it."""
        self.page.wait_for_timeout(URL_QUIET_MS)
        return self.page.url

    def shot(self, name):
        self.page.screenshot(path=str(ARTIFACTS / f"{name}.png"))

    def check(self):
        local = ("http://127.0.0.1:", "ws://127.0.0.1:", "data:", "blob:")
        outside = [u for u in self.requests if not u.startswith(local)]
        assert outside == [], outside
        assert self.errors == [], self.errors
        assert self.warnings == [], self.warnings

    def numbers(self):
        """The numbers table's rows (lists of cell texts), without its wall-time rows."""
        rows = self.page.evaluate(TABLE_JS)
        return [r for r in rows if r and not r[0].endswith("time (s)") and "time with" not in r[0]]

    def plotted(self):
        """A fingerprint of every plotted data column on the page (sum and length per source)."""
        return self.page.evaluate("""() => {
            const out = [];
            for (const doc of Bokeh.documents) for (const m of doc.all_models) {
                if (m.type !== "ColumnDataSource") continue;
                const data = m.data instanceof Map ? Object.fromEntries(m.data) : m.data;
                for (const [k, v] of Object.entries(data)) {
                    if (!v || typeof v.length !== "number" || typeof v[0] !== "number") continue;
                    let s = 0; for (let i = 0; i < v.length; i++) if (Number.isFinite(v[i])) s += v[i];
                    out.push(k + ":" + v.length + ":" + s.toPrecision(12));
                }
            }
            return out.sort().join("|");
        }""")

    def wait_for_numbers_change(self, before):
        deadline = time.monotonic() + WAIT_MS / 1000
        while self.numbers() == before:
            assert time.monotonic() < deadline, "the numbers panel did not change"
            self.page.wait_for_timeout(200)


TABLE_JS = """() => {
    // The rows of the first visible table (the numbers) on the page, as lists of cell texts.
    const tables = [];
    function find(root) {
        for (const el of root.querySelectorAll("*")) {
            if (el.tagName === "TABLE" && el.classList.contains("dataframe") && el.checkVisibility()) tables.push(el);
            if (el.shadowRoot) find(el.shadowRoot);
        }
    }
    find(document);
    if (!tables.length) return [];
    return [...tables[0].querySelectorAll("tbody tr")].map(row => [...row.querySelectorAll("td, th")]
        .map(c => c.innerText.trim()));
}"""
TABLE_ROW = "table.dataframe tbody tr"  # a table row (Playwright's CSS selectors enter shadow roots)


def query(**items):
    return "?" + urlencode({k: v if isinstance(v, str) else json.dumps(v) for k, v in items.items()})
