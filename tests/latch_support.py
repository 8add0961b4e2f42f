"""A model's latch switch currents on one experiment (for the flexible latch laws' tests)."""

from __future__ import annotations

from clutchlab.data import dither_period_mean, dither_period_samples
from clutchlab.physics import CircuitModel, simulate
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
