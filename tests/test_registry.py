"""The registries as the rest of cosymp reads them: every scene's declarations are consistent and
its declared cases do what they say; every method family declares what the studies need; the
compiled layer is imported without any scene. A new scene or family is checked here by being
registered."""
import ast
import dataclasses
import math
import pathlib

import numpy as np
import pytest

from cosymp import bench, kernels, sweep
from cosymp.errors import RunError
from cosymp.integrate import Setup, simulate
from cosymp.kernels.registry import FAMILIES, family
from cosymp.methods import LEAPFROG, METHODS, compose
from cosymp.scenes import SCENES, cases, first, lead
from cosymp.workprecision import rhs_per_step

CASES = cases()


def test_the_compiled_layer_imports_no_scene():
    """Scenes register with the kernels, not the other way round: no module of cosymp/kernels
    imports cosymp.scenes, at its top or inside a function."""
    for path in sorted(pathlib.Path(kernels.__file__).parent.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] + [a.name for a in node.names]
                assert not any("scenes" in n for n in names), (path.name, node.lineno)


def test_exactly_one_case_leads_and_every_scene_declares_one_first_view():
    """The lead is its scene's first view; each scene's first view opens in Orbits, on a run that
    reaches T (tests/test_app_state.py checks what each shows)."""
    assert sum(c.lead for _, c in CASES) == 1
    scene, case = lead()
    assert first(scene) is case
    for s in SCENES.values():
        firsts = [c for c in s.cases if c.first]
        assert len(firsts) == 1 and first(s) is firsts[0], s.name
        assert not firsts[0].hard and not firsts[0].fails and firsts[0].view == "compare"


@pytest.mark.parametrize("scene", list(SCENES))
def test_a_scenes_declarations_name_its_own_parameters_and_known_measures(scene):
    s = SCENES[scene]
    numeric = {p.name for p in s.params if not p.choices and not isinstance(p.default, str)}
    if s.map_axes is not None:
        (x, x0, x1, _), (y, y0, y1, _) = s.map_axes
        assert x != y and {x, y} <= numeric | {"h", "T"} and x0 < x1 and y0 < y1
    assert s.map_measure in sweep.MEASURES
    if s.paper is not None:
        s.values({**s.paper.values, **s.paper.long_values})
        assert s.T_long is None or s.T_long > s.T
    if s.has_gauges:
        assert set(s.gauges) == set(next(p for p in s.params if p.name == "gauge").choices)
        assert s.mechanical is not None and s.gauge_map is not None and s.gauge_jacobian is not None


@pytest.mark.parametrize("scene", list(SCENES))
def test_a_scenes_defaults_print_its_equations_and_leave_no_parameter_unused(scene):
    s = SCENES[scene]
    assert s.shown_equations(s.values()) == s.equations and s.unused(s.values()) == ()


@pytest.mark.parametrize("beta,line", [("constant", r"\beta(t) = B_0"),
                                       ("0.05*(1 + tanh(t))", r"\beta(t) = 0.05 \left(1 + \tanh(t)\right)")])
def test_the_charged_scene_prints_the_beta_it_runs_and_its_unused_parameters_change_nothing(beta, line):
    """The last equation is the chosen beta(t); a parameter `unused` names leaves the run bit-identical
    (a control that moves nothing is disabled in the app), the others change it."""
    s = SCENES["charged"]
    vals = s.values({"beta": beta})
    assert s.shown_equations(vals) == s.equations[:-1] + (line,)
    z = simulate(Setup.make("charged", "midpoint", {"beta": beta}), 0.01, 2.0).z[-1]
    for name in ("B0", "eps", "w"):
        moved = simulate(Setup.make("charged", "midpoint", {"beta": beta, name: 0.7}), 0.01, 2.0).z[-1]
        assert np.array_equal(moved, z) == (name in s.unused(vals)), name


@pytest.mark.parametrize("scene,case", CASES, ids=[f"{s.name}: {c.name}" for s, c in CASES])
def test_every_declared_case_runs_as_it_says(scene, case):
    """Both of its methods apply; those it declares as failing stop early with a RunError naming the
    step, the others reach T with a finite state (a long-run case is run to its study's T)."""
    for name in (case.method, case.other):
        assert METHODS[name].refusal(scene) is None
        s = Setup.make(scene, name, case.values)
        if name in case.fails:
            with pytest.raises(RunError) as err:
                simulate(s, case.h, case.T)
            assert 0 < err.value.step < round(case.T / case.h)
        else:
            run = simulate(s, case.h, case.T, stride=max(1, round(case.T / case.h) // 100))
            assert run.t[-1] == pytest.approx(case.T) and np.all(np.isfinite(run.z[-1]))


@pytest.mark.parametrize("scene", list(SCENES))
def test_every_method_has_a_declared_evaluation_count(scene):
    s = SCENES[scene]
    for m in METHODS.values():
        if m.refusal(s) is None:
            setup = Setup.make(s, m.name)
            count = rhs_per_step(setup)
            implicit_nonlinear = not s.kernel.linear and m.name not in ("euler", "rk4", "rk8", "boris") \
                and m.requires != "separable"
            assert math.isnan(count) == (implicit_nonlinear or m.name == "exact"), (m.name, count)
            if not math.isnan(count):
                assert count >= 1 and count == int(count)


def test_the_bench_reads_which_scenes_and_families_its_c_mirror_has():
    mirror = bench.mirrored_scenes()
    assert {"decaying", "damped", "modulated", "charged", "kapitza"} <= set(mirror) <= set(SCENES)
    for scene, fields in mirror.items():
        P = SCENES[scene].pack(SCENES[scene].values())
        assert all(isinstance(getattr(P, f), float) for f in fields)
    assert {cls.__name__ for cls, k in FAMILIES.items() if k.mirror(METHODS[_first_of(cls)].data()) is None} \
        == {"Splitting", "Perturbed"}


def _first_of(cls):
    return next(m.name for m in METHODS.values() if not m.takes_theta and type(m.data()) is cls)


def test_compositions_take_any_symmetric_base_step():
    """Yoshida's triple jump of the kick-drift-kick leapfrog (a base the methods do not use) is of
    order 4 on the plain oscillator (the errors at two steps give it); a base or coefficients
    that are not symmetric are refused."""
    kdk = ((1.0, 0.0), (0.5, 0.5))
    x = 2 ** (1 / 3)
    data = compose(kdk, [1 / (2 - x), -x / (2 - x), 1 / (2 - x)])
    assert family(data) is FAMILIES[type(data)] and np.count_nonzero(data.b) == 6
    s = Setup.make("modulated", "leapfrog", {"eps": 0.0})
    s = dataclasses.replace(s, data=data)
    exact = np.array([np.cos(8.0) + np.sin(8.0), np.cos(8.0) - np.sin(8.0)])
    errs = [np.linalg.norm(simulate(s, h, 8.0).z[-1, 0] - exact) for h in (0.2, 0.1)]
    assert math.log2(errs[0] / errs[1]) == pytest.approx(4, abs=0.2)
    with pytest.raises(AssertionError):
        compose(((1.0, 0.0), (0.0, 1.0)), [1.0])  # drift then kick: not symmetric
    with pytest.raises(AssertionError):
        compose(LEAPFROG, [0.7, 0.3])
