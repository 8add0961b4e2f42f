"""The ``reg_pilot_lag`` flexible law and the lag signature that switches it on.

A circuit whose regulated branch lags through a path the latch pilot does not see (a
clutch-fill lag, a damping orifice) has a regulated band that widens with ramp rate
more than its latch currents move. The datasheet model's one pilot lag (the VFS
accumulator orifice) cannot give both; the staged start reads the two time constants
off the training data and adds the law when the data ask for it.
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Trace
from clutchlab.errors import ModelError
from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.fit import FitSettings
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.staged import (
    LATCH_PORT_GAIN,
    lag_signature,
    latch_port_structure,
    regulated_band,
    regulator_lag_structure,
    staged_start,
)
from clutchlab.physics.parameters import without_design_checks
from clutchlab.physics.settings import SimulationSettings
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.physics.stand.plants import PlantConfig, run_plant

RAMPS = (RampProfile("fast", 2.5, 0.5), RampProfile("slow", 10.0, 0.5))
SETTING = (DitherSetting(50.0, "A"),)


@pytest.fixture(scope="module")
def stand_small():
    """clutchlab's own circuit: one pilot lag sets the band and the latch delay."""
    return list(run_stand(StandConfig(settings=SETTING, ramps=RAMPS), False).dataset)


@pytest.fixture(scope="module")
def zoo_small():
    """A zoo plant whose clutch fills through a slower lag than its latch pilot."""
    cfg = PlantConfig("saturating_lugre", settings=SETTING, ramps=RAMPS, seed=5)
    return list(run_plant(cfg, progress=False).dataset)


def test_identity_at_defaults(stand_small):
    base, lagged = CircuitModel(), CircuitModel().with_effects("reg_pilot_lag")
    tr = stand_small[0]
    p0 = simulate(base, base.default_params(), tr).pressure_bar
    p1 = simulate(lagged, lagged.default_params(), tr).pressure_bar
    assert np.max(np.abs(p1 - p0)) < 1e-9


def test_the_lag_widens_the_band_and_leaves_the_latch(stand_small):
    fast, slow = stand_small
    base = CircuitModel()
    lagged = base.with_effects("reg_pilot_lag")
    on = lagged.params(rlag_w=1.0, rlag_tau=100.0)

    def pred(model, params):
        return {t.name: simulate(model, params, t).pressure_bar for t in (fast, slow)}

    sig0 = lag_signature([fast], [slow], pred(base, base.default_params()))
    sig1 = lag_signature([fast], [slow], pred(lagged, on))
    assert sig1["tau_band_ms"] - sig0["tau_band_ms"] > 60.0, (sig0, sig1)
    assert abs(sig1["tau_latch_ms"] - sig0["tau_latch_ms"]) < 15.0, (sig0, sig1)
    w0 = regulated_band(fast, pred(base, base.default_params())[fast.name])[0]
    w1 = regulated_band(fast, pred(lagged, on)[fast.name])[0]
    assert w1 > w0 + 0.5, (w0, w1)


@pytest.mark.parametrize("which, expected", [("stand", False), ("zoo", True)])
def test_staged_start_asks_for_the_lag_only_when_the_data_do(which, expected, request):
    traces = request.getfixturevalue(f"{which}_small")
    model, settings = CircuitModel(), FitSettings(progress=False, regulator_lag="auto")
    free = resolve_free(model, settings)
    _, info = staged_start(model, traces, settings, model.default_params(), free, 20.0)
    sig = info.lag_signature
    assert set(sig) == {
        "data_tau_band_ms",
        "data_tau_latch_ms",
        "model_tau_band_ms",
        "model_tau_latch_ms",
    }
    assert (info.regulator_lag_ms is not None) is expected, info.summary()
    assert "lag signature" in info.summary()
    if expected:
        assert "reg_pilot_lag" in info.summary()
        lag_model, start = regulator_lag_structure(model, model.default_params(), info)
        assert start["rlag_w"] == 1.0 and start["rlag_tau"] == pytest.approx(info.regulator_lag_ms)
        assert "rlag_tau" in resolve_free(lag_model, settings)
        assert "rlag_w" not in resolve_free(lag_model, settings)
    off = FitSettings(progress=False, regulator_lag="off")
    _, info_off = staged_start(model, traces, off, model.default_params(), free, 20.0)
    assert info_off.regulator_lag_ms is None and not info_off.lag_signature


def test_settings_refuse_an_unknown_regulator_lag():
    with pytest.raises(Exception, match="regulator_lag"):
        FitSettings(regulator_lag="maybe")


def test_signature_needs_two_rates_and_a_latch(zoo_small):
    fast, slow = zoo_small
    assert lag_signature([fast], [fast]) is None
    flat = {t.name: np.minimum(t.get("clutch_pressure_bar"), 12.0) for t in (fast, slow)}
    assert lag_signature([fast], [slow], flat) is None


def test_unknown_law_parameter_is_refused():
    with pytest.raises(ModelError):
        CircuitModel().with_effects("reg_pilot_lag").params(rlag_x=1.0)


@pytest.mark.xfail(
    strict=True,
    reason="known defect: the law lags the pilot chamber's hydraulic spring too (negative "
    "damping); the fix is tag stable-reg-pilot-lag (commit c5c700a), not landed: it changes the "
    "discovery's verdicts (the demo then claims transport_delay and takes 1062 s)",
)
def test_the_lagged_pilot_leaves_the_spool_stable(zoo_small):
    """A lagged pilot-chamber spring is negative damping. With the law as it is, these
    values (an iterate of a zoo fit, `--regulator-lag auto`) and a prime pressure below
    the declared initial 0.5 bar send this run to 3.1 bar at zero current (1 substep); in
    that fit's settling run to 298 bar, its sensitivities to 1e75, and IPOPT stopped with
    Error_In_Step_Computation. The fix (the spool's own displacement moves the lagged
    pressure at once) keeps it at 0.5 bar."""
    substeps = 1
    model = CircuitModel().with_effects("reg_pilot_lag")
    params = model.params(
        vfs_K_m=14.73,
        vfs_i_knee=306.4,
        vfs_F_pre=0.518,
        reg_F0=-3.433,
        reg_F_c=0.0671,
        vfs_d_orf=0.876,
        latch_F0=27.99,
        latch_k=1.356,
        rlag_w=1.0,
        rlag_tau=67.3,
    )
    fast = zoo_small[0]
    # prime pressure below the declared initial 0.5 bar: the spool starts out of balance
    low = dict(fast.signals, prime_pressure_bar=np.full(len(fast.time_s), 0.455))
    fast = Trace(fast.name, low, meta=fast.meta)
    run = SimulationSettings(settle_s=0.0, substeps=substeps)
    p = simulate(model, params, fast, run).pressure_bar
    start = fast.time_s - fast.time_s[0] < 0.5  # the current is still below the VFS's knee
    assert np.all(np.isfinite(p))
    assert np.max(p[start]) < 1.5, np.max(p[start])


@pytest.mark.parametrize("which", ["stand", "zoo"])
def test_latch_port_is_chosen_on_the_fast_ramps(which, request):
    """With the lag signature fired, the fit tries the line-select latch port and keeps it
    only when it snaps closer to the data on the fast ramps (matched on the slow ones)."""
    traces = request.getfixturevalue(f"{which}_small")
    model, settings = CircuitModel(), FitSettings(progress=False, regulator_lag="auto")
    free = resolve_free(model, settings)
    start, info = staged_start(model, traces, settings, model.default_params(), free, 20.0)
    info.regulator_lag_ms = info.regulator_lag_ms or 50.0  # as if the signature had fired
    with without_design_checks():  # the staged start's values, not the user's
        lag_model, start = regulator_lag_structure(model, start, info)
    chosen, params = latch_port_structure(lag_model, start, traces, free, settings, info)
    port = info.latch_port
    assert set(port) == {"exhaust_fast_mA", "line_select_fast_mA"}
    selected = "latch_line_select" in chosen.effect_names
    assert selected == (port["line_select_fast_mA"] < LATCH_PORT_GAIN * port["exhaust_fast_mA"])
    assert ("structure: latch_line_select" in info.summary()) == selected
    if selected:
        assert params["lsel_w"] == 1.0 and "lsel_w" not in resolve_free(chosen, settings)
    # the zoo plant's latch switches the clutch to line; the stand's exhausts the feedback
    assert selected == (which == "zoo"), info.summary()
