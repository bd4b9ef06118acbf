"""The command-line contract: JSON fields, listings, and one-line errors for bad input."""
import io
import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from cosymp.cli import main
from cosymp.integrate import MAX_STEPS, Setup, simulate


def run_cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out=out, err=err)
    return code, out.getvalue(), err.getvalue()


FIELDS = {"scene", "method", "h", "steps", "t_final", "q_final", "p_final", "pt_final", "H_ext_max_abs",
          "det_max_dev", "symp_max_dev", "error_final", "wall_s"}


def test_run_json_contract_damped_against_exact_flow():
    code, out, err = run_cli("run", "damped", "--method", "midpoint", "--h", "0.1", "--T", "50", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert FIELDS <= set(res)
    assert res["steps"] == 500 and res["t_final"] == pytest.approx(50.0)
    assert len(res["q_final"]) == 1 and len(res["p_final"]) == 1
    # round-off in M^T J M grows with |M|^2, and |M| reaches ~ h e^{gamma T} = 2e3 here
    assert res["det_max_dev"] < 1e-11 and res["symp_max_dev"] < 1e-11
    assert 1e-4 < res["error_final"] < 10
    assert res["reference"] == "exact flow"


def test_run_json_charged_transported_has_mechanical_momentum():
    code, out, err = run_cli("run", "charged", "--method", "symplectic-euler", "--h", "0.001", "--T", "2",
                             "--gauge", "landau", "--transport-from", "coulomb", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert len(res["Pi_final"]) == 2 and len(res["q_final"]) == 2
    code, out0, _ = run_cli("run", "charged", "--method", "symplectic-euler", "--h", "0.001", "--T", "2",
                            "--gauge", "coulomb", "--json")
    base = json.loads(out0)
    assert np.allclose(res["q_final"], base["q_final"], rtol=0, atol=1e-14)
    assert np.allclose(res["Pi_final"], base["Pi_final"], rtol=0, atol=1e-13)
    assert res["error_final"] is not None and res["reference_uncertainty"] < 1e-9


def test_run_beta_expression_and_theta():
    code, out, err = run_cli("run", "charged", "--method", "theta", "--theta", "0.3", "--T", "1",
                             "--set", "beta=0.05*(1+tanh(t))", "--json")
    assert code == 0, err
    assert json.loads(out)["det_max_dev"] < 1e-12


def test_readable_summary_and_listings():
    code, out, _ = run_cli("run", "decaying", "--method", "euler", "--T", "5")
    assert code == 0 and "max |det M_k - 1|" in out
    code, out, _ = run_cli("scenes")
    assert code == 0 and all(s in out for s in ("decaying", "damped", "modulated", "charged", "kapitza"))
    assert "gamma = 0.2" in out
    code, out, _ = run_cli("methods")
    assert code == 0 and "symplectic-euler" in out and "gauss4" in out


BAD = [
    (["run", "damped", "--h", "0"], "h = 0"),
    (["run", "damped", "--h", "-0.1"], "positive"),
    (["run", "damped", "--h", "nan"], "finite"),
    (["run", "damped", "--T", "inf"], "finite"),
    (["run", "damped", "--h", "1e-9", "--T", "1e3"], "cap"),
    (["run", "nosuch"], "unknown scene"),
    (["run", "damped", "--method", "nosuch"], "unknown method"),
    (["run", "charged", "--gauge", "weyl"], "unknown gauge"),
    (["run", "damped", "--method", "theta", "--theta", "1.5"], "theta"),
    (["run", "charged", "--set", "beta=t.__class__"], "beta"),
    (["run", "charged", "--set", "beta=sin(t"], "beta"),
    (["run", "charged", "--set", "beta=1/(t-5)", "--T", "20"], "leaves floating-point range at t = 5"),
    (["report", "charged", "--set", "beta=tan(t)", "--T", "20", "-o", "x.html"], "shorten T below 1.5708"),
    (["run", "damped", "--method", "boris"], "boris"),
    (["run", "modulated", "--method", "exact"], "closed-form"),
    (["run", "damped", "--set", "mass=2"], "no parameter"),
    (["run", "damped", "--set", "gamma=abc"], "number"),
    (["run", "damped", "--gauge", "coulomb"], "no gauges"),
    (["run", "damped", "--method", "midpoint", "--theta", "0.2"], "takes no theta"),
    (["run", "damped", "--h"], "expected one argument"),
    (["frobnicate"], "invalid choice"),
]


@pytest.mark.parametrize("argv,words", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_exits_2_with_one_line(argv, words):
    code, _out, err = run_cli(*argv)
    assert code == 2
    assert err.startswith("cosymp: ") and err.count("\n") == 1, err
    assert words in err
    assert "Traceback" not in err


def test_step_cap_is_documented_value():
    code, _, err = run_cli("run", "damped", "--h", "1", "--T", str(2 * MAX_STEPS))
    assert code == 2 and f"{MAX_STEPS:.0e}" in err


def test_run_failure_exits_3_with_time():
    code, _, err = run_cli("run", "modulated", "--method", "rk4", "--h", "3", "--T", "10000", "--no-error")
    assert code == 3 and "overflow" in err and "t = " in err and err.count("\n") == 1


def test_console_entry_point_in_fresh_process():
    """python -m cosymp: no traceback reaches the user on bad input."""
    r = subprocess.run([sys.executable, "-m", "cosymp", "run", "damped", "--h", "-1"], check=False,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_run_gives_the_same_relative_error_as_the_comparison():
    """`cosymp run` printed the absolute error (7.85 on damped, midpoint, h 0.1, T 50) where the app,
    the reports and the sweeps give the relative one (0.125)."""
    from cosymp.integrate import Setup
    from cosymp.study import compare

    code, out, err = run_cli("run", "damped", "--method", "midpoint", "--h", "0.1", "--T", "50", "--json")
    assert code == 0, err
    c = compare(Setup.make("damped", "midpoint"), 0.1, 50.0)
    assert json.loads(out)["error_final"] == pytest.approx(float(c.error[-1]), rel=1e-9) == pytest.approx(0.125, abs=1e-3)


def test_run_error_where_one_exact_step_over_T_overflows():
    """damped at gamma T = 1000: the reference was one exact step over T, which overflows (the run
    exited 3 with 'overflow ... reduce h'); carried in pieces it is the comparison's exact flow of
    10^4 steps, to their rounding of the phase."""
    from cosymp.integrate import Setup
    from cosymp.study import compare

    code, out, err = run_cli("run", "damped", "--method", "gauss4", "--set", "gamma=1", "--h", "0.1", "--T", "1000",
                             "--json")
    assert code == 0, err
    c = compare(Setup.make("damped", "gauss4", {"gamma": 1.0}), 0.1, 1000.0)
    assert json.loads(out)["error_final"] == pytest.approx(float(c.error[-1]), rel=1e-5) == pytest.approx(0.0115, rel=0.01)


def piped(*argv):
    """python -m cosymp with stdout and stderr both pipes (not terminals), as in a CI log."""
    r = subprocess.run([sys.executable, "-m", "cosymp", *argv], check=False, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    return r.stdout, r.stderr.splitlines()


def stages(err):
    """The stage labels of the progress lines on stderr ('cosymp:  1.2 s  [k/n done] LABEL')."""
    assert err and all(line.startswith("cosymp: ") for line in err), err
    return [line.split(" done] ", 1)[1] for line in err]


def test_long_commands_report_progress_on_a_pipe_and_keep_stdout_clean(tmp_path):
    """workprecision and sweep printed nothing on stderr off a terminal (report and bench: see below):
    each long command now writes a line per stage there, and stdout holds its results alone."""
    import csv

    path = tmp_path / "wp.json"
    out, err = piped("workprecision", "damped", "--methods", "midpoint", "rk4", "--T", "20", "--budget", "0.01",
                     "--out", str(path))
    assert stages(err)[0] == "reference" and stages(err)[-1] == "done" and "rk4 h = 1" in stages(err)
    assert out.startswith("damped to T = 20;") and "cosymp:" not in out and out.endswith(f"written to {path}\n")
    assert {r["solver"] for r in json.loads(path.read_text())} == {"midpoint", "rk4"}

    path = tmp_path / "s.csv"
    out, err = piped("sweep", "damped", "--vary", "gamma=0.9:1:2", "--measure", "error_final", "--h", "0.1",
                     "--T", "1000", "-o", str(path))
    assert stages(err)[0].startswith("first points") and stages(err)[-1] == "points" and "[2/2 done]" in err[-1]
    assert out.startswith("damped with midpoint: 2 points") and "cosymp:" not in out
    rows = list(csv.DictReader(path.open()))
    assert [r["status"] for r in rows] == ["ok", "ok"] and all(math.isfinite(float(r["error_final"])) for r in rows)


def test_bench_and_report_progress_on_a_pipe(tmp_path):
    """bench printed no progress at all; the report already did. With --json, stdout is the JSON alone."""
    out, err = piped("bench", "--steps", "100", "--scenes", "decaying", "--methods", "euler", "midpoint", "--json")
    assert [r["method"] for r in json.loads(out)] == ["euler", "midpoint"]
    assert stages([line for line in err if "done]" in line]) == ["decaying euler", "decaying midpoint", "done"]
    path = tmp_path / "r.html"
    out, err = piped("report", "decaying", "-o", str(path))
    assert stages(err)[-1] == "done" and out == f"report written to {path} ({path.stat().st_size / 1e6:.2f} MB)\n"


@pytest.mark.parametrize("argv", [
    ["workprecision", "damped", "--methods", "midpoint", "--T", "5", "--h", "0.5", "--budget", "0.01"],
    ["workprecision", "damped", "--methods", "midpoint", "--long", "--h", "0.5", "--horizons", "5", "10"],
    ["sweep", "damped", "--vary", "gamma=0:0.2:2", "--measure", "error_final", "--T", "5"],
], ids=["workprecision", "workprecision --long", "sweep"])
def test_long_commands_compile_what_they_need_first_with_a_line_each(argv, tmp_path, monkeypatch):
    """As the report does: on a cold cache the kernels a command needs (here one unit said to be missing,
    and one it does not need) are compiled first, a line each, then the stages follow; stdout keeps
    the results alone. Bad input is refused before any compiling."""
    from cosymp import warm

    units = {u.key: u for u in warm.units()}
    monkeypatch.setattr(warm, "missing", lambda: [units["damped/Theta"], units["kapitza/Gauss"]])
    if argv[0] == "sweep":
        argv = [*argv, "-o", str(tmp_path / "s.csv")]
    code, out, err = run_cli(*argv)
    assert code == 0, err
    lines = err.splitlines()
    assert lines[0].startswith("cosymp: compiling 1 groups of kernels") and "damped × Theta" in lines[0]
    assert "[  1/1]" in lines[1] and "compiled damped × Theta" in lines[1]
    assert len(lines) > 2 and all(" done] " in line for line in lines[2:]) and "cosymp:" not in out
    code, out, err = run_cli(*argv, "--theta", "0.3")
    assert code == 2 and err.count("\n") == 1 and "theta" in err and "compiling" not in err


def _strict(text):
    """json.loads that refuses NaN and Infinity, which are not JSON."""
    def refuse(name):
        raise ValueError(f"{name} in the output")
    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("scene, h, T", [("modulated", "0.02", "10"), ("charged", "0.001", "2.001")])
def test_rk8_is_never_measured_against_itself(scene, h, T):
    """Where h is already below the reference's 2% of the time scale, rk8 at h was its own
    reference (an error of exactly 0). Its error is now measured against rk8 at h/2 or finer,
    and the reference's own uncertainty is a number (it was NaN, not JSON, at an odd step count)."""
    code, out, err = run_cli("run", scene, "--method", "rk8", "--h", h, "--T", T, "--json")
    assert code == 0, err
    res = _strict(out)
    assert res["reference"].startswith("rk8 at h/") and res["reference"] != "rk8 at h/1"
    assert 0 < res["error_final"] < 1e-12
    assert 0 < res["reference_uncertainty"] < 1e-13


def test_an_error_below_the_references_own_is_said_to_be_unresolved():
    """rk8 at h = 0.02 on modulated: its error, 1.9e-15, is below its reference's own uncertainty (7e-15,
    the round-off of 1000 rk8 steps); the line gave both numbers without saying the first means nothing."""
    code, out, err = run_cli("run", "modulated", "--method", "rk8", "--h", "0.02", "--T", "10")
    assert code == 0 and "at least as large: the run's error is not resolved)" in out, out + err
    code, out, _err = run_cli("run", "modulated", "--method", "rk4", "--h", "0.1", "--T", "10")
    assert code == 0 and "(the reference's own, estimated:" in out and "not resolved" not in out, out


def test_a_reference_over_the_step_cap_is_refused_before_the_run(monkeypatch):
    import cosymp.summary

    def must_not_run(*args, **kwargs):
        raise AssertionError("the run started before its reference was checked")

    monkeypatch.setattr(cosymp.summary, "Drive", must_not_run)
    code, out, err = run_cli("run", "kapitza", "--method", "midpoint", "--h", "0.05", "--T", "3e5")
    assert code == 2 and not out
    assert "over the cap" in err and "--no-error" in err and err.count("\n") == 1


def _longest_t(err):
    """The T a reference failure's message names ("shorten T to at most X") and where it failed."""
    found = re.search(r"at t ≈ ([0-9.]+).*shorten T to at most ([0-9.]+)", err)
    return float(found[2]), float(found[1])


def test_a_reference_whose_check_overflows_leaves_the_error_unresolved():
    """beta(t) = exp(t), h = 0.001: the reference, rk8 at h/2, reaches T = 8.5 (it overflows near 8.87),
    its check at twice its step (rk8 at h) overflows at 8.25. That check failed the whole run with the
    check's step count; then the uncertainty was called unknown beside midpoint's error, 3.47, while rk8
    at h/16 (converged against h/8) puts it at 0.82. Nothing bounds the reference there: unbounded, and
    the error not resolved (null in JSON)."""
    argv = ("run", "charged", "--set", "beta=exp(t)", "--T", "8.5")
    code, out, err = run_cli(*argv, "--json")
    assert code == 0, err
    assert _strict(out)["reference_uncertainty"] is None
    code, out, err = run_cli(*argv)
    assert code == 0 and ("(the reference's own: unbounded, its check at twice its step overflowed: the run's error "
                          "is not resolved)") in out


@pytest.mark.parametrize("T, true_error", [("8", 1.557), ("8.2", 0.969)])
def test_the_references_uncertainty_bounds_its_error_outside_rk8s_asymptotic_range(T, true_error):
    """Richardson's estimate, the distance from the check / 255, assumes halving rk8's step divides its
    error by 256: at T = 8 it read 4.1e-3 of |z| where the reference is 0.31 off (rk8 at h/16 and h/64
    agree to 1e-5 of |z|), so midpoint's error, 1.63 against a true 1.557, looked measured to 0.4 %. The
    distance itself bounds it (1.1 here); at T = 8.2 it is 1e96 and the error (4.11, true 0.969) is not
    resolved."""
    code, out, _ = run_cli("run", "charged", "--set", "beta=exp(t)", "--T", T, "--json")
    res = _strict(out)
    fine = Setup.make("charged", "rk8", {"beta": "exp(t)"})
    truth, finer = (simulate(fine, 0.001 / k, float(T), stride=10 ** 9).z[-1, 0] for k in (16, 64))
    assert np.linalg.norm(truth - finer) < 1e-5 * np.linalg.norm(truth), "rk8 at h/16 converged"
    z = np.array(res["q_final"] + res["p_final"])
    true = np.linalg.norm(z - truth) / np.linalg.norm(truth)
    assert true == pytest.approx(true_error, abs=1e-3)
    assert code == 0 and abs(res["error_final"] - true) <= res["reference_uncertainty"]
    code, out, _ = run_cli("run", "charged", "--set", "beta=exp(t)", "--T", T)
    line = next(x for x in out.splitlines() if "relative error at T" in x)
    assert line.endswith("at least as large: the run's error is not resolved)") == (T == "8.2"), line


@pytest.mark.parametrize("argv, longest", [(("--T", "9"), 8.867), (("--h", "0.3", "--T", "6.4"), 6.3)])
def test_a_reference_that_fails_says_it_is_the_reference_and_names_a_t_that_works(argv, longest):
    """To T = 9 the reference itself overflows (t = 8.87) where midpoint does not: the message said
    "overflow in step 17735 ... reduce h", the reference's step count and a step the user does not set.
    It said "shorten T below" the failure: at h = 0.3, T = 6.4 is below 6.46 but runs 22 steps to 6.6.
    It names the longest T of whole steps before the failure now, and a run to it measures its error."""
    code, out, err = run_cli("run", "charged", "--set", "beta=exp(t)", *argv)
    assert code == 3 and not out and err.count("\n") == 1
    assert err.startswith("cosymp: the reference for the error at T, rk8 at h/")
    assert "leaves floating-point range" in err and err.rstrip().endswith(", or skip the error at T (--no-error)")
    named, failed = _longest_t(err)
    assert named == pytest.approx(longest) and named <= failed
    code, out, err = run_cli("run", "charged", "--set", "beta=exp(t)", *argv[:-1], str(named))
    assert code == 0 and "relative error at T" in out, err


def test_a_reference_over_the_cap_gives_its_true_step_count():
    """One step of h = 3e5 on kapitza takes 1.5e8 rk8 steps of its reference: the message said "more than
    1e+300 steps" for any count over the cap."""
    code, out, err = run_cli("run", "kapitza", "--h", "3e5", "--T", "3e5")
    assert code == 2 and not out and "would take 1.5e+08 steps of rk8" in err


@pytest.mark.parametrize("argv", [("run", "kapitza", "--h", "1e305", "--T", "1e306"),
                                  ("run", "modulated", "--h", "3e306", "--T", "3e307"),
                                  ("sweep", "kapitza", "--vary", "h=1e305:2e305:2", "--T", "1e306", "--measure",
                                   "error_final")])
def test_a_reference_past_floating_point_is_refused_in_one_line(argv, tmp_path):
    """The exact step count, an integer past 1.8e308, was compared as a float: a traceback
    (OverflowError: int too large to convert to float), exit 1."""
    code, out, err = run_cli(*argv, *(("-o", str(tmp_path / "s.csv")) if argv[0] == "sweep" else ()))
    assert code == 2 and not out and err.count("\n") == 1
    assert "would take more than 1.8e+308 steps of rk8" in err


@pytest.mark.parametrize("argv, flags", [
    (["report", "paper", "--h", "0.1"], "--h applies"),
    (["report", "paper", "--method", "rk4", "--set", "gamma=1"], "--method, --set apply"),
    (["report", "damped", "--quick", "--no-work-precision"], "--quick, --no-work-precision apply"),
    (["report", "damped", "--theta", "0.3"], "--theta applies to the methods 'theta' and 'theta-naive'"),
])
def test_a_report_refuses_the_options_it_would_ignore(argv, flags, tmp_path):
    """The paper report ran its own values whatever --h, --method or --set said, a scene's report
    has no long runs for --quick to leave out, and --theta with neither method taking θ changed
    nothing: each was ignored without a word."""
    code, out, err = run_cli(*argv, "-o", str(tmp_path / "r.html"))
    assert code == 2 and not out and err.startswith(f"cosymp: {flags}") and err.count("\n") == 1
    assert not (tmp_path / "r.html").exists()


def test_a_reports_error_below_its_references_own_uncertainty_is_not_resolved(tmp_path):
    """beta(t) = exp(t) to T = 8.5: the reference's check overflows at t = 8.25. The report printed
    midpoint's error, 3.47 (rk8 at h/16 puts it at 0.82), as measured; it says it is not resolved, as
    `cosymp run` does, and its trajectory error plot draws the reference's own uncertainty."""
    path = tmp_path / "r.html"
    code, _, err = run_cli("report", "charged", "--set", "beta=exp(t)", "--T", "8.5", "-o", str(path))
    text = path.read_text()
    assert code == 0, err
    said = re.search(r"<td>([0-9.]+) \(not resolved: the reference&#x27;s own uncertainty is unbounded, its check at "
                     r"twice its step overflowed\)</td>", text)
    assert said and 1 < float(said[1]) < 10, "midpoint's, 3.47"
    spec = json.loads(re.search(r'id="figures" type="application/json">(.*?)</script>', text,
                                re.DOTALL).group(1).replace("<\\/", "</"))
    error = next(f for f in spec if f["title"].startswith("Trajectory error against rk8 at h/2"))
    own = error["series"][2]
    assert own["label"] == "the reference's own uncertainty" and own["dash"]
    ys = [y for y in own["y"] if y is not None]
    assert ys and all(0 < y < 1 for y in ys[:1000]), "finite before the check overflows, a gap after"
    assert own["y"][-1] is None


def test_a_report_whose_reference_fails_is_written_without_errors(tmp_path, recwarn):
    """beta(t) = exp(t) to T = 9: the reference overflows at t = 8.87. The report computed both runs and
    then exited 3 with no file, where the app shows the same comparison and says no error is measured;
    it is written now, with the errors left blank and the reason given, and no NumPy warning on stderr."""
    path = tmp_path / "r.html"
    code, _, err = run_cli("report", "charged", "--set", "beta=exp(t)", "--T", "9", "-o", str(path))
    text = path.read_text()
    assert code == 0, err
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in recwarn]
    assert ("No error is measured: the reference for the error at T, rk8 at h/2, leaves floating-point range"
            in text) and "shorten T to at most 8.8" in text
    assert "Trajectory error against" not in text
