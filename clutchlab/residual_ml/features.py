"""The paper's input features, built from a trace (DESIGN §1), and the regression target.

Features, each a per-sample signal with a unit:

========================  =====  ==========================================================
name                      unit   meaning
========================  =====  ==========================================================
``current_mA``            mA     nominal VFS current (``current_cmd_mA``, else demodulated)
``current_lag_mA``        mA     nominal current through a first-order lag of time constant
                                 ``lag_s`` (causal): the current the circuit has caught up
                                 with, so one pressure curve serves every ramp rate
``dither_amp_mA``         mA     dither amplitude (logged, else demodulated)
``dither_freq_Hz``        Hz     dither frequency (logged, else demodulated)
``didt_mA_s``             mA/s   filtered dI/dt of the nominal current (rate of travel)
``direction``             1      last direction of travel: +1 after the current last rose,
                                 −1 after it last fell (|dI/dt| above a dead band), 0 before
                                 the first move; held through holds (hysteresis memory)
``physics_bar``           bar    physics-model clutch pressure, dither-period mean (hybrid)
``physics_pilot_bar``     bar    physics-model pilot (VFS accumulator) pressure, dither-period
                                 mean (hybrid): what the latch valve responds to
``didt_causal_mA_s``      mA/s   causal dI/dt: least-squares slope over the *trailing* window
                                 (:func:`clutchlab.data.causal_didt`), no look-ahead
``direction_causal``      1      last direction of travel from ``didt_causal_mA_s``
========================  =====  ==========================================================

The paper's stage 1 uses the first three, stage 2 adds the current derivative "to indicate the
direction of the current ramp": here both its value (``didt_mA_s``, the rate, which sets the
lag-induced part of the hysteresis) and the direction it implies (``direction``, which sets
the friction part and, unlike the sign of dI/dt, is remembered while the current holds).
Building features is the estimators' job (:class:`FeatureBuilder` is one of their
parameters), not the caller's.

**Causal features.** ``didt_mA_s`` is a centred Savitzky–Golay slope and the physics
features are centred dither-period means: each looks half a window ahead, which offline
training and scoring can afford but a real-time model (an exported FMU) cannot. The causal
counterparts (:data:`CAUSAL_COUNTERPART`) use past samples only; a model trained on them
(``features=causal_features(...)``, ``clutchlab train --causal``) is reproduced exactly by
its FMU. They are separate feature names rather than a switch so that the choice travels
with the model wherever its feature names do (estimator parameters, saved model JSON,
reports, the FMU exporter), and a model trained on the centred features can never be
mistaken for a causal one. The physics features have no causal counterpart yet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ..data import (
    Trace,
    causal_didt,
    demodulate_trace,
    didt,
    didt_period_samples,
    dither_period_mean,
    dither_period_samples,
    first_order_lag,
)
from ..errors import DataError

__all__ = [
    "BASE_FEATURES",
    "CAUSAL_COUNTERPART",
    "CAUSAL_DIDT_FEATURES",
    "DIDT_FEATURES",
    "FEATURES",
    "LAG_DIDT_FEATURES",
    "LOOKAHEAD_FEATURES",
    "PHYSICS_FEATURES",
    "FeatureBuilder",
    "causal_features",
    "direction_of_travel",
    "first_order_lag",
    "target_pressure",
]

#: Feature name → (unit, description).
FEATURES: MappingProxyType[str, tuple[str, str]] = MappingProxyType(
    {
        "current_mA": ("mA", "nominal VFS current"),
        "current_lag_mA": ("mA", "nominal VFS current through a first-order lag (lag_s)"),
        "dither_amp_mA": ("mA", "dither amplitude"),
        "dither_freq_Hz": ("Hz", "dither frequency"),
        "didt_mA_s": ("mA/s", "filtered dI/dt of the nominal current"),
        "direction": ("1", "last direction of travel of the nominal current (+1 / -1 / 0)"),
        "physics_bar": ("bar", "physics-model clutch pressure (dither-period mean)"),
        "physics_pilot_bar": ("bar", "physics-model pilot pressure (dither-period mean)"),
        "didt_causal_mA_s": ("mA/s", "causal dI/dt of the nominal current (trailing window)"),
        "direction_causal": ("1", "last direction of travel, from the causal dI/dt (+1/-1/0)"),
    }
)

#: The paper's stage-1 inputs.
BASE_FEATURES: tuple[str, ...] = ("current_mA", "dither_amp_mA", "dither_freq_Hz")
#: Features taken from the physics model's outputs (feature → model output).
PHYSICS_FEATURES: MappingProxyType[str, str] = MappingProxyType(
    {"physics_bar": "clutch_pressure_bar", "physics_pilot_bar": "pilot_pressure_bar"}
)
#: The paper's stage-2 inputs (stage 1 + dI/dt).
DIDT_FEATURES: tuple[str, ...] = (*BASE_FEATURES, "didt_mA_s", "direction")
#: The stage-2 inputs with the nominal current seen through the circuit's lag (the estimators'
#: default for stage 2 and 3; see :mod:`~clutchlab.residual_ml.lag`).
LAG_DIDT_FEATURES: tuple[str, ...] = ("current_lag_mA", *DIDT_FEATURES[1:])
#: Features computed with a centred window (they look ahead in time).
LOOKAHEAD_FEATURES: tuple[str, ...] = ("didt_mA_s", "direction", *PHYSICS_FEATURES)
#: Centred feature → its causal counterpart (past samples only).
CAUSAL_COUNTERPART: MappingProxyType[str, str] = MappingProxyType(
    {"didt_mA_s": "didt_causal_mA_s", "direction": "direction_causal"}
)
#: The stage-2 inputs with causal dI/dt and direction.
CAUSAL_DIDT_FEATURES: tuple[str, ...] = (*BASE_FEATURES, "didt_causal_mA_s", "direction_causal")


def causal_features(features: tuple[str, ...]) -> tuple[str, ...]:
    """``features`` with every centred feature replaced by its causal counterpart.

    Parameters
    ----------
    features : tuple of str
        Feature names (:data:`FEATURES`).

    Returns
    -------
    tuple of str
        Same order; features that are already causal are kept.

    Raises
    ------
    DataError
        If a feature has no causal counterpart (the physics features), naming it.
    """
    missing = [f for f in features if f in LOOKAHEAD_FEATURES and f not in CAUSAL_COUNTERPART]
    if missing:
        raise DataError(
            f"feature(s) {', '.join(missing)} have no causal counterpart (centred "
            "dither-period means of the physics outputs); leave them out for a causal model"
        )
    return tuple(CAUSAL_COUNTERPART.get(f, f) for f in features)


def _from_meta(trace: Trace, signal: str) -> np.ndarray | None:
    """A constant ``signal`` from the trace's manifest metadata (e.g. ``"dither_freq_Hz":
    50``), per sample in its unit, for a trace with neither the column nor a measured current
    to demodulate it from; None when the metadata hold no finite number ≥ 0."""
    value = trace.meta.get(signal)
    if isinstance(value, int | float) and not isinstance(value, bool) and value >= 0:
        if math.isfinite(value):
            return np.full(len(trace), float(value))
    return None


@dataclass(frozen=True)
class FeatureBuilder:
    """Builds the feature matrix of a trace.

    Parameters
    ----------
    features : tuple of str
        Feature names (:data:`FEATURES`), in column order.
    didt_periods : float
        Savitzky–Golay window of dI/dt, in dither periods (default 5; see
        :func:`clutchlab.data.nominal_didt`).
    deadband_mA_s : float
        |dI/dt| below which the direction of travel is held, mA/s (default 10: above the
        ~6 mA/s noise of dI/dt from a demodulated current, below the slowest stand ramp,
        27.5 mA/s).
    lag_s : float
        Time constant of ``current_lag_mA``, s (default 0: no lag; the estimators choose it
        from their training data, see :func:`clutchlab.residual_ml.select_lag`).
    """

    features: tuple[str, ...] = DIDT_FEATURES
    didt_periods: float = 5.0
    deadband_mA_s: float = 10.0
    lag_s: float = 0.0

    def __post_init__(self) -> None:
        unknown = [f for f in self.features if f not in FEATURES]
        if unknown or not self.features:
            raise DataError(f"unknown or no feature(s) {unknown}; known: {', '.join(FEATURES)}")
        if len(set(self.features)) != len(self.features):
            raise DataError(f"repeated feature in {self.features}")
        if not (np.isfinite(self.didt_periods) and self.didt_periods > 0):
            raise DataError(f"didt_periods must be > 0, got {self.didt_periods!r}")
        if not (np.isfinite(self.deadband_mA_s) and self.deadband_mA_s >= 0):
            raise DataError(f"deadband_mA_s must be >= 0, got {self.deadband_mA_s!r}")
        if not (np.isfinite(self.lag_s) and self.lag_s >= 0):
            raise DataError(f"lag_s must be >= 0 s, got {self.lag_s!r}")

    @property
    def names(self) -> tuple[str, ...]:
        """Feature names, in column order."""
        return tuple(self.features)

    @property
    def units(self) -> tuple[str, ...]:
        """Unit of each feature column."""
        return tuple(FEATURES[f][0] for f in self.features)

    @property
    def causal(self) -> bool:
        """Whether every feature uses past samples only (none of :data:`LOOKAHEAD_FEATURES`)."""
        return not any(f in LOOKAHEAD_FEATURES for f in self.features)

    @property
    def needs_physics(self) -> bool:
        """Whether a physics-model output is one of the features."""
        return any(f in PHYSICS_FEATURES for f in self.features)

    def build(self, trace: Trace, physics: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """Feature matrix of ``trace``.

        Parameters
        ----------
        trace : Trace
            Experiment with ``current_cmd_mA`` or ``current_mA`` (dither amplitude and
            frequency are demodulated from ``current_mA`` when not logged).
        physics : dict of str to numpy.ndarray, optional
            Physics-model outputs per sample (``clutch_pressure_bar``,
            ``pilot_pressure_bar``, bar, dither-period means); required for the physics
            features (:data:`PHYSICS_FEATURES`).

        Returns
        -------
        numpy.ndarray
            n × len(features) float64 matrix, columns in the units of :attr:`units`.

        Raises
        ------
        DataError
            If a needed signal cannot be obtained, or ``physics_bar`` is missing or of the
            wrong length.
        """
        if not isinstance(trace, Trace):
            raise DataError(f"expected a Trace, got {type(trace).__name__}")
        estimate = None

        def est(signal: str):
            nonlocal estimate
            if estimate is None:
                if not trace.has("current_mA"):
                    where = trace.name + (f" ({trace.source})" if trace.source else "")
                    raise DataError(
                        f"{where}: no {signal} column, and no measured current_mA to "
                        f"demodulate it from; the model's features need {signal}: log it, or "
                        f"give a constant ({signal} = ... under [defaults] in the channel map, "
                        "or in its manifest entry)"
                    )
                estimate = demodulate_trace(trace)
            return estimate

        cols: dict[str, np.ndarray] = {}
        need = set(self.features)
        slopes = {"didt_mA_s", "direction", "didt_causal_mA_s", "direction_causal"}
        if need & ({"current_mA", "current_lag_mA"} | slopes):
            if trace.has("current_cmd_mA"):
                cols["current_mA"] = np.asarray(trace.get("current_cmd_mA"), dtype=float)
            else:
                cols["current_mA"] = est("current_cmd_mA").nominal_mA
        if "current_lag_mA" in need:
            cols["current_lag_mA"] = first_order_lag(
                cols["current_mA"], self.lag_s, trace.sample_rate_Hz
            )

        def dither(signal: str, of_estimate: str) -> np.ndarray:
            # logged; else demodulated from the measured current; else, with no measured
            # current, the manifest's constant (as the physics model takes it)
            if trace.has(signal):
                return np.asarray(trace.get(signal), dtype=float)
            if not trace.has("current_mA") and (const := _from_meta(trace, signal)) is not None:
                return const
            return getattr(est(signal), of_estimate)

        if "dither_amp_mA" in need:
            cols["dither_amp_mA"] = dither("dither_amp_mA", "amplitude_mA")
        if need & ({"dither_freq_Hz"} | slopes):
            cols["dither_freq_Hz"] = dither("dither_freq_Hz", "frequency_Hz")
        if need & slopes:
            f = cols["dither_freq_Hz"]
            fpos = f[f > 0]
            fs = trace.sample_rate_Hz
            # no dither anywhere: the data layer's dI/dt window (a 50 Hz period), not 1 sample
            period = fs / float(np.median(fpos)) if fpos.size else didt_period_samples(trace)
            window = self.didt_periods * period
            if need & {"didt_mA_s", "direction"}:
                cols["didt_mA_s"] = didt(cols["current_mA"], fs, window)
                cols["direction"] = direction_of_travel(cols["didt_mA_s"], self.deadband_mA_s)
            if need & {"didt_causal_mA_s", "direction_causal"}:
                slope = causal_didt(cols["current_mA"], fs, window)
                cols["didt_causal_mA_s"] = slope
                cols["direction_causal"] = direction_of_travel(slope, self.deadband_mA_s)
        for feat, output in PHYSICS_FEATURES.items():
            if feat not in need:
                continue
            if physics is None or output not in physics:
                raise DataError(
                    f"trace {trace.name!r}: feature {feat!r} needs the physics output {output!r}"
                )
            p = np.asarray(physics[output], dtype=float)
            if p.shape != (len(trace),):
                raise DataError(
                    f"trace {trace.name!r}: physics output {output!r} has shape {p.shape}, "
                    f"expected ({len(trace)},)"
                )
            cols[feat] = p
        return np.column_stack([cols[f] for f in self.features])


def direction_of_travel(didt_mA_s: np.ndarray, deadband_mA_s: float = 10.0) -> np.ndarray:
    """Last direction of travel: sign of dI/dt where |dI/dt| > dead band, held in between.

    Parameters
    ----------
    didt_mA_s : numpy.ndarray
        dI/dt per sample, mA/s.
    deadband_mA_s : float
        Dead band, mA/s.

    Returns
    -------
    numpy.ndarray
        +1.0 / −1.0 per sample, 0.0 before the first sample outside the dead band.
    """
    d = np.asarray(didt_mA_s, dtype=float)
    sig = np.where(d > deadband_mA_s, 1.0, np.where(d < -deadband_mA_s, -1.0, 0.0))
    idx = np.where(sig != 0, np.arange(d.size), -1)
    last = np.maximum.accumulate(idx) if d.size else idx
    return np.where(last >= 0, sig[np.maximum(last, 0)], 0.0)


def target_pressure(
    trace: Trace, smoothing: str = "period_mean", signal: str = "clutch_pressure_bar"
) -> np.ndarray:
    """Regression target of a trace: its clutch pressure, bar.

    Parameters
    ----------
    trace : Trace
        Experiment with ``clutch_pressure_bar``.
    smoothing : {"period_mean", "raw"}
        ``period_mean`` (default): averaged over one dither period
        (:func:`clutchlab.data.dither_period_mean`), the primary scored signal; the features
        carry no dither phase, so the ripple is noise to the regression. ``raw``: as logged.
    signal : str
        Pressure signal to smooth (default ``clutch_pressure_bar``; ``line_pressure_bar`` for
        the latched plateau's reference).

    Returns
    -------
    numpy.ndarray
        Clutch pressure per sample, bar.
    """
    p = np.asarray(trace.get(signal), dtype=float)
    if smoothing == "raw":
        return p
    if smoothing != "period_mean":
        raise DataError(f"smoothing must be 'period_mean' or 'raw', got {smoothing!r}")
    return dither_period_mean(p, dither_period_samples(trace))
