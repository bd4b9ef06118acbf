"""Shared lists: every scene x method pair the tests iterate, built from the registries.

A new scene is tested by adding its module to cosymp/scenes/, a new method by adding it to the
method registry (cosymp.methods.METHODS). On a cold numba cache every
kernel is compiled first, in one process per core (cosymp.warm), instead of test by test.
"""
import numpy as np
import pytest

from cosymp import warm
from cosymp.integrate import Setup
from cosymp.methods import METHODS
from cosymp.scenes import SCENES

THETAS = {"theta": (0.0, 0.3, 0.5, 1.0), "theta-naive": (0.3, 0.5)}


def pytest_sessionstart(session):
    if not warm.is_warm():
        terminal = session.config.pluginmanager.get_plugin("terminalreporter")
        compiler = warm.compile_all(report=lambda line: terminal.write_line(f"cosymp compile {line}"))
        assert not compiler.failed, compiler.failed


def pairs(methods=None, scenes=None, linear_only=False):
    """(scene, method, theta) triples: every method on every scene it applies to."""
    out = []
    for s in SCENES.values():
        if scenes is not None and s.name not in scenes:
            continue
        if linear_only and not s.kernel.linear:
            continue
        for m in METHODS.values():
            if methods is not None and m.name not in methods:
                continue
            if m.refusal(s) is None:
                for th in THETAS.get(m.name, (None,)):
                    out.append((s.name, m.name, th))
    return out


def case_id(case):
    scene, method, theta = case
    return f"{scene}-{method}" + ("" if theta is None else f"-{theta}")


def structure_preserving(method, theta):
    return METHODS[method].preserves_at(0.5 if theta is None else theta) == "symplectic"


@pytest.fixture(autouse=True)
def forget_remembered_results():
    """Each test computes its own maps and long runs: the app's server-wide memory of results
    (app.jobs.REMEMBERED) would show one test another's, with no lease and no progress."""
    import sys

    jobs = sys.modules.get("app.jobs")
    if jobs is not None:
        jobs.REMEMBERED.clear()


@pytest.fixture(autouse=True)
def own_memory_budget(monkeypatch):
    """Each test leases from a budget of its own (the server's cap): the studies a test makes hold
    their results' leases, as a page's do until it closes, and a test's studies are never closed;
    over a worker's files they reached the 4096 MB cap, and a later test's comparison was refused."""
    import sys

    memory = sys.modules.get("app.memory")
    if memory is not None:
        monkeypatch.setattr(memory, "BUDGET", memory.MemoryBudget(memory.BUDGET.cap))


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


def setup(scene, method, theta=None, **values):
    return Setup.make(scene, method, values or None, theta)


# The browser tests' server, browser and page (served.py): one server per session, one browser per
# module. Playwright's sync API keeps its event loop running while it is open, so a session-wide
# browser would break every later test that runs a loop of its own (asyncio.run, Panel's callbacks).


@pytest.fixture(scope="session")
def server():
    """`panel serve app --setup app/warmup.py` on a free port, logging at info level (the app's
    spare sessions say when they are built and handed out); yields its base URL."""
    from served import SERVER_LOG, served

    with served(SERVER_LOG, {"PANEL_LOG_LEVEL": "info", "PYTHONUNBUFFERED": "1"}) as (url, _):
        yield url


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright
    from served import CHROMIUM, CHROMIUM_ARGS

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, timeout=60_000)
        yield b
        b.close()


@pytest.fixture
def page(browser, server):
    from served import Page

    p = Page(browser, server)
    yield p
    p.page.close()
