"""The evaluation report states a physics fit's convergence as the fit reported it."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

import clutchlab.physics.fit as fit_pkg
from clutchlab.validation.variants import FittedPhysics


class _StoppedFitter:
    """A fit that stops at its iteration limit: returns its best iterate, not converged."""

    def __init__(self, model=None, settings=None):
        pass

    def fit(self, traces):
        self.result_ = SimpleNamespace(
            success=False,
            status="Maximum_Iterations_Exceeded",
            cost_history=[2.0, 1.0],
            values={"reg_F0": -1.6},
            free=["reg_F0"],
            train=[t.name for t in traces],
            wall_s=9.0,
        )
        return self


@pytest.mark.parametrize("success", [False, True])
def test_a_fit_returned_at_its_iteration_limit_is_not_reported_converged(
    monkeypatch, fast_ramp_trace, success
):
    class Fitter(_StoppedFitter):
        def fit(self, traces):
            super().fit(traces)
            self.result_.success = success
            return self

    monkeypatch.setattr(fit_pkg, "PhysicsFitter", Fitter)
    model = FittedPhysics().fit([fast_ramp_trace])
    assert model.converged_ is success
