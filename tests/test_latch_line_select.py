"""The ``latch_line_select`` flexible law: a latch valve that switches the clutch port to line.

The datasheet latch exhausts the regulator's feedback chamber; on release the clutch drains
to the regulated pressure only as fast as the chamber refills and the spool returns. A latch
that selects the clutch feed leaves the regulator regulating, so on release the port is
back at the regulated pressure within the valve's own switching.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.effects import FLEXIBLE_LAWS

LINE_BAR = 17.7


@pytest.fixture(scope="module")
def up_down():
    """Up to 1100 mA, held, and back (50 Hz dither of 60 mA): latches on and releases."""
    return make_trace(
        [0.0, 0.3, 1.3, 2.3, 3.3],
        [0.0, 0.0, 1100.0, 1100.0, 0.0],
        dither_mA=60.0,
        line_bar=LINE_BAR,
    )


def _run(effects, up_down, **values):
    model = CircuitModel().with_effects(*effects)
    return simulate(model, model.params(**values), up_down)


def _release(res):
    """Sample index where the latch valve closes (opening falls through 0.5) on the way down."""
    t, lam = res.time_s, res.outputs["latch_state"]
    return int(np.flatnonzero((lam[:-1] >= 0.5) & (lam[1:] < 0.5) & (t[:-1] > 2.3))[0])


def test_selected_port_sees_line_while_the_regulator_keeps_regulating(up_down):
    res = _run(("latch_line_select",), up_down, lsel_w=1.0)
    out = res.outputs
    latched = out["latch_state"] > 0.999
    assert latched.sum() > 500  # the trace latches for a while
    np.testing.assert_allclose(out["clutch_pressure_bar"][latched], LINE_BAR, atol=0.05)
    # the regulator's own output is still regulated when the latch lets go: well below line
    k = _release(res)
    assert out["clutch_pressure_true_bar"][k - 5] < LINE_BAR - 3.0
    # the datasheet latch instead drives the regulator's output itself to line
    plain = _run((), up_down)
    assert plain.outputs["clutch_pressure_true_bar"][_release(plain) - 5] > LINE_BAR - 0.5


def test_release_drops_the_port_pressure_sooner(up_down):
    """Time from the latch valve closing to the port pressure 2 bar below line: at once for
    the selector, only after the regulator has recovered for the datasheet latch."""

    def drop_ms(res):
        t, p, k = res.time_s, res.outputs["clutch_pressure_bar"], _release(res)
        return 1e3 * (t[k + np.flatnonzero(p[k:] < LINE_BAR - 2.0)[0]] - t[k])

    select = drop_ms(_run(("latch_line_select",), up_down, lsel_w=1.0))
    exhaust = drop_ms(_run((), up_down))
    assert select < 5.0, select
    assert exhaust > select + 30.0, (select, exhaust)


def test_port_rate_is_the_rate_of_the_port_pressure(up_down):
    """The port's rate (what sensor effects filter) matches its pressure: a sensor lag on the
    selected port is the exact first-order filter of the unlagged port pressure."""
    tau_ms = 5.0
    lagged = _run(("latch_line_select", "sensor_lag"), up_down, lsel_w=1.0, slag_tau=tau_ms)
    port = _run(("latch_line_select",), up_down, lsel_w=1.0).outputs["clutch_pressure_bar"]
    dt = float(np.mean(np.diff(up_down.time_s)))
    a = math.exp(-dt / (tau_ms * 1e-3))
    filt = np.empty_like(port)
    filt[0] = lagged.outputs["clutch_pressure_bar"][0]
    for k in range(1, port.size):  # exact for a port pressure linear over each sample
        b = (1.0 - a) / (dt / (tau_ms * 1e-3))
        filt[k] = a * filt[k - 1] + (1.0 - b) * port[k] + (b - a) * port[k - 1]
    err = np.abs(lagged.outputs["clutch_pressure_bar"] - filt)
    assert np.ptp(port) > 10.0
    assert np.max(err) < 0.05, np.max(err)


def test_law_holds_its_weight_and_fits_nothing_of_its_own():
    cls = FLEXIBLE_LAWS["latch_line_select"]
    assert cls.STRENGTH == ("lsel_w",) and cls.fit_parameters() == ()
    spec = next(p for p in cls.PARAMETERS if p.name == "lsel_w")
    assert (spec.default, spec.lower, spec.upper) == (0.0, 0.0, 1.0)


def test_a_fit_of_a_model_naming_the_law_starts_it_on():
    """Named on the model to be fitted (``--effects latch_line_select``), the switch is on:
    at weight 0 it would act on nothing. A start of the user's is used as given."""
    import warnings

    from synthetic import tiny_zoo

    from clutchlab.errors import FitWarning
    from clutchlab.physics.fit import FitSettings, PhysicsFitter

    data = [t for t in tiny_zoo("saturating_lugre", 0, ((50.0, "A"),)) if t.ramp != "medium"]
    model = CircuitModel().with_effects("latch_line_select", "reg_pilot_lag")
    quick = FitSettings(progress=False, max_iter=1, time_limit_s=30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        named = PhysicsFitter(model, quick).fit(data)
        own = PhysicsFitter(model, quick, model.default_params()).fit(data)
    assert named.result_.values["lsel_w"] == 1.0 and named.result_.values["rlag_w"] == 1.0
    assert own.result_.values["lsel_w"] == 0.0 and own.result_.values["rlag_w"] == 0.0
