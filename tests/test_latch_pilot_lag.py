"""The ``latch_pilot_lag`` flexible law: the latch valve's pilot through a lag of its own.

The complement of ``reg_pilot_lag``: the latch snaps and releases later behind the
current, the more so the faster the ramp, while the regulated branch is untouched.
Discovery offers it as an alternative once the model holds the regulator's lag (see
``test_discover_alternatives``).
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.effects import FLEXIBLE_LAWS
from clutchlab.physics.effects.flexible import switched_on
from clutchlab.physics.fit.staged import lag_signature, regulated_band
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

RAMPS = (RampProfile("fast", 2.5, 0.5), RampProfile("slow", 10.0, 0.5))


@pytest.fixture(scope="module")
def stand_small():
    cfg = StandConfig(settings=(DitherSetting(50.0, "A"),), ramps=RAMPS)
    return list(run_stand(cfg, False).dataset)


def _pred(model, params, traces):
    return {t.name: simulate(model, params, t).pressure_bar for t in traces}


def test_the_lag_delays_the_latch_and_leaves_the_band(stand_small):
    fast, slow = stand_small
    base = CircuitModel()
    lagged = base.with_effects("latch_pilot_lag")
    on = lagged.params(llag_w=1.0, llag_tau=100.0)
    p0, p1 = _pred(base, base.default_params(), stand_small), _pred(lagged, on, stand_small)
    sig0 = lag_signature([fast], [slow], p0)
    sig1 = lag_signature([fast], [slow], p1)
    # the latch's delay behind the current grows by about the lag; the band does not move
    assert sig1["tau_latch_ms"] - sig0["tau_latch_ms"] > 50.0, (sig0, sig1)
    assert abs(sig1["tau_band_ms"] - sig0["tau_band_ms"]) < 15.0, (sig0, sig1)
    w0 = regulated_band(fast, p0[fast.name])[0]
    w1 = regulated_band(fast, p1[fast.name])[0]
    assert abs(w1 - w0) < 0.1, (w0, w1)
    # and the plateau is the same once latched: a timing law, not a level
    assert np.max(p1[fast.name]) == pytest.approx(np.max(p0[fast.name]), abs=0.05)


def test_a_fit_holds_it_on_and_frees_its_time_constant_alone():
    cls = FLEXIBLE_LAWS["latch_pilot_lag"]
    assert cls.HELD_SWITCH and cls.fit_parameters() == ("llag_tau",)
    model = CircuitModel().with_effects("reg_pilot_lag", "latch_pilot_lag")
    assert switched_on(model) == {"rlag_w": 1.0, "llag_w": 1.0}
    assert cls.ALTERNATIVE_AFTER == ("reg_pilot_lag",)
