"""Effect size on the stand: one outcome-blind rule for how strong an undeclared effect is.

A discovery test case needs a strength for the effect switched on at the stand. Picking
it by whether discovery then succeeds — worse, by the test-ramp error — makes the test
case part of the result. The rule here fixes it from the *truth* alone, before any
discovery runs, and the same way for every library effect:

    the effect's size parameters are set to ``m ×`` their stand defaults, with ``m`` such
    that the stand's dither-period-mean clutch pressure on the **training** ramps, outside
    the latch snaps, differs from the same stand with the effect off (same noise seed) by
    an RMS of :data:`TARGET_RMS_BAR`; if a parameter bound is reached first, ``m`` stops
    at the bound.

Nothing here fits a model, runs discovery or reads the test ramp. The size parameters are
the effect's strength parameters, scaled together along their defaults, except where the
size of an effect is not its strength (:data:`SIZE_PARAMETERS`): a lag at full strength
(κ = 1 is the exact lag) grows with its time constant, a transport delay with its delay
(its Padé filter delay moves with it, so that the truth stays an exact delay).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...data import dither_period_mean, dither_period_samples
from ...physics import CircuitModel
from ...physics.effects import EFFECTS
from ...physics.fit import FitSettings
from ...physics.fit.problem import snap_mask
from ...physics.stand import run_stand

__all__ = [
    "SIZE_PARAMETERS",
    "TARGET_RMS_BAR",
    "THREE_SETTING_EFFECTS",
    "EffectSize",
    "calibrate_effect_size",
    "effect_change_rms",
]

#: Target RMS change (bar) of the training ramps' period-mean pressure: five times the
#: ~0.02 bar floor the fitted base model reaches on the discovery stand without any
#: undeclared effect (latch-snap timing jitter), so that halving the error is possible.
TARGET_RMS_BAR = 0.10
#: Effects whose size is not their strength parameter (see the module docstring).
SIZE_PARAMETERS: dict[str, tuple[str, ...]] = {
    "sensor_lag": ("slag_tau",),
    "eddy_current_lag": ("eddy_tau",),
    "transport_delay": ("delay_d", "delay_d0"),
}
#: Effects that need several temperatures / dither shapes to be told apart: run on the
#: three-setting discovery stand (30 Hz/A at 40 °C, 50 Hz/B at 55 °C, 70 Hz/C at 70 °C).
THREE_SETTING_EFFECTS = frozenset({"oil_temperature", "dither_friction_reduction"})
#: Training ramps of the calibration (the discovery stand's fast and slow ramps).
TRAIN_RAMPS = ("fast", "slow")
#: Smallest multiplier scanned.
_M_MIN = 1.0 / 64.0


@dataclass(frozen=True)
class EffectSize:
    """Calibrated size of one effect on the discovery stand.

    Attributes
    ----------
    effect : str
        Library name.
    n_settings : int
        Dither settings of the stand it is calibrated (and tested) on.
    multiplier : float
        ``m``: the size parameters are ``m ×`` their defaults.
    overrides : dict
        The resulting truth values (engineering units).
    rms_bar : float
        RMS change of the training period-mean pressure at ``overrides`` (bar).
    default_rms_bar : float
        The same at the stand defaults (``m = 1``) (bar).
    at_bound : bool
        True when a bound stopped ``m`` before the target was reached.
    """

    effect: str
    n_settings: int
    multiplier: float
    overrides: dict[str, float]
    rms_bar: float
    default_rms_bar: float
    at_bound: bool

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return {
            "effect": self.effect,
            "n_settings": self.n_settings,
            "multiplier": self.multiplier,
            "overrides": dict(self.overrides),
            "rms_bar": self.rms_bar,
            "default_rms_bar": self.default_rms_bar,
            "at_bound": self.at_bound,
        }


def size_parameters(effect: str) -> tuple[str, ...]:
    """The parameters scaled to size ``effect`` (its strengths unless listed otherwise)."""
    if effect not in EFFECTS:
        raise KeyError(f"unknown effect {effect!r}; known: {sorted(EFFECTS)}")
    return SIZE_PARAMETERS.get(effect, tuple(EFFECTS[effect].STRENGTH))


def _specs(effect: str) -> dict:
    return {p.name: p for p in CircuitModel().with_effects(effect).parameters}


def multiplier_range(effect: str) -> tuple[float, float]:
    """Smallest and largest ``m`` keeping every size parameter ``m × default`` inside its
    bounds (the smallest at least ``1/64``)."""
    specs = _specs(effect)
    lo, hi = _M_MIN, math.inf
    for name in size_parameters(effect):
        d, s = specs[name].default, specs[name]
        if d == 0:
            continue
        a, b = sorted((s.lower / d, s.upper / d))
        lo, hi = max(lo, a), min(hi, b)
    return lo, hi


def _overrides(effect: str, m: float) -> dict[str, float]:
    specs = _specs(effect)
    return {n: m * specs[n].default for n in size_parameters(effect)}


def _training_means(effect: str | None, n_settings: int, overrides: dict, seed: int):
    # local import: scenarios imports this module (run_sized_case)
    from .scenarios import discovery_stand

    effects = (effect,) if effect else ()
    data = run_stand(
        discovery_stand(effects, n_settings=n_settings, overrides=overrides, seed=seed),
        progress=False,
    ).dataset
    out = {}
    for tr in data:
        if tr.ramp in TRAIN_RAMPS:
            y = dither_period_mean(tr.get("clutch_pressure_bar"), dither_period_samples(tr))
            out[tr.name] = (np.asarray(tr.get("time_s"), dtype=float), y)
    return out


def effect_change_rms(
    effect: str, overrides: dict[str, float], *, n_settings: int = 1, seed: int = 1, _ref=None
) -> float:
    """RMS change (bar) of the training ramps' period-mean pressure the effect causes.

    Stand with ``effect`` at ``overrides`` against the same stand with it off (same
    seed, so the noise cancels), over the fast and slow ramps, leaving out the samples
    within 50 ms of a latch snap of either run (the discovery's snap guard).

    Parameters
    ----------
    effect : str
        Library effect.
    overrides : dict
        Its truth values (engineering units).
    n_settings : {1, 3}
        Dither settings of the stand.
    seed : int
        Noise seed.

    Returns
    -------
    float
        RMS difference, bar.
    """
    ref = _ref if _ref is not None else _training_means(None, n_settings, {}, seed)
    on = _training_means(effect, n_settings, overrides, seed)
    rate = FitSettings().snap_rate_bar_s
    diffs = []
    for name, (t, y0) in ref.items():
        y1 = on[name][1]
        keep = snap_mask(y0, t, rate, 0.05) & snap_mask(y1, t, rate, 0.05)
        diffs.append((y1 - y0)[keep])
    d = np.concatenate(diffs)
    return float(np.sqrt(np.mean(d * d))) if d.size else 0.0


def calibrate_effect_size(
    effect: str, *, target_bar: float = TARGET_RMS_BAR, seed: int = 1, tol: float = 0.02
) -> EffectSize:
    """The multiplier of the effect's size at which it changes the training pressure by
    ``target_bar`` RMS (see the module docstring).

    A geometric scan from ``1/64`` up to the bound finds the first multiplier at or above
    the target; bisection (in ``log m``) refines it to a relative error ``tol`` of the
    RMS change.

    Parameters
    ----------
    effect : str
        Library effect.
    target_bar : float
        Target RMS change, bar.
    seed : int
        Noise seed of the stand (that of the discovery cases).
    tol : float
        Relative tolerance on the RMS change.

    Returns
    -------
    EffectSize
    """
    n_settings = 3 if effect in THREE_SETTING_EFFECTS else 1
    ref = _training_means(None, n_settings, {}, seed)

    def size(m: float) -> float:
        return effect_change_rms(effect, _overrides(effect, m), n_settings=n_settings, _ref=ref)

    default_rms = size(1.0)
    m, m_hi_limit = multiplier_range(effect)
    lo, hi, f_lo = 0.0, None, 0.0
    while True:
        m_eval = min(m, m_hi_limit)
        f = size(m_eval)
        if f >= target_bar:
            hi, f_hi = m_eval, f
            break
        lo, f_lo = m_eval, f
        if m_eval >= m_hi_limit:
            break
        m *= 2.0
    if hi is None:
        return EffectSize(effect, n_settings, lo, _overrides(effect, lo), f_lo, default_rms, True)
    best_m, best_f = hi, f_hi
    for _ in range(20):
        if abs(best_f - target_bar) <= tol * target_bar or lo <= 0.0:
            break
        mid = math.sqrt(lo * hi)
        f = size(mid)
        if f >= target_bar:
            hi, f_hi = mid, f
        else:
            lo, f_lo = mid, f
        best_m, best_f = (mid, f)
    return EffectSize(
        effect, n_settings, best_m, _overrides(effect, best_m), best_f, default_rms, False
    )
