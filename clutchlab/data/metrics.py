"""Error metrics of a predicted clutch pressure against the measured one (DESIGN §5 names)."""

from __future__ import annotations

import numpy as np

__all__ = ["pressure_metrics"]


#: RMS variation (bar, relative to the mean pressure when above 1 bar) below which a
#: measured pressure counts as constant: far below any sensor's resolution.
_CONSTANT_RMS = 1e-9


def pressure_metrics(measured: np.ndarray, predicted: np.ndarray) -> dict[str, float]:
    """RMSE, MAE, max |e| (bar) and fit % = 100·(1 − ‖e‖/‖y − ȳ‖).

    Parameters
    ----------
    measured, predicted : array_like
        Clutch pressure (bar), same length; concatenate experiments before calling.

    Returns
    -------
    dict with ``rmse_bar``, ``mae_bar``, ``max_abs_bar``, ``fit_pct``. ``fit_pct`` is NaN
    when the measured pressure does not vary (no spread to explain, its RMS variation below
    1e-9 bar: rounding errors gave a fit of −6·10¹⁴ %), without a warning.
    """
    y = np.asarray(measured, dtype=float)
    p = np.asarray(predicted, dtype=float)
    if y.shape != p.shape or y.size == 0:  # checked before any broadcasting
        raise ValueError(
            f"measured {y.shape} and predicted {p.shape} must have the same shape, non-empty"
        )
    e = p - y
    spread = float(np.linalg.norm(y - y.mean()))
    # a constant pressure leaves a spread of rounding errors (1e-15 bar), not one to explain
    varies = spread / np.sqrt(y.size) > _CONSTANT_RMS * max(1.0, abs(float(y.mean())))
    fit = 100.0 * (1.0 - np.linalg.norm(e) / spread) if varies else np.nan
    return {
        "rmse_bar": float(np.sqrt(np.mean(e * e))),
        "mae_bar": float(np.mean(np.abs(e))),
        "max_abs_bar": float(np.max(np.abs(e))),
        "fit_pct": float(fit),
    }
