"""Single-sample prediction for co-simulation: one feature vector in, one pressure out.

:func:`step_predictor` freezes a fitted model into a :class:`StepPredictor` that holds its
arrays pre-scaled (GP bins divided by the length scales, SVM support vectors standardized)
and evaluates one sample with a handful of NumPy calls. The caller supplies the features in
the model's order (``feature_names_``), e.g. the nominal current, dither amplitude and
frequency, the filtered dI/dt and the direction of travel it keeps track of itself. For a
:class:`~clutchlab.residual_ml.hybrid.HybridModel` the step returns the residual plus the
``physics_bar`` feature: the physics model's own step (simulation or FMU) is not included.
"""

from __future__ import annotations

import numpy as np

from ..errors import ModelError
from .classifiers import KernelDecision, LinearDecision
from .estimators import GPBaseline, SVCPartitionedGP
from .hybrid import HybridModel
from .latch_local import LocalEventDecision, within_setting
from .local_gp import LocalGPRegressor

__all__ = ["StepPredictor", "step_predictor"]


class _GPStep:
    def __init__(self, gp: LocalGPRegressor) -> None:
        s2, ell, alpha = gp.kernel_.unpack(gp.theta_[:-1])
        self.shift = gp.x_mean_
        self.scale = gp.x_scale_ * ell
        self.zb = np.ascontiguousarray(gp.X_bins_ / ell)
        self.bb = np.einsum("ij,ij->i", self.zb, self.zb)
        self.coef = gp.dual_coef_ * (s2 * gp.y_scale_)
        self.y0 = gp.y_mean_
        self.rq = gp.kernel_.name == "rq"
        self.c = 0.5 / alpha if self.rq else -0.5
        self.alpha = alpha

    def __call__(self, x: np.ndarray) -> float:
        z = (x - self.shift) / self.scale
        d2 = self.zb @ z
        d2 *= -2.0
        d2 += self.bb
        d2 += z @ z
        d2 *= self.c
        if self.rq:
            np.log1p(d2, out=d2)
            d2 *= -self.alpha
        np.exp(d2, out=d2)
        return float(d2 @ self.coef) + self.y0


class _RBFStep:
    def __init__(self, dec: KernelDecision, cols: list[int]) -> None:
        self.cols = np.asarray(cols)
        self.mean, self.scale = dec.mean, dec.scale
        self.sv = np.ascontiguousarray(dec.support)
        self.ss = np.einsum("ij,ij->i", self.sv, self.sv)
        self.coef, self.b, self.g = dec.coef, dec.intercept, dec.gamma

    def __call__(self, x: np.ndarray) -> float:
        z = (x[self.cols] - self.mean) / self.scale
        d2 = self.sv @ z
        d2 *= 2.0
        d2 -= self.ss
        d2 -= z @ z
        d2 *= self.g
        np.exp(d2, out=d2)
        return float(d2 @ self.coef) + self.b


class _LinearStep:
    def __init__(self, dec: LinearDecision, cols: list[int]) -> None:
        self.cols = np.asarray(cols)
        self.w = dec.weights / dec.scale
        self.b = dec.intercept - float(dec.mean @ self.w)

    def __call__(self, x: np.ndarray) -> float:
        return float(x[self.cols] @ self.w) + self.b


class _LocalEventStep:
    """:class:`LocalEventDecision` for one feature vector, the direction's events only
    (:func:`~clutchlab.residual_ml.latch_local.local_law` with its per-event products
    computed once)."""

    def __init__(self, dec: LocalEventDecision, cols: list[int]) -> None:
        c = np.asarray(cols)[np.maximum(dec.columns, 0)]
        self.cols = [int(k) if j >= 0 else -1 for k, j in zip(c, dec.columns, strict=True)]
        self.s = 1.0 / np.asarray(dec.scale, dtype=float)
        self.h2 = -0.5 / dec.bandwidth**2
        self.h2_slope = -0.5 / dec.slope_bandwidth**2
        self.rho = dec.slope_prior
        self.uses_line = dec.uses_line
        self.line = (dec.line_coef, dec.line_reference)
        cens = np.asarray(dec.censored, dtype=float).reshape(-1, 3)
        # censored_share for one query: scaled coordinates of the latch-on events and of
        # the never-latched rows, and the rows' peak currents
        self.censored = (
            (dec.on[:, 2] * self.s[0], dec.on[:, 3] * self.s[1]),
            (cens[:, 1] * self.s[0], cens[:, 2] * self.s[1], cens[:, 0]),
        )
        self.branch = {}
        for side, ev in ((1, dec.on), (-1, dec.off)):
            di, dr = within_setting(ev, dec.scale, dec.bandwidth)
            i_k, r_k = ev[:, 0], ev[:, 1]
            # rows: I, İ, İ², İ·I, ΔI·Δİ, Δİ²
            table = np.ascontiguousarray(
                np.stack([i_k, r_k, r_k * r_k, r_k * i_k, di * dr, dr * dr])
            )
            self.branch[side] = (ev[:, 2] * self.s[0], ev[:, 3] * self.s[1], table)

    def __call__(self, x: np.ndarray, line_bar: float | None = None) -> float:
        i_raw, di, direction, a, f = (x[k] if k >= 0 else 0.0 for k in self.cols)
        i = i_raw
        if self.uses_line:
            if line_bar is None:
                raise ModelError("this model's latch decision follows line pressure: pass line_bar")
            i = i - self.line[0] * (line_bar - self.line[1])
        a_k, f_k, table = self.branch[1 if direction >= 0 else -1]
        d2 = (a * self.s[0] - a_k) ** 2 + (f * self.s[1] - f_k) ** 2
        d2 -= d2.min()
        w0 = np.exp(self.h2_slope * d2)
        _, _, mrr0, _, num, den = (table @ w0) / w0.sum()
        tau0 = num / den if den > 1e-6 * mrr0 and den > 0 else 0.0
        w = np.exp(self.h2 * d2)
        mi, mr, mrr, mri, _, _ = (table @ w) / w.sum()
        var_r = mrr - mr * mr
        lam = self.rho * mrr
        tau = ((mri - mr * mi) + lam * tau0) / (var_r + lam) if var_r + lam > 0 else 0.0
        d = float(i - (mi - tau * mr) - tau * di)
        (a_on, f_on), (a_c, f_c, peak) = self.censored
        if len(peak):
            q_on = (a * self.s[0] - a_on) ** 2 + (f * self.s[1] - f_on) ** 2
            q_c = (a * self.s[0] - a_c) ** 2 + (f * self.s[1] - f_c) ** 2
            low = min(q_on.min(), q_c.min())
            w_c = np.exp(self.h2 * (q_c - low))
            sw_c = w_c.sum()
            if sw_c > np.exp(self.h2 * (q_on - low)).sum():  # share > 1/2
                d = min(d, float(i_raw - peak[w_c >= 0.5 * w_c.max()].max()))
        return d


class StepPredictor:
    """Clutch pressure (bar) of one feature vector.

    Attributes
    ----------
    feature_names : list of str
        Expected feature order (units as in :data:`~clutchlab.residual_ml.features.FEATURES`).
    latched_line : bool
        The latched prediction is line pressure (``line_bar``) less the GP's offset.
    """

    def __init__(
        self,
        gps: dict,
        decide,
        single: int | None,
        physics_col: int | None,
        feature_names: list[str],
        latched_line: bool = False,
    ) -> None:
        self._gps = gps
        self._decide = decide
        self._single = single
        self._phys = physics_col
        self.feature_names = feature_names
        self.latched_line = latched_line

    def __call__(self, x, line_bar: float | None = None) -> float:
        """Prediction at one sample.

        Parameters
        ----------
        x : array_like
            One value per feature, in :attr:`feature_names` order and their units.
        line_bar : float, optional
            Line pressure (bar); required when :attr:`latched_line` (the model predicts
            the latched plateau relative to line pressure) and when the latch decision
            follows line pressure (a kept ``latch_line`` coupling).

        Returns
        -------
        float
            Clutch pressure, bar.
        """
        x = np.asarray(x, dtype=np.float64)
        if self._decide is None:
            g = self._single
        else:
            uses_line = getattr(self._decide, "uses_line", False)
            d = self._decide(x, line_bar) if uses_line else self._decide(x)
            g = 1 if d > 0 else 0
        out = self._gps[g](x)
        if self._phys is not None:
            out += x[self._phys]
        if self.latched_line and g == 1:
            if line_bar is None:
                raise ModelError(
                    "this model's latched plateau follows line pressure: pass line_bar"
                )
            out += line_bar
        return out


def step_predictor(model) -> StepPredictor:
    """Freeze a fitted model into a :class:`StepPredictor`.

    Parameters
    ----------
    model : GPBaseline, GPWithDerivative, SVCPartitionedGP or HybridModel
        Fitted model (a hybrid's residual model must be one of the first three).

    Raises
    ------
    ModelError
        If the model kind is not supported.
    """
    model._check_fitted()
    phys = None
    names = list(model.feature_names_)
    if isinstance(model, HybridModel):
        if "physics_bar" not in names and model.physics_ is not None:
            raise ModelError("a hybrid step needs 'physics_bar' among the residual features")
        phys = names.index("physics_bar") if "physics_bar" in names else len(names) - 1
        model = model.residual_
    if isinstance(model, GPBaseline):
        g = _GPStep(model.gp_)
        return StepPredictor({0: g, 1: g}, None, 0, phys, names)
    if isinstance(model, SVCPartitionedGP):
        gps = {g: _GPStep(gp) for g, gp in model.gps_.items()}
        for g in (0, 1):
            gps.setdefault(g, gps[1 - g])
        dec = model.decision_
        cols = list(model.classifier_columns_)
        if dec is None:
            decide = None
        elif isinstance(dec, KernelDecision):
            decide = _RBFStep(dec, cols)
        elif isinstance(dec, LinearDecision):
            decide = _LinearStep(dec, cols)
        elif isinstance(dec, LocalEventDecision):
            decide = _LocalEventStep(dec, cols)
        else:
            est = dec

            def decide(x):
                return float(est(x[cols][None, :])[0])

        line = getattr(model, "latched_reference_", "none") == "line"
        return StepPredictor(gps, decide, model.single_state_, phys, names, line)
    raise ModelError(f"no step predictor for a {type(model).__name__}")
