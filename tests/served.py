"""The app served by `panel serve app --setup app/warmup.py` on a free loopback port, for the
browser tests (test_app_e2e.py, test_load.py), with the Chromium they drive."""
import contextlib
import os
import pathlib
import socket
import subprocess
import sys
import time
import urllib.request

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "tests" / "artifacts"
CHROMIUM = os.environ.get("COSYMP_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
START_TIMEOUT_S = 600  # a cold numba cache compiles every kernel first (1-3 min quiet, more under load)


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
    path = [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path), **(env or {})}
    with open(log_path, "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "panel", "serve", "app", "--setup", "app/warmup.py",
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
