"""Shared pieces of the flexible latch laws' tests: a model's switch currents on one
experiment, clutchlab's own circuit with and without a law, a latch stage's inputs."""

from __future__ import annotations

from clutchlab.data import dither_period_mean, dither_period_samples
from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.fit import FitSettings
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.staged import match_latch_snaps, staged_start
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.validation.latch import latch_currents
from clutchlab.validation.protocol import ExperimentReference
from clutchlab.validation.settings import AnalysisSettings


def switch_currents(model: CircuitModel, trace, **values) -> tuple[float, float]:
    """Latch-on and latch-off currents (mA) of ``model`` at ``values`` on ``trace``
    (dither-period-mean clutch pressure against the nominal current)."""
    pressure = simulate(model, model.params(**values), trace).pressure_bar
    ref = ExperimentReference.of(trace, AnalysisSettings())
    mean = dither_period_mean(pressure, dither_period_samples(trace))
    lc = latch_currents(ref.current_mA, mean, ref.direction, ref.line_bar)
    return lc.on_mA, lc.off_mA


#: The nine dither settings and the fast (2.5 s) and slow (12 s) ramps of the latch stages'
#: own-model tests.
OWN_SETTINGS = tuple(DitherSetting(f, s) for f in (30.0, 50.0, 70.0) for s in ("A", "B", "C"))
OWN_RAMPS = (RampProfile("fast", 2.5, 0.5), RampProfile("slow", 12.0, 0.5))


def own_model_runs(law_model: CircuitModel, **law_values) -> dict:
    """The stand's 18 experiments (fast and slow ramps, nine dither settings) with the
    clutch pressure of clutchlab's own model: ``"plain"`` without the law, ``"law"`` with
    ``law_model`` at the datasheet values and ``law_values``."""
    traces = list(run_stand(StandConfig(settings=OWN_SETTINGS, ramps=OWN_RAMPS), False).dataset)
    plain = CircuitModel()
    truth = plain.default_params()
    with_law = law_model.params(**truth.values, **law_values)
    out = {}
    for name, model, params in (("plain", plain, truth), ("law", law_model, with_law)):
        out[name] = [
            tr.with_signals(clutch_pressure_bar=simulate(model, params, tr).pressure_bar)
            for tr in traces
        ]
    return out


def matched_stage_inputs(traces, effects=()):
    """A latch stage's inputs on ``traces``: clutchlab's model (with ``effects``), its
    datasheet values, the free parameters, settings and a staged start's record (with its
    latch-matching Jacobian), the start matched to the snaps of the plain model."""
    plain = CircuitModel()
    settings = FitSettings(progress=False, regulator_lag="off")
    free = resolve_free(plain, settings)
    _, info = staged_start(plain, traces, settings, plain.default_params(), free, 20.0)
    match_latch_snaps(plain, plain.default_params(), traces, free, settings, info)
    assert info.latch_jacobian is not None, info.summary()
    model = plain.with_effects(*effects) if effects else plain
    return model, model.default_params(), free, settings, info
