"""Compiling ahead of use (cosymp.warm): units, worker processes, priorities, waiting runs.

These run on a warm cache (conftest compiles every unit first), where a worker loads a unit
from the cache in about a second.
"""
import pytest

from conftest import pairs
from cosymp import simulate, warm
from cosymp.cli import main
from cosymp.integrate import Setup


def test_every_applicable_method_of_every_scene_is_in_exactly_one_unit():
    units = warm.units()
    keys = [u.key for u in units]
    assert len(set(keys)) == len(keys) and keys[0] == warm.COMMON
    for scene, method, theta in pairs():
        holding = [u for u in units if u.scene == scene and method in u.methods]
        assert len(holding) == 1, (scene, method)
        assert holding[0].key == warm.key_of(Setup.make(scene, method, None, theta))


def test_a_warm_cache_is_complete_and_compile_has_nothing_to_do(capsys):
    assert warm.is_warm() and warm.missing() == []
    assert main(["compile"]) == 0
    assert capsys.readouterr().out == "cosymp: every kernel is in the cache\n"
    assert main(["compile", "--processes", "0"]) == 2


def test_workers_report_progress_and_a_failing_unit_does_not_stop_the_others():
    lines = []
    good = warm.units()[1:3]
    bad = warm.Unit("nowhere/Family", "nowhere", ("none",))
    c = warm.Compiler([good[0], bad, good[1]], processes=2, report=lines.append)
    c.join()
    assert c.finished and c.done == 3 and list(c.failed) == ["nowhere/Family"]
    assert "KeyError" in c.failed["nowhere/Family"] and "nowhere/Family" in c.failed["nowhere/Family"]
    assert lines[0].startswith("compiling 3 groups of kernels in 2 processes")
    assert [line.split("]")[0] for line in lines[1:]] == ["[  1/3", "[  2/3", "[  3/3"]
    assert sum(line.count("FAILED") for line in lines) == 1


def test_waiting_for_a_unit_moves_it_to_the_front():
    units = warm.units()[1:4]
    lines = []
    c = warm.Compiler(units, processes=1, report=lines.append)
    c.wait([units[2].key])
    c.join()
    order = [line.split("compiled ")[1].split(";")[0] for line in lines[1:]]
    assert order.index(units[2].describe()) < order.index(units[1].describe())


@pytest.fixture
def background():
    """A background compiler of one unit, removed again after the test."""
    s = Setup.make("modulated", "gauss4")
    unit = next(u for u in warm.units() if u.key == warm.key_of(s))
    warm._background = warm.Compiler([unit], processes=1)
    yield s, warm._background
    warm._background.join()
    warm._background = None


def test_a_run_waits_for_its_unit_while_a_background_compiler_has_it(background):
    setup, compiler = background
    assert not compiler.finished
    simulate(setup, 0.1, 1.0)
    assert compiler.finished and not compiler.failed
