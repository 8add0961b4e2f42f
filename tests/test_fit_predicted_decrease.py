"""The pre-fit's stopping rule: the Gauss–Newton model's predicted decrease (nlp.py)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from clutchlab.physics.fit.nlp import PredictedDecrease


class _Cache:
    """A stand-in for FitProblem's evaluation cache: r(z) = A z - b, J = A."""

    def __init__(self, a: np.ndarray, b: np.ndarray, cached: bool = True):
        self.a, self.b, self.is_cached = a, b, cached

    def cached(self, z):
        if not self.is_cached:
            return None
        return {"r": self.a @ z - self.b, "J": sp.csc_matrix(self.a)}


def _linear(seed=0, n_r=40, n_z=3):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n_r, n_z)), rng.normal(size=n_r)


def _cost(a, b, z):
    r = a @ z - b
    return 0.5 * float(r @ r)


def test_share_is_the_exact_decrease_on_a_linear_problem():
    a, b = _linear()
    z_opt = np.linalg.lstsq(a, b, rcond=None)[0]
    box = np.full(3, -100.0), np.full(3, 100.0)
    rule = PredictedDecrease(_Cache(a, b), *box, tol=1e-3, reg=0.0)
    z = z_opt + np.array([0.3, -0.2, 0.1])
    expected = (_cost(a, b, z) - _cost(a, b, z_opt)) / _cost(a, b, z)
    assert rule.share(z) == pytest.approx(expected, rel=1e-9)
    assert rule.share(z_opt) == pytest.approx(0.0, abs=1e-12)


def test_a_bound_holds_the_parameters_it_would_be_crossed_by():
    # separable problem: the optimum of z[0] lies beyond its upper bound, z[1] is free
    a = np.diag([1.0, 2.0])
    b = np.array([5.0, 2.0])  # optimum (5, 1)
    lo, hi = np.array([-1.0, -1.0]), np.array([2.0, 3.0])
    rule = PredictedDecrease(_Cache(a, b), lo, hi, tol=1e-3, reg=0.0)
    z = np.array([2.0, 0.0])  # z[0] at its bound, pushed outward
    best = np.array([2.0, 1.0])  # the constrained optimum
    expected = (_cost(a, b, z) - _cost(a, b, best)) / _cost(a, b, z)
    assert rule.share(z) == pytest.approx(expected, rel=1e-9)
    # a parameter short of its bound moves to the bound, not beyond
    z = np.array([0.0, 0.0])
    best = np.array([2.0, 1.0])
    assert rule.share(z) == pytest.approx(
        (_cost(a, b, z) - _cost(a, b, best)) / _cost(a, b, z), rel=1e-9
    )


def test_stops_after_successive_small_shares_only():
    a, b = _linear(1)
    z_opt = np.linalg.lstsq(a, b, rcond=None)[0]
    box = np.full(3, -100.0), np.full(3, 100.0)
    rule = PredictedDecrease(_Cache(a, b), *box, tol=1e-3, successive=2, reg=0.0)
    far = z_opt + 1.0
    assert not rule.should_stop(z_opt)  # one small share
    assert not rule.should_stop(far)  # a large one resets the count
    assert not rule.should_stop(z_opt)
    assert rule.should_stop(z_opt) and rule.stopped
    assert len(rule.shares) == 4


def test_nothing_is_evaluated_without_a_cached_jacobian():
    a, b = _linear(2)
    rule = PredictedDecrease(_Cache(a, b, cached=False), -np.ones(3), np.ones(3), tol=1.0)
    assert rule.share(np.zeros(3)) is None
    assert not rule.should_stop(np.zeros(3)) and rule.shares == []
