"""The methods' coefficients themselves, checked against the conditions their families promise
(as scipy's test_rk checks its tableaus). Every registered method is checked by its family; a
family without checks here fails the test."""
import math

import numpy as np
import pytest

from cosymp.kernels.families import Boris, Composition, Exact, Explicit, Gauss, Perturbed, Splitting, Theta
from cosymp.methods import METHODS

TOL = 1e-14
THETAS = (0.0, 0.25, 0.5, 0.8, 1.0)


def cases():
    for m in METHODS.values():
        for theta in (THETAS if m.takes_theta else (None,)):
            yield pytest.param(m, theta, id=m.name + ("" if theta is None else f"-{theta}"))


def explicit(m, D, theta):
    s = len(D.b)
    A = np.reshape(D.A, (s, s))
    b, c = np.array(D.b), np.array(D.offsets)[np.array(D.stage)]
    assert np.all(np.triu(A) == 0.0), "an explicit tableau is strictly lower triangular"
    assert np.allclose(A.sum(axis=1), c, rtol=0, atol=TOL), "row sums of A are the nodes c"
    for k in range(1, m.order + 1):  # the bushy-tree conditions up to the declared order
        assert np.dot(b, c ** (k - 1)) == pytest.approx(1.0 / k, abs=TOL), f"sum b c^{k - 1} = 1/{k}"
    trees = {3: [(b @ (A @ c), 1 / 6)],
             4: [(b @ (c * (A @ c)), 1 / 8), (b @ (A @ c ** 2), 1 / 12), (b @ (A @ (A @ c)), 1 / 24)]}
    for order, conditions in trees.items():
        if m.order >= order:
            for value, expected in conditions:
                assert value == pytest.approx(expected, abs=TOL), f"an order-{order} condition"


def gauss(m, D, theta):
    s = len(D.b)
    A = np.reshape(D.A, (s, s))
    b, c = np.array(D.b), np.array(D.offsets)
    assert np.allclose(A.sum(axis=1), c, rtol=0, atol=TOL), "row sums of A are the nodes c"
    assert np.allclose(np.polynomial.legendre.legroots([0] * s + [1]), 2 * c - 1, atol=TOL), \
        "the nodes are the Gauss-Legendre points"
    for k in range(1, 2 * s + 1):
        assert np.dot(b, c ** (k - 1)) == pytest.approx(1.0 / k, abs=TOL), f"B({2 * s}): sum b c^{k - 1} = 1/{k}"
    for k in range(1, s + 1):
        assert np.allclose(A @ c ** (k - 1), c ** k / k, rtol=0, atol=TOL), f"C({s}): collocation at degree {k}"
    sym = b[:, None] * A + (b[:, None] * A).T - np.outer(b, b)
    assert np.max(np.abs(sym)) < TOL, "symplectic: b_i a_ij + b_j a_ji = b_i b_j"
    assert 2 * s == m.order


def composition(m, D, theta):
    g = D.gammas
    assert g.sum() == pytest.approx(1.0, abs=TOL), "the sub-steps add up to one step"
    assert np.allclose(g, g[::-1], rtol=0, atol=TOL), "symmetric"
    starts = np.concatenate(([0.0], np.cumsum(g)[:-1]))
    assert np.allclose(D.offsets, starts + g / 2, rtol=0, atol=TOL), "each midpoint sub-step is centred"
    for k in range(3, m.order, 2):  # a symmetric composition of an order-2 method: sum g^k = 0, odd k < order
        assert abs(np.sum(g ** k)) < 1e-13, f"sum gamma^{k} = 0 for order {m.order}"


def theta_family(m, D, theta):
    th = 0.5 if theta is None else theta
    assert D.wq0 + D.wq1 == 1.0 and D.wp0 + D.wp1 == 1.0, "convex weights"
    assert tuple(D.offsets) == (D.wq1,), "H at t_k + theta h, where q is taken"
    if m.name == "theta-naive":
        assert (D.wq1, D.wp1) == (th, th), "naive: q and p both at theta"
    else:
        expected = {"midpoint": 0.5, "symplectic-euler": 0.0}.get(m.name, th)
        assert (D.wq1, D.wp1) == (expected, 1.0 - expected), "lifted: q at theta, p at 1 - theta"


def splitting(m, D, theta):
    assert D.a.sum() == pytest.approx(1.0, abs=TOL) and D.b.sum() == pytest.approx(1.0, abs=TOL), \
        "drifts and kicks each add up to one step"
    times = np.concatenate(([0.0], np.cumsum(D.a)[:-1]))
    kicked = D.b != 0.0
    assert np.allclose(D.offsets[D.kick[kicked]], times[kicked], rtol=0, atol=TOL), "each kick at its time"
    ops = [(kind, x) for kick, drift in zip(D.b, D.a) for kind, x in (("kick", kick), ("drift", drift)) if x != 0.0]
    assert [k for k, _ in ops] == [k for k, _ in ops[::-1]], "symmetric (time-reversible)"
    assert np.allclose([x for _, x in ops], [x for _, x in ops[::-1]], rtol=0, atol=TOL), "symmetric"
    if m.name.startswith(("leapfrog", "yoshida")):  # leapfrogs of sizes g: sum g^k = 0, odd k < order
        g = D.b[kicked]
        for k in range(3, m.order, 2):
            assert abs(np.sum(g ** k)) < 1e-13, f"sum gamma^{k} = 0 for order {m.order}"


def fixed_offsets(expected):
    def check(m, D, theta):
        assert tuple(D.offsets) == expected
    return check


CHECKS = {Explicit: explicit, Gauss: gauss, Composition: composition, Theta: theta_family, Splitting: splitting,
          Perturbed: splitting,
          Boris: fixed_offsets((0.0, 0.5, 1.0)), Exact: fixed_offsets((0.0, 1.0))}


@pytest.mark.parametrize("m,theta", list(cases()))
def test_the_coefficients_meet_their_family_conditions(m, theta):
    D = m.data(theta)
    assert type(D) in CHECKS, f"no coefficient checks for family {type(D).__name__}: add them here"
    CHECKS[type(D)](m, D, theta)
    assert all(math.isfinite(float(x)) for f in D for x in np.ravel(f))
