"""Latch-timing uncertainty: how far a predicted switch current may be off, and the
predictive distribution that gives near a predicted switch.

A latch-partitioned model predicts one latch state per sample. Where its switch current is
off by a few mA, the pressure it predicts around the switch is off by the whole snap (line
pressure minus the regulated pressure, several bar), while each regime's GP std is a few
hundredths of a bar: the GP std says nothing about *which* regime a sample is in. Here the
switch current is treated as uncertain, and near a predicted switch the prediction becomes a
two-component mixture of the two regimes' predictions.

**Switch-current error, per direction** (latch-on, latch-off; mA of the estimator's current
feature)::

    σ² = σ_fit² + (κ · ΔI)² · v(u)

* ``σ_fit``: RMS error of the switch currents predicted for each training experiment by a
  decision fitted without it (leave-one-experiment-out; the held-out experiment's ramp rate
  stays trained through the other dither settings). It includes a systematic offset.
* The rate term: at a ramp rate between two trained rates the decision interpolates the
  switch current, and two rates cannot tell how the switch current bends between them (the
  default stand's latch-off current is concave in the rate). The bend is modelled as the
  Brownian bridge of :mod:`~clutchlab.residual_ml.rate_bridge` in ``u = ln |dI/dt|``
  through the trained rates' mean switch currents (``v(u)`` there; ``ΔI`` the change of the
  mean switch current between the two bracketing rates). ``κ`` (``latch_rate_scale`` of the
  estimator, passed in as ``scale``; dimensionless) is calibrated on held-back
  *training-side* ramp rates (``studies/latch_timing.py``), never on the test ramp.

**Predictive distribution near a switch** predicted at current ``I*``: the other latch
state has probability ``p = Φ(−|I − I*| / σ)`` at a sample of current ``I``; the predictive
distribution is ``(1 − p)·N(μ_own, s_own²) + p·N(μ_other, s_other²)``. The mean stays the
point prediction (the most likely regime); the reported std is the half-width of the
mixture's interval around it that holds ``level`` of the mass, divided by the normal
quantile of ``level`` — a Gaussian of that std has the same interval, so ``±1.96 σ`` stays a
95 % band, and far from a switch (``p → 0``) it is the regime's own std.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr, ndtri

from .rate_bridge import bridge_weight, group_log_rates

__all__ = [
    "LatchTiming",
    "bridge_variance",
    "mixture_interval_std",
    "rate_anchors",
    "switch_errors",
    "switches",
]

#: Floor of σ (mA): below one current-quantization step the mixture is not resolved.
_SIGMA_FLOOR_MA = 0.5
#: Window around a predicted switch (σ): beyond it the other state's probability is < 3e-5.
_WINDOW_SIGMA = 4.0


def switches(state: np.ndarray) -> list[tuple[int, int]]:
    """Switches of a latch-state sequence: ``(first sample after, +1 on / −1 off)``."""
    s = np.asarray(state, dtype=np.int8)
    k = np.flatnonzero(np.diff(s) != 0) + 1
    return [(int(j), 1 if s[j] == 1 else -1) for j in k]


def switch_errors(
    measured: np.ndarray, predicted: np.ndarray, current_mA: np.ndarray
) -> tuple[dict[int, list[float]], dict[int, int]]:
    """Predicted minus measured switch current (mA) per direction, matched per switch.

    Each measured switch is matched to the nearest predicted switch of the same direction
    (by sample); a measured switch without one counts as missed.

    Parameters
    ----------
    measured, predicted : numpy.ndarray
        Latch state per sample (1 latched), measured and predicted.
    current_mA : numpy.ndarray
        The current the decision reads per sample, mA.

    Returns
    -------
    errors : dict of int to list of float
        ``{+1: [...], -1: [...]}``, mA.
    missed : dict of int to int
        Measured switches without a predicted one, per direction.
    """
    i = np.asarray(current_mA, dtype=float)
    pred = switches(predicted)
    errors: dict[int, list[float]] = {1: [], -1: []}
    missed = {1: 0, -1: 0}
    for k, d in switches(measured):
        cands = [j for j, e in pred if e == d]
        if not cands:
            missed[d] += 1
            continue
        j = min(cands, key=lambda c: abs(c - k))
        errors[d].append(float(i[j] - i[k]))
    return errors, missed


def rate_anchors(events: list[tuple[float, float, int]]) -> dict[int, tuple[list, list]]:
    """Mean switch current per trained ramp rate and direction.

    Parameters
    ----------
    events : list of (float, float, int)
        ``(|dI/dt| mA/s, switch current mA, direction)`` of the measured training switches.

    Returns
    -------
    dict of int to (list of float, list of float)
        Per direction: the log-rates ``ln(mA/s)`` of the rate groups (ascending,
        :func:`~.rate_bridge.group_log_rates`) and their mean switch currents (mA).
    """
    out: dict[int, tuple[list, list]] = {}
    for d in (1, -1):
        rows = [(np.log(max(r, 1e-9)), c) for r, c, e in events if e == d]
        groups = group_log_rates([u for u, _ in rows])
        out[d] = (
            [float(np.mean([rows[j][0] for j in g])) for g in groups],
            [float(np.mean([rows[j][1] for j in g])) for g in groups],
        )
    return out


def bridge_variance(u: float, log_rates: list[float], currents: list[float]) -> float:
    """``ΔI² · v(u)`` (mA²) at log-rate ``u`` (``ln(mA/s)``), :mod:`~.rate_bridge`'s bridge
    through the trained rates' mean switch currents."""
    c = np.asarray(currents, dtype=float)
    if c.size < 2 or not np.isfinite(u):
        return 0.0
    k, v = bridge_weight(u, log_rates)
    return float((c[k + 1] - c[k]) ** 2 * v)


@dataclass
class LatchTiming:
    """The switch-current error model of the module docstring, as fitted.

    Attributes
    ----------
    fit_rms_mA : dict of int to float
        ``σ_fit`` per direction (+1 latch-on, −1 latch-off), mA.
    log_rates, currents : dict of int to list of float
        Per direction, the trained rate groups' ``ln(|dI/dt| / (mA/s))`` and mean switch
        current (mA).
    n_errors, n_missed : dict of int to int
        Held-out switches scored and missed, per direction.
    """

    fit_rms_mA: dict[int, float]
    log_rates: dict[int, list[float]]
    currents: dict[int, list[float]]
    n_errors: dict[int, int] = field(default_factory=lambda: {1: 0, -1: 0})
    n_missed: dict[int, int] = field(default_factory=lambda: {1: 0, -1: 0})

    def sigma_mA(self, direction: int, rate_mA_s: float, scale: float) -> float:
        """σ of the switch current (mA) for a switch of ``direction`` at ``|dI/dt|`` rate
        (mA/s), with ``κ = scale`` (dimensionless)."""
        u = np.log(max(abs(rate_mA_s), 1e-9))
        var = self.fit_rms_mA[direction] ** 2 + scale**2 * bridge_variance(
            u, self.log_rates[direction], self.currents[direction]
        )
        return float(max(np.sqrt(var), _SIGMA_FLOOR_MA))

    def to_dict(self) -> dict:
        """JSON-ready form (direction keys ``"on"`` / ``"off"``)."""

        def by(d: dict) -> dict:
            return {"on": d[1], "off": d[-1]}

        return {
            "fit_rms_mA": by(self.fit_rms_mA),
            "log_rates": by(self.log_rates),
            "currents_mA": by(self.currents),
            "n_errors": by(self.n_errors),
            "n_missed": by(self.n_missed),
        }

    @classmethod
    def from_dict(cls, d: dict) -> LatchTiming:
        """Inverse of :meth:`to_dict`."""

        def un(x: dict, kind=float) -> dict:
            if kind is None:
                return {1: [float(v) for v in x["on"]], -1: [float(v) for v in x["off"]]}
            return {1: kind(x["on"]), -1: kind(x["off"])}

        return cls(
            fit_rms_mA=un(d["fit_rms_mA"]),
            log_rates=un(d["log_rates"], None),
            currents=un(d["currents_mA"], None),
            n_errors=un(d["n_errors"], int),
            n_missed=un(d["n_missed"], int),
        )

    def windows(
        self,
        classes: np.ndarray,
        current_mA: np.ndarray,
        didt_mA_s: np.ndarray | None,
        scale: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Samples near a predicted switch and the probability that their state is the other.

        Parameters
        ----------
        classes : numpy.ndarray
            Predicted latch state per sample.
        current_mA : numpy.ndarray
            The decision's current per sample, mA.
        didt_mA_s : numpy.ndarray or None
            dI/dt per sample, mA/s (None: no rate term).
        scale : float
            ``κ`` of the rate term (dimensionless).

        Returns
        -------
        rows : numpy.ndarray
            Sample indices (sorted, unique).
        p_other : numpy.ndarray
            Probability of the other latch state at each of ``rows`` (largest over the
            switches near it).
        """
        i = np.asarray(current_mA, dtype=float)
        n = i.size
        p = np.zeros(n)
        for k, d in switches(classes):
            rate = abs(float(didt_mA_s[k])) if didt_mA_s is not None else np.nan
            sigma = (
                self.sigma_mA(d, rate, scale)
                if np.isfinite(rate)
                else max(self.fit_rms_mA[d], _SIGMA_FLOOR_MA)
            )
            reach = _WINDOW_SIGMA * sigma
            lo = k
            while lo > 0 and abs(i[lo - 1] - i[k]) <= reach:
                lo -= 1
            hi = k
            while hi < n - 1 and abs(i[hi + 1] - i[k]) <= reach:
                hi += 1
            seg = slice(lo, hi + 1)
            p[seg] = np.maximum(p[seg], ndtr(-np.abs(i[seg] - i[k]) / sigma))
        rows = np.flatnonzero(p > 0)
        return rows, p[rows]


def mixture_interval_std(
    mean: np.ndarray,
    std: np.ndarray,
    other_mean: np.ndarray,
    other_std: np.ndarray,
    p_other: np.ndarray,
    level: float = 0.95,
) -> np.ndarray:
    """Std of the Gaussian whose ``level`` interval equals the mixture's around ``mean``.

    The mixture is ``(1 − p)·N(mean, std²) + p·N(other_mean, other_std²)``; its interval is
    ``mean ± h`` with the smallest ``h`` that holds ``level`` of the mass (found by
    bisection); the result is ``h / z`` with ``z`` the normal quantile of ``level``.

    Parameters
    ----------
    mean, std : numpy.ndarray
        Point prediction and its std (the own regime), bar.
    other_mean, other_std : numpy.ndarray
        The other regime's prediction and std, bar.
    p_other : numpy.ndarray
        Probability of the other regime.
    level : float
        Interval probability.

    Returns
    -------
    numpy.ndarray
        Equivalent std, bar (≥ ``std`` wherever ``p_other`` > 0).
    """
    s1 = np.maximum(np.asarray(std, dtype=float), 1e-12)
    s2 = np.maximum(np.asarray(other_std, dtype=float), 1e-12)
    delta = np.asarray(other_mean, dtype=float) - np.asarray(mean, dtype=float)
    p = np.clip(np.asarray(p_other, dtype=float), 0.0, 1.0)

    def mass(h):
        own = ndtr(h / s1) - ndtr(-h / s1)
        other = ndtr((h - delta) / s2) - ndtr((-h - delta) / s2)
        return (1 - p) * own + p * other

    z = float(ndtri(0.5 + level / 2))
    lo = np.zeros_like(s1)
    hi = np.abs(delta) + 10.0 * np.maximum(s1, s2)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        short = mass(mid) < level
        lo = np.where(short, mid, lo)
        hi = np.where(short, hi, mid)
    return np.maximum(hi / z, np.asarray(std, dtype=float))
