"""Tests for `cosymp bench`: rows, figures and the C mirror's agreement (no timing assertions)."""

import json
import math
import shutil
from io import StringIO

import pytest

from cosymp import bench
from cosymp.cli import main

ARGS = ["bench", "--steps", "20000", "--scenes", "damped", "--methods", "midpoint", "rk4", "--json"]


def _rows(argv, err=None):
    out, err = StringIO(), err or StringIO()
    assert main(argv, out=out, err=err) == 0, err.getvalue()
    return json.loads(out.getvalue())


def test_bench_rows_and_c_mirror_agrees():
    rows = _rows(ARGS)
    assert [(r["scene"], r["method"]) for r in rows] == [("damped", "midpoint"), ("damped", "rk4")]
    for r in rows:
        assert r["steps"] == 20000 and r["status"] == 0
        assert math.isfinite(r["numba_ns"]) and r["numba_ns"] > 0
    if shutil.which(bench.CC) is None:
        pytest.skip(f"{bench.CC} not found: no C comparison")
    for r in rows:
        assert math.isfinite(r["c_ns"]) and r["c_ns"] > 0
        assert r["ratio"] == pytest.approx(r["numba_ns"] / r["c_ns"])
        assert r["agree"], f"C and numba final states differ for {r['method']}: rel {r['rel_diff']:.1e}"


def test_bench_without_compiler_still_gives_numba_figures(monkeypatch):
    monkeypatch.setattr(bench, "CC", "cosymp-no-such-compiler")
    err = StringIO()
    rows = _rows(ARGS[:5] + ["--methods", "midpoint", "--json"], err)
    assert "not found" in err.getvalue()
    assert len(rows) == 1 and rows[0]["numba_ns"] > 0
    assert rows[0]["c_ns"] is None and rows[0]["ratio"] is None and rows[0]["agree"] is None


def test_bench_table_without_compiler_says_so(monkeypatch):
    monkeypatch.setattr(bench, "CC", "cosymp-no-such-compiler")
    out = StringIO()
    assert main(["bench", "--steps", "100", "--scenes", "decaying", "--methods", "euler"], out=out) == 0
    lines = out.getvalue().splitlines()
    assert "not found" in lines[0]
    assert lines[-1].split()[:2] == ["decaying", "euler"]


@pytest.mark.parametrize("argv", [["--steps", "0"], ["--scenes", "nowhere"], ["--methods", "nothing"],
                                  ["--scenes", "kapitza", "--methods", "boris"]])
def test_bench_bad_input_exits_2(argv):
    err = StringIO()
    assert main(["bench", *argv], out=StringIO(), err=err) == 2
    assert err.getvalue().startswith("cosymp: ")


def test_bench_names_the_pairs_its_c_mirror_lacks(monkeypatch):
    monkeypatch.setattr(bench, "CC", "cosymp-no-such-compiler")
    out = StringIO()
    assert main(["bench", "--steps", "100", "--scenes", "modulated", "--methods", "midpoint", "leapfrog"], out=out) == 0
    assert out.getvalue().splitlines()[-1] == "no C mirror in bench_ref.c (numba figures only) for modulated: leapfrog"


def test_bench_without_the_c_source_says_where_it_is(monkeypatch, tmp_path):
    """An installed package has no benchmarks/: the bench gives numba figures and says why (on the
    command's stderr, with --json)."""
    monkeypatch.setattr(bench, "C_SOURCE", tmp_path / "benchmarks" / "bench_ref.c")
    err = StringIO()
    rows = _rows(["bench", "--steps", "100", "--scenes", "decaying", "--methods", "euler", "--json"], err)
    assert "benchmarks/bench_ref.c is not in this installation" in err.getvalue()
    assert rows[0]["c_ns"] is None and rows[0]["numba_ns"] > 0 and rows[0]["mirrored"] is False
