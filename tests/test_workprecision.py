"""Work-precision and long-horizon measurements on tiny configurations."""
import io
import math
import re

import numpy as np
import pytest

from cosymp import workprecision as wp
from cosymp.cli import main
from cosymp.errors import RunError
from cosymp.integrate import Setup
from cosymp.progress import Bar, Lines, for_stream

HS = [0.4, 0.2, 0.1, 0.05]


@pytest.fixture(scope="module")
def decaying_rows():
    return wp.measure("decaying", ["euler", "midpoint", "rk4", "gauss6"], T=2.0, hs=HS, budget=0.01)


def by_solver(rows, solver):
    return sorted((r for r in rows if r["solver"] == solver), key=lambda r: -r["h"])


def test_errors_order_as_the_orders_predict(decaying_rows):
    """At every step size: euler > midpoint > rk4 > gauss6, and each fitted slope is the order."""
    errs = {s: np.array([r["error"] for r in by_solver(decaying_rows, s)]) for s in ("euler", "midpoint", "rk4", "gauss6")}
    assert np.all(errs["euler"] > errs["midpoint"])
    assert np.all(errs["midpoint"] > errs["rk4"])
    assert np.all(errs["rk4"] > errs["gauss6"])
    for solver, order in (("euler", 1), ("midpoint", 2), ("rk4", 4), ("gauss6", 6)):
        rows = by_solver(decaying_rows, solver)
        slope = np.polyfit(np.log([r["h"] for r in rows]), np.log([r["error"] for r in rows]), 1)[0]
        assert abs(slope - order) < 0.3, (solver, slope)


def test_rows_are_complete_and_honest(decaying_rows):
    for r in decaying_rows:
        assert set(r) == set(wp.ROW_FIELDS)
        assert r["status"] == "ok" and r["reference"] == "exact flow"
        assert r["steps"] * r["h"] == pytest.approx(2.0)
        assert 0 < r["wall_s"] < 1.0
        assert r["error"] > 0
    # one reference for all: error_abs / error is its norm, the same in every row
    scale = {round(r["error_abs"] / r["error"], 12) for r in decaying_rows}
    assert len(scale) == 1
    for r in by_solver(decaying_rows, "midpoint") + by_solver(decaying_rows, "gauss6"):
        assert r["det_max_dev"] < 1e-14
    euler = by_solver(decaying_rows, "euler")
    # explicit Euler's one-step det on the opening example is 1 + h^2 e^(-2 t_k): largest at t = 0
    assert [r["det_max_dev"] for r in euler] == pytest.approx([r["h"] ** 2 for r in euler], rel=1e-12)
    assert [r["rhs_evals"] for r in by_solver(decaying_rows, "rk4")] == [4 * r["steps"] for r in by_solver(decaying_rows, "rk4")]


def test_adaptive_grid_stops_at_round_off():
    rows = wp.measure("decaying", ["rk8"], T=2.0, budget=0.0)
    errs = [r["error"] for r in rows]
    assert min(errs) < 1e-11
    assert len(rows) < 20


def test_peers_in_the_same_table():
    rows = wp.measure("modulated", ["rk4"], T=5.0, hs=[0.1], peers=True, rtols=(1e-4, 1e-8), budget=0.0)
    peers = [r for r in rows if r["kind"] == "scipy"]
    assert [r["solver"] for r in peers] == ["scipy-RK45"] * 2 + ["scipy-DOP853"] * 2 + ["scipy-LSODA"] * 2
    assert rows[0]["reference"].startswith("scipy DOP853") and rows[0]["reference_uncertainty"] < 1e-11
    for solver in wp.PEERS:
        loose, tight = (r for r in peers if r["solver"] == f"scipy-{solver}")
        assert tight["error"] < loose["error"]
        assert tight["rhs_evals"] > loose["rhs_evals"] and math.isnan(tight["det_max_dev"])
        assert tight["H_ext_max_abs"] < loose["H_ext_max_abs"]


def test_a_failed_run_is_a_nan_row_not_dropped():
    """Implicit midpoint on the driven pendulum from q0 = 1 at h = 0.5: Newton fails in step 4."""
    rows = wp.measure("kapitza", ["midpoint"], {"q0": 1.0}, T=2.0, hs=[0.5, 0.01], budget=0.0)
    failed, ok = by_solver(rows, "midpoint")
    assert math.isnan(failed["error"]) and math.isnan(failed["wall_s"]) and "Newton" in failed["status"]
    assert ok["status"] == "ok" and ok["error"] < 0.1
    assert math.isnan(wp.cost_at([failed], "midpoint", 1.0))


@pytest.mark.parametrize("suffix", ["csv", "json"])
def test_rows_round_trip(decaying_rows, tmp_path, suffix):
    rows = decaying_rows + wp.measure("kapitza", ["midpoint"], T=1.0, hs=[0.5], budget=0.0)
    path = tmp_path / f"wp.{suffix}"
    wp.write_rows(rows, path)
    back = wp.read_rows(path)
    assert len(back) == len(rows)
    for a, b in zip(rows, back):
        assert list(b) == list(wp.ROW_FIELDS)
        for k in wp.ROW_FIELDS:
            if isinstance(a[k], float) and math.isnan(a[k]):
                assert math.isnan(b[k]), k
            else:
                assert b[k] == a[k], k


def test_cost_at_interpolates_in_log_log():
    rows = [{"solver": "x", "wall_s": w, "error": e} for w, e in ((1.0, 1e-4), (10.0, 1e-8), (100.0, 1e-12))]
    assert wp.cost_at(rows, "x", 1e-6) == pytest.approx(math.sqrt(10.0))
    assert wp.cost_at(rows, "x", 1e-4) == 1.0
    assert math.isnan(wp.cost_at(rows, "x", 1e-13))


def test_progress_and_cancel():
    seen = []
    wp.measure("decaying", ["rk4", "midpoint"], T=1.0, hs=[0.1], budget=0.0, progress=lambda *a: seen.append(a))
    assert seen[0][:2] == (0, 2) and seen[-1] == (2, 2, "done")

    def stop(done, total, label):
        if done == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        wp.measure("decaying", ["rk4", "midpoint"], T=1.0, hs=[0.1], budget=0.0, progress=stop)


def test_drift_symplectic_bounded_rk4_growing():
    """The pendulum (kapitza without drive): |H + p_t| of RK4 grows linearly with T, that of
    the symplectic methods stays bounded; the errors of the symplectic methods grow linearly."""
    horizons = [20.0, 50.0, 100.0, 200.0, 500.0, 1000.0]
    rows = wp.drift("kapitza", ["rk4", "midpoint", "gauss4"], {"a": 0.0, "q0": 1.0}, h=0.05, horizons=horizons)
    assert len(rows) == 3 * len(horizons) and all(r["status"] == "ok" for r in rows)
    assert wp.growth_exponent(rows, "rk4", "H_ext_max_abs") == pytest.approx(1.0, abs=0.1)
    for solver in ("midpoint", "gauss4"):
        H = [r["H_ext_max_abs"] for r in rows if r["solver"] == solver]
        assert H[-1] < 1.5 * H[0]
        assert wp.growth_exponent(rows, solver) == pytest.approx(1.0, abs=0.15)
    assert rows[0]["reference"] == "rk8 at h/2" and max(r["reference_uncertainty"] for r in rows) < 1e-9


def test_drift_failure_is_kept():
    rows = wp.drift("kapitza", ["midpoint"], h=0.5, horizons=[1.0, 10.0])
    assert all(math.isnan(r["error"]) and "Newton" in r["status"] for r in rows[1:])


def test_cli_workprecision(tmp_path):
    out, err = io.StringIO(), io.StringIO()
    path = tmp_path / "wp.csv"
    code = main(["workprecision", "decaying", "--methods", "rk4", "midpoint", "--T", "2", "--h", "0.2", "0.1",
                 "--budget", "0.01", "--out", str(path)], out, err)
    assert code == 0, err.getvalue()
    text = out.getvalue()
    assert "rk4" in text and "s to 1e-6" in text and "4 runs written" in text
    assert len(wp.read_rows(path)) == 4
    midpoint = next(line for line in text.splitlines() if line.startswith("midpoint"))
    assert midpoint.split()[-4:-2] == ["–", "–"], "midpoint (error 6e-4 at best) reaches neither 1e-6 nor 1e-9"
    assert "nan" not in text


def test_cli_long(tmp_path):
    out, err = io.StringIO(), io.StringIO()
    code = main(["workprecision", "damped", "--long", "--methods", "midpoint", "--h", "0.1", "--set", "gamma=2e-4",
                 "--horizons", "10", "100", "1000", "--out", str(tmp_path / "d.json")], out, err)
    assert code == 0, err.getvalue()
    assert "err T=1000" in out.getvalue() and "H~ slope" in out.getvalue()
    assert len(wp.read_rows(tmp_path / "d.json")) == 3
    midpoint = next(line for line in out.getvalue().splitlines() if line.startswith("midpoint"))
    assert midpoint.split()[-3] == "–" and midpoint.split()[-1] == "0.00", "error past 0.1 at T = 1000; |H~| bounded"


def test_cli_long_past_the_reference_says_where_and_prints_no_nan():
    out, err = io.StringIO(), io.StringIO()
    assert main(["workprecision", "damped", "--long", "--methods", "midpoint", "--horizons", "1000", "2000", "1e4"],
                out, err) == 0, err.getvalue()
    text = out.getvalue()
    assert "nan" not in text and "-0.00" not in text
    assert 7090 < float(re.search(r"leaves floating point at t ≈ (\S+)", text).group(1)) < 7110
    assert "T = 10000 needs parameters with a growth rate 1.5× smaller" in text


@pytest.mark.parametrize("argv,says", [
    (["decaying", "--out", "x.txt"], "name a .csv or .json"),
    (["decaying", "--max-steps", "0"], "--max-steps"),
    (["decaying", "--budget", "-1"], "--budget"),
    (["nowhere"], "unknown scene"),
    (["decaying", "--methods", "nothing"], "unknown method"),
    (["decaying", "--h", "0"], "h = 0.0 must be positive"),
    (["decaying", "--T", "-1"], "T = -1.0 must be a positive finite horizon"),
    (["decaying", "--long", "--horizons", "10", "nan"], "T = nan must be a positive finite horizon"),
    (["decaying", "--long", "--h", "0.1", "0.2"], "one --h"),
    (["decaying", "--long", "--horizons", "1e12"], "exceeds the cap"),
    (["decaying", "--methods", "boris"], "pushes a charge"),
    (["charged", "--set", "beta=tan(t)", "--T", "5"], "leaves floating-point range at t = 1.5708"),
    (["charged", "--long", "--set", "beta=tan(t)"], "leaves floating-point range at t = 1.5708"),
    (["decaying", "--out", "/nonexistent/dir/x.csv"], "not a writable folder"),
    (["decaying", "--methods", "rk4", "--theta", "0.3"], "applies to the methods 'theta'"),
    (["decaying", "--methods", "exact", "rk4"], "'exact' is the reference"),
    (["decaying", "--max-steps", "3"], "below the first run's 10 steps"),
    (["decaying", "--long", "--T", "5"], "drop --T"),
    (["decaying", "--long", "--h", "1e300"], "not below the shortest horizon"),
    (["decaying", "--long", "--h", "1e-3", "--horizons", "1e5"], "over this study's"),
])
def test_cli_bad_input_one_line(argv, says):
    out, err = io.StringIO(), io.StringIO()
    assert main(["workprecision", *argv], out, err) == 2
    assert says in err.getvalue() and err.getvalue().count("\n") == 1


def test_progress_bar_draws_on_a_terminal():
    stream = io.StringIO()
    bar = Bar(stream, width=10, force=True)
    bar(3, 10, "rk4 h = 0.1")
    bar.close()
    assert "[###.......] 3/10 rk4 h = 0.1" in stream.getvalue() and stream.getvalue().endswith("\n")
    quiet = io.StringIO()
    Bar(quiet)(1, 2)
    assert quiet.getvalue() == ""


def test_progress_off_a_terminal_is_a_line_per_stage():
    """A log gets a line when a stage begins, and within one at most a line per `every` seconds."""
    stream = io.StringIO()
    lines = for_stream(stream)
    assert isinstance(lines, Lines)
    lines.every = 3600.0
    for done, label in ((0, "reference"), (0, "rk4 h = 0.1"), (1, "midpoint h = 0.1"), (1, "midpoint h = 0.05")):
        lines(done, 2, label)
    lines.every = 0.0
    lines(1, 2, "midpoint h = 0.025")
    lines.close()
    said = [line.split("s  ", 1)[1] for line in stream.getvalue().splitlines()]
    assert said == ["[0/2 done] reference", "[1/2 done] midpoint h = 0.1", "[1/2 done] midpoint h = 0.025"]


def test_growth_exponent_stops_where_the_error_saturates():
    """A phase error that wrapped back below 0.1 after saturating must not enter the fit."""
    rows = [{"solver": "x", "T": T, "steps": 10 * T, "error": e, "reference_uncertainty": 0.0, "H_ext_max_abs": 1e-9,
             "H_scale": 1.0} for T, e in ((1.0, 1e-4), (10.0, 1e-3), (100.0, 1e-2), (1e3, 0.5), (1e4, 0.01))]
    assert wp.growth_exponent(rows, "x") == pytest.approx(1.0)
    assert wp.growth_exponent(rows, "x", "H_ext_max_abs") == pytest.approx(0.0)
    assert math.isnan(wp.growth_exponent(rows[:2], "x"))


def drift_rows(values, scale=1.0):
    """Drift rows of a solver 'x' at horizons 10, 100, 1000 (10 steps per unit) with these max |H + p_t|."""
    return [{"solver": "x", "T": T, "steps": 10 * T, "error": 1e-3, "reference_uncertainty": 0.0, "H_ext_max_abs": v,
             "H_scale": scale} for T, v in zip((10.0, 100.0, 1e3), values)]


def test_growth_at_round_off_is_said_instead_of_a_slope():
    """Within ROUNDOFF ε |H| √N the values are rounding, whatever their slope; above it the slope
    shows, never as '-0.00'; '–' with fewer than three horizons."""
    eps = np.finfo(float).eps
    walk = [eps * 2.0 * math.sqrt(10 * T) for T in (10.0, 100.0, 1e3)]  # ε |H| √N with |H| = 2
    key = "H_ext_max_abs"
    assert wp.growth_text(drift_rows([0.9 * wp.ROUNDOFF * w for w in walk], 2.0), "x", key) == "round-off"
    assert wp.growth_text(drift_rows([1.1 * wp.ROUNDOFF * w for w in walk], 2.0), "x", key) == "0.50"
    assert wp.growth_text(drift_rows([0.9 * wp.ROUNDOFF * w for w in walk], 1.0), "x", key) == "0.50", \
        "the bound scales with |H|"
    assert wp.growth_text(drift_rows([1e-3, 1e-3 * (1 - 1e-6), 1e-3 * (1 - 2e-6)]), "x", key) == "0.00"
    assert wp.growth_text(drift_rows([1e-3, 1e-3]), "x", key) == "–"
    assert wp.growth_text(drift_rows([1e-3] * 3), "x") == "0.00"


def test_a_drift_at_round_off_and_a_real_one_side_by_side():
    """modulated at h = 0.1: gauss6's max |H + p_t| is 1e-14 to 1e-13, growing like T^0.56 as the
    rounding of its steps does; RK4's drifts like T at 1e-5 to 1e-3."""
    rows = wp.drift("modulated", ["rk4", "gauss6"], h=0.1, horizons=[100.0, 1e3, 1e4])
    assert max(r["H_ext_max_abs"] for r in rows if r["solver"] == "gauss6") < 1e-12
    assert wp.growth_exponent(rows, "gauss6", "H_ext_max_abs") > 0.3
    assert wp.growth_text(rows, "gauss6", "H_ext_max_abs") == "round-off"
    assert wp.growth_text(rows, "rk4", "H_ext_max_abs") == "1.00"
    assert all(0.5 < r["H_scale"] < 2.0 for r in rows)


def test_drift_beyond_the_reference_is_a_nan_row():
    """The damped oscillator at gamma = 0.2: its state passes 1.8e308 at t = 7098 (the hard case
    'Damped beyond floating point'), so the reference reaches T = 5000 (q ~ 1e217; one exact step
    from 0 overflowed there) and stops before 1e4, saying where."""
    rows = wp.drift("damped", ["midpoint"], h=0.1, horizons=[100.0, 5000.0, 1e4])
    reached, far, beyond = rows
    assert reached["status"] == far["status"] == "ok" and reached["error"] < 1.0 and math.isfinite(far["error"])
    assert beyond["status"].startswith(wp.REFERENCE_SHORT) and "T = 10000" in beyond["status"]
    assert 7090 < float(re.search(r"t ≈ (\S+)", beyond["status"]).group(1)) < 7110
    assert math.isnan(beyond["error"])


def test_the_work_precision_reference_reaches_where_the_state_does():
    setup = Setup.make("damped", "midpoint")
    z, label, _ = wp.reference(setup, 5000.0)
    assert label == "exact flow" and 1e216 < abs(z[0]) < 1e218
    with pytest.raises(RunError, match="leaves floating point at t ≈ 7098"):
        wp.reference(setup, 8000.0)


def test_drift_reports_every_chunk_so_cancel_is_prompt():
    """1e6 steps of the method and 3e6 of the rk8 reference: progress at least once per CHUNK
    steps, and an exception raised from it ends the run."""
    calls = []
    wp.drift("modulated", ["midpoint"], h=0.1, horizons=[1e5], progress=lambda *a: calls.append(a[2]))
    assert sum(label.startswith("midpoint") for label in calls) >= 1_000_000 // wp.CHUNK
    assert sum(label.startswith("reference") for label in calls) >= 3_000_000 // wp.CHUNK

    def stop(done, total, label):
        if label.startswith("midpoint"):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        wp.drift("modulated", ["midpoint"], h=0.1, horizons=[1e5], progress=stop)


def test_targets_compute_the_issues_ratios():
    rows = [{"solver": s, "kind": k, "preserves": p, "wall_s": w, "error": e}
            for s, k, p, pts in (("rk4", "cosymp", "none", ((1.0, 1e-5), (2.0, 1e-7), (4.0, 1e-10))),
                                 ("gauss6", "cosymp", "symplectic", ((1.5, 1e-4), (3.0, 1e-8))),
                                 ("scipy-DOP853", "scipy", "none", ((100.0, 1e-5), (1000.0, 1e-11))))
            for w, e in pts]
    t = wp.targets(rows)
    rk4_6 = math.exp(0.5 * math.log(2.0))          # halfway between 1e-5 and 1e-7 in log-log
    g6_6 = math.exp(math.log(1.5) + 0.5 * math.log(2.0))
    assert t["cost"][1e-6]["rk4"] == pytest.approx(rk4_6)
    assert t["ratios"][1e-6]["fastest"] == "rk4" and t["ratios"][1e-6]["best_symplectic"] == "gauss6"
    assert t["ratios"][1e-6]["symplectic_over_rk4"] == pytest.approx(g6_6 / rk4_6)
    dop = math.exp(math.log(100.0) + (1 / 6) * math.log(10.0))
    assert t["ratios"][1e-6]["dop853_over_fastest"] == pytest.approx(dop / rk4_6)
    assert math.isnan(t["cost"][1e-9]["gauss6"])


def test_timed_leaves_out_the_warm_up():
    import time

    calls = []

    def call():
        calls.append(1)
        time.sleep(0.2 if len(calls) == 1 else 0.001)
        return len(calls)

    first, best = wp.timed(call, budget=0.05)
    assert first == 1 and best < 0.05 and len(calls) >= 3


def test_huge_but_finite_states_keep_finite_errors():
    """gamma = 10 on the damped oscillator: q(T) ~ 1e214, its square overflows, the state does not."""
    rows = wp.measure("damped", ["gauss6"], {"gamma": 10.0}, T=50.0, hs=[0.01], budget=0.0)
    assert rows[0]["status"] == "ok" and 0 < rows[0]["error"] < 1e-3 and math.isfinite(rows[0]["error_abs"])


def test_drift_rows_round_trip_as_csv(tmp_path):
    rows = wp.drift("damped", ["midpoint"], {"gamma": 2e-4}, h=0.1, horizons=[10.0, 100.0])
    wp.write_rows(rows, tmp_path / "d.csv", wp.DRIFT_FIELDS)
    back = wp.read_rows(tmp_path / "d.csv")
    assert [b["H_ext_abs"] for b in back] == [float(r["H_ext_abs"]) for r in rows]
    assert all(isinstance(b["error"], float) for b in back)


def test_rk4_error_grows_quadratically_on_the_pendulum():
    """The plain pendulum (kapitza without drive): RK4's energy drift changes its frequency, so
    its phase error grows like T^2; the symplectic gauss4 keeps the energy and errs like T."""
    rows = wp.drift("kapitza", ["rk4", "gauss4"], {"a": 0.0, "q0": 1.0}, h=0.05, horizons=[500.0, 1e3, 2e3, 5e3, 1e4, 2e4])
    assert wp.growth_exponent(rows, "rk4") > 1.7
    assert wp.growth_exponent(rows, "gauss4") == pytest.approx(1.0, abs=0.15)


def test_progress_off_a_terminal_counts_under_one_label_every_few_seconds():
    """A count under one label (a sweep's points, done after each task) is not a line per task: a line
    at most every `every` seconds, and one when the count reaches the total."""
    stream = io.StringIO()
    lines = Lines(stream, every=3600.0)
    lines(0, 100, "first points")
    for done in range(2, 100, 7):
        lines(done, 100, "points")
    lines(100, 100, "points")
    said = [line.split("s  ", 1)[1] for line in stream.getvalue().splitlines()]
    assert said == ["[0/100 done] first points", "[2/100 done] points", "[100/100 done] points"]
