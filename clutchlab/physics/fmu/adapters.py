"""Fitted ``clutchlab.residual_ml`` estimators → :class:`FmuProgram` (duck-typed).

This module reads the fitted attributes of the estimators (``gp_``, ``gps_``, ``decision_``,
``feature_names_`` …) without importing :mod:`clutchlab.residual_ml`, which sits above the
physics layer. Only models whose features the FMU computes exactly from its inputs are
exported as they are: the nominal current, dither amplitude and frequency. The offline
dI/dt is a centred Savitzky–Golay slope (it looks ahead); with ``causal_didt=True`` the FMU
uses the causal slope of :class:`~.ml.DidtSpec` instead and lags at ramp reversals.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_solve

from .errors import FmuError
from .ml import DecisionSpec, DidtSpec, GPSpec, ml_program
from .program import FmuProgram

__all__ = ["EXACT_FEATURES", "decision_spec", "gp_spec", "ml_program_from"]

#: Features an FMU computes exactly as the offline estimators do.
EXACT_FEATURES: tuple[str, ...] = ("current_mA", "dither_amp_mA", "dither_freq_Hz")


def gp_spec(gp, with_std: bool = True) -> GPSpec:
    """The :class:`GPSpec` of a fitted ``LocalGPRegressor``."""
    s2, ell, alpha = gp.kernel_.unpack(gp.theta_[:-1])
    d = gp.X_bins_.shape[1]
    k_inv = None
    if with_std:
        L = gp._factor()
        k_inv = cho_solve((L, True), np.eye(L.shape[0]))
    return GPSpec(
        kernel=gp.kernel_.name,
        x_mean=np.asarray(gp.x_mean_, dtype=float),
        x_scale=np.asarray(gp.x_scale_, dtype=float),
        length_scales=np.broadcast_to(np.asarray(ell, dtype=float), (d,)).copy(),
        alpha=float(alpha) if np.isfinite(alpha) else 1.0,
        points=np.asarray(gp.X_bins_, dtype=float),
        weights=np.asarray(gp.dual_coef_, dtype=float) * s2 * gp.y_scale_,
        y_mean=float(gp.y_mean_),
        signal_var=float(s2),
        y_scale=float(gp.y_scale_),
        k_inv=k_inv,
    )


def decision_spec(decision, columns=None) -> DecisionSpec:
    """The :class:`DecisionSpec` of a lean decision function (RBF-SVC or linear)."""
    cols = tuple(int(c) for c in columns) if columns is not None else None
    kind = getattr(decision, "kind", None)
    if kind == "rbf_svc":
        return DecisionSpec(
            "rbf",
            decision.mean,
            decision.scale,
            float(decision.intercept),
            support=decision.support,
            coef=decision.coef,
            gamma=float(decision.gamma),
            columns=cols,
        )
    if kind == "linear":
        return DecisionSpec(
            "linear",
            decision.mean,
            decision.scale,
            float(decision.intercept),
            weights=decision.weights,
            columns=cols,
        )
    raise FmuError(
        f"cannot export the latch classifier {type(decision).__name__}: only RBF-SVC and "
        "linear decision functions are exported"
    )


def ml_program_from(
    model,
    with_std: bool = True,
    causal_didt: bool = False,
    name: str | None = None,
) -> FmuProgram:
    """The FMU program of a fitted ``GPBaseline`` / ``GPWithDerivative`` / ``SVCPartitionedGP``.

    Parameters
    ----------
    model : estimator
        Fitted; its ``feature_names_`` must be among :data:`EXACT_FEATURES`, plus
        ``didt_mA_s`` when ``causal_didt``.
    with_std : bool
        Output the predictive standard deviation (an n × n product per step).
    causal_didt : bool
        Compute ``didt_mA_s`` causally (see the module docstring).
    name : str, optional
        Model identifier (default ``clutch_<class name>``).

    Raises
    ------
    FmuError
        For a hybrid model, a feature the FMU cannot compute, or a classifier it cannot export.
    """
    kind = type(model).__name__
    if hasattr(model, "residual_"):
        raise FmuError(
            f"cannot export the {kind} yet: its residual features are dither-period means of "
            "the physics outputs (a centred window that looks ahead), which a real-time FMU "
            "cannot compute; see ml_program(physics=...) for hybrids with causal features"
        )
    names = tuple(getattr(model, "feature_names_", ()))
    allowed = EXACT_FEATURES + (("didt_mA_s",) if causal_didt else ())
    bad = [f for f in names if f not in allowed]
    if bad:
        hint = (
            " (didt_mA_s: pass causal_didt=True to use a causal slope, which lags by half "
            "its window at ramp reversals)"
            if "didt_mA_s" in bad
            else ""
        )
        raise FmuError(
            f"cannot export the {kind}: the FMU cannot compute the feature(s) "
            f"{', '.join(bad)} as the model was trained on them{hint}"
        )
    didt = DidtSpec(periods=float(model.didt_periods)) if "didt_mA_s" in names else None
    ident = name or f"clutch_{kind.lower()}"
    if hasattr(model, "gp_"):
        return ml_program(
            gp_spec(model.gp_, with_std), names, didt=didt, with_std=with_std, name=ident
        )
    gps = {g: gp_spec(gp, with_std) for g, gp in model.gps_.items()}
    decision = None
    if model.decision_ is not None:
        decision = decision_spec(model.decision_, getattr(model, "classifier_columns_", None))
    elif len(gps) > 1:
        raise FmuError(f"cannot export the {kind}: two GPs but no decision function")
    if decision is None:
        gps = {0: next(iter(gps.values()))}
    return ml_program(gps, names, decision=decision, didt=didt, with_std=with_std, name=ident)
