"""Closing the loop (issue 7): no false positives, unexplained residuals, two effects at once.

Slow tests on the short discovery stand (:mod:`clutchlab.validation.discover.scenarios`).

* No undeclared effect (data from the fit model's own structure, with the stand's noise,
  quantization, wander and resolved dither): no effect may be claimed.
* A disturbance no library effect has (added to the measured pressure here, a test-only
  hook): reported as unexplained, with a signature, and no effect claimed.
* Two undeclared effects: both found, one per iteration.
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Dataset, nominal_current
from clutchlab.physics.fit import FitSettings
from clutchlab.physics.stand import run_stand
from clutchlab.validation.discover import DiscoverySettings, discover
from clutchlab.validation.discover.scenarios import discovery_stand

pytestmark = pytest.mark.slow

SETTINGS = DiscoverySettings(fit=FitSettings(progress=False), progress=False)


def test_no_missing_effect_claims_no_effect():
    dataset = run_stand(discovery_stand(), progress=False).dataset
    res = discover(dataset, settings=SETTINGS)
    print(res.table())
    print(res.summary)
    assert res.added == []
    assert not res.unexplained and res.signature == []
    (it,) = res.iterations
    assert it.effect is None
    assert not any(c.significant for c in it.candidates), [
        (c.effect, c.statistic, c.share) for c in it.candidates
    ]


#: A pressure bump of a flow-area notch in no library effect: +0.25 bar centred on
#: 450 mA (±60 mA), on the way up and the way down alike.
BUMP_BAR, BUMP_MA, BUMP_WIDTH_MA = 0.25, 450.0, 60.0


def _with_bump(dataset: Dataset) -> Dataset:
    traces = []
    for tr in dataset:
        i = nominal_current(tr)
        bump = BUMP_BAR * np.exp(-(((i - BUMP_MA) / BUMP_WIDTH_MA) ** 2))
        traces.append(tr.with_signals(clutch_pressure_bar=tr.get("clutch_pressure_bar") + bump))
    return Dataset(traces)


def test_a_disturbance_in_no_library_effect_is_reported_unexplained():
    dataset = _with_bump(run_stand(discovery_stand(), progress=False).dataset)
    res = discover(dataset, settings=SETTINGS)
    print(res.table())
    print(res.summary)
    assert res.added == []
    assert res.unexplained
    assert "unexplained residual" in res.summary
    assert "current_mA" in res.signature  # the bump follows the current
    assert res.to_dict()["unexplained"] is True


def test_two_undeclared_effects_are_both_found_in_two_iterations():
    config = discovery_stand(("supply_droop", "eddy_current_lag"))
    dataset = run_stand(config, progress=False).dataset
    res = discover(dataset, settings=SETTINGS)
    print(res.table())
    print(res.summary)
    assert sorted(res.added[:2]) == ["eddy_current_lag", "supply_droop"]
    first, second = res.iterations[:2]
    assert first.effect and second.effect
    assert second.after.test["rmse_bar"] < first.before.test["rmse_bar"]
