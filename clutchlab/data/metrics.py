"""Error metrics of a predicted clutch pressure against the measured one (DESIGN §5 names)."""

from __future__ import annotations

import numpy as np

__all__ = ["pressure_metrics"]


def pressure_metrics(measured: np.ndarray, predicted: np.ndarray) -> dict[str, float]:
    """RMSE, MAE, max |e| (bar) and fit % = 100·(1 − ‖e‖/‖y − ȳ‖).

    Parameters
    ----------
    measured, predicted : array_like
        Clutch pressure (bar), same length; concatenate experiments before calling.

    Returns
    -------
    dict with ``rmse_bar``, ``mae_bar``, ``max_abs_bar``, ``fit_pct``. ``fit_pct`` is NaN
    when the measured pressure does not vary (no spread to explain), without a warning.
    """
    y = np.asarray(measured, dtype=float)
    p = np.asarray(predicted, dtype=float)
    if y.shape != p.shape or y.size == 0:  # checked before any broadcasting
        raise ValueError(
            f"measured {y.shape} and predicted {p.shape} must have the same shape, non-empty"
        )
    e = p - y
    spread = float(np.linalg.norm(y - y.mean()))
    fit = 100.0 * (1.0 - np.linalg.norm(e) / spread) if spread > 0 else np.nan
    return {
        "rmse_bar": float(np.sqrt(np.mean(e * e))),
        "mae_bar": float(np.mean(np.abs(e))),
        "max_abs_bar": float(np.max(np.abs(e))),
        "fit_pct": float(fit),
    }
