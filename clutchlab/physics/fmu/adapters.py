"""Fitted ``clutchlab.residual_ml`` estimators → :class:`FmuProgram` (duck-typed).

This module reads the fitted estimators through their public surface (``feature_names_``,
``gp_`` / ``gps_`` and ``LocalGPRegressor.prediction_arrays``, ``decision_`` …) without
importing :mod:`clutchlab.residual_ml`, which sits above the physics layer.

A model is exported **exactly** when the FMU computes every feature as training did: the
nominal current, dither amplitude and frequency (inputs), the lagged current
``current_lag_mA`` (first-order lag, :class:`~.ml.LagSpec`, time constant ``lag_s_``), and
the causal features ``didt_causal_mA_s`` / ``direction_causal`` (trailing-window slope and
the direction it implies, :class:`~.ml.DidtSpec`) of a model trained with
``clutchlab train --causal``. A
model trained on the centred features (``didt_mA_s``, ``direction``: Savitzky–Golay slope
centred on the sample, i.e. looking half a window ahead) is refused, unless
``approximate_didt=True``: then the FMU substitutes the causal slope and direction, which
lag the centred ones by half a window and move the model's output at ramp reversals (up to
~0.1 bar on the default stand). Models using the physics features (dither-period means
centred on the sample) are refused: they have no causal form.

A hybrid (``HybridModel``) in its standalone form (``form_ == "standalone"``) is exported
as its ML model alone. Otherwise it is exported as its physics (command drive) plus its residual
model, when the physics is a :class:`~clutchlab.residual_ml.physics.PhysicsPredictor`
(effects + parameter values) and the residual's features are exact.
"""

from __future__ import annotations

import numpy as np

from .errors import FmuError
from .ml import DecisionSpec, DidtSpec, GPSpec, LagSpec, ml_program
from .program import FmuProgram

__all__ = [
    "CAUSAL_FEATURES",
    "EXACT_FEATURES",
    "decision_spec",
    "gp_spec",
    "ml_program_from",
    "std_terms_not_exported",
]

#: Features an FMU reads from its inputs exactly as the offline estimators do.
EXACT_FEATURES: tuple[str, ...] = ("current_mA", "dither_amp_mA", "dither_freq_Hz")
#: Causal features the FMU computes exactly as the offline feature builder does.
CAUSAL_FEATURES: tuple[str, ...] = ("current_lag_mA", "didt_causal_mA_s", "direction_causal")
#: Centred features and the causal ones substituted with ``approximate_didt``.
_APPROXIMATE = {"didt_mA_s": "didt_causal_mA_s", "direction": "direction_causal"}
_DEFAULT_DEADBAND_MA_S = 10.0


def gp_spec(gp, with_std: bool = True, noise: bool = False) -> GPSpec:
    """The :class:`GPSpec` of a fitted ``LocalGPRegressor`` (its ``prediction_arrays``).

    With ``with_std`` the spec carries the estimator's std bins and their ``L⁻¹``: the FMU
    computes the same predictive standard deviation (bar) as ``predict(return_std=True)``,
    the GP's std given the coarse std bins (at most ``max_std_points``); with ``noise``
    the GP's observation noise is added, as the trace estimators' std has it.
    """
    a = gp.prediction_arrays(inverse=with_std)
    alpha = a["alpha"]
    spec = GPSpec(
        kernel=a["kernel"],
        x_mean=a["x_mean"],
        x_scale=a["x_scale"],
        length_scales=a["length_scales"],
        alpha=float(alpha) if np.isfinite(alpha) else 1.0,
        points=a["points"],
        weights=a["weights"],
        y_mean=a["y_mean"],
        signal_var=a["signal_var"],
        y_scale=a["y_scale"],
        l_inv=a["std_l_inv"],
        std_points=a["std_points"] if with_std else None,
        noise_var=float(gp.noise_var_) if noise else 0.0,
    )
    return spec


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
    if kind in ("event", "local_event"):
        # The laws read their own columns: no standardization (mean 0, scale 1, unused).
        n = len(cols) if cols is not None else int(max(decision.columns)) + 1
        common = {"columns": cols, "event_columns": tuple(int(c) for c in decision.columns)}
        if kind == "event":
            return DecisionSpec(
                "event",
                np.zeros(n),
                np.ones(n),
                0.0,
                event_on=np.asarray(decision.on, dtype=float),
                event_off=np.asarray(decision.off, dtype=float),
                **common,
            )
        return DecisionSpec(
            "local_event",
            np.zeros(n),
            np.ones(n),
            0.0,
            gamma=float(decision.bandwidth),
            event_on=decision.events_with_deviations(decision.on),
            event_off=decision.events_with_deviations(decision.off),
            event_scale=np.asarray(decision.scale, dtype=float),
            event_slope=np.array([decision.slope_bandwidth, decision.slope_prior], dtype=float),
            event_line=(
                np.array([decision.line_coef, decision.line_reference], dtype=float)
                if decision.uses_line
                else None
            ),
            event_censored=(
                np.asarray(decision.censored, dtype=float) if len(decision.censored) else None
            ),
            **common,
        )
    raise FmuError(
        f"cannot export the latch classifier {type(decision).__name__}: only RBF-SVC, "
        "linear and latch-event decision functions are exported"
    )


def _fmu_features(model, kind: str, approximate_didt: bool) -> tuple[str, ...]:
    """The model's features as the FMU names them; FmuError for those it cannot compute."""
    names = tuple(getattr(model, "feature_names_", ()))
    allowed = EXACT_FEATURES + CAUSAL_FEATURES + (tuple(_APPROXIMATE) if approximate_didt else ())
    bad = [f for f in names if f not in allowed]
    if bad:
        centred = [f for f in bad if f in _APPROXIMATE]
        other = [f for f in bad if f not in _APPROXIMATE]
        lines = []
        if centred:
            lines.append(
                f"{', '.join(centred)}: centred filters (they look half a window ahead); "
                "retrain with `clutchlab train ... --causal` (features "
                f"{', '.join(_APPROXIMATE[f] for f in centred)}) for an exact FMU, or export "
                "with --approximate-didt (causal stand-ins; the output moves at ramp "
                "reversals)"
            )
        if other:
            lines.append(
                f"{', '.join(other)}: not computable in real time (physics features are "
                "dither-period means centred on the sample)"
            )
        raise FmuError(
            f"cannot export the {kind}: the FMU cannot compute the feature(s) "
            f"{', '.join(bad)} as the model was trained on them:\n  - " + "\n  - ".join(lines)
        )
    return tuple(_APPROXIMATE.get(f, f) for f in names)


def _didt_spec(model, features: tuple[str, ...]) -> DidtSpec | None:
    if not any(f in ("didt_causal_mA_s", "direction_causal") for f in features):
        return None
    builder = getattr(model, "_builder", None)
    deadband = getattr(builder(), "deadband_mA_s", None) if callable(builder) else None
    return DidtSpec(
        periods=float(getattr(model, "didt_periods", 5.0)),
        deadband_mA_s=float(deadband if deadband is not None else _DEFAULT_DEADBAND_MA_S),
    )


def _physics_program(hybrid, kind: str):
    """The physics program (command drive) of a hybrid's physics."""
    from ..model import CircuitModel
    from .physics import physics_program

    phys = getattr(hybrid, "physics_", None)
    needed = ("effects", "params", "substeps")
    if phys is None or not all(hasattr(phys, a) for a in needed):
        raise FmuError(
            f"cannot export the {kind}: its physics ({type(phys).__name__}) is not a "
            "PhysicsPredictor (effects + parameter values); a hybrid trained on an imported "
            "FMU needs that FMU beside it and cannot be re-exported"
        )
    model = CircuitModel().with_effects(*phys.effects)
    origin = {"source": "hybrid", "summary": "those of the trained hybrid's physics"}
    return physics_program(
        model,
        model.params(**phys.params),
        "command",
        substeps=int(phys.substeps),
        origin=origin,
    )


def std_terms_not_exported(model) -> list[str]:
    """The terms of a fitted ML model's predictive std that its FMU's std does not have.

    Parameters
    ----------
    model : estimator
        A fitted ``GPBaseline`` / ``GPWithDerivative`` / ``SVCPartitionedGP`` /
        ``HybridModel`` (a hybrid: its residual model's, or its standalone model's).

    Returns
    -------
    list of str
        One phrase per term the fitted model uses (empty: the FMU's std is the model's).
    """
    est = getattr(model, "residual_", model)
    out = []
    if getattr(est, "latch_uncertainty", "none") != "none" and (
        getattr(est, "latch_timing_", None) is not None
    ):
        out.append("latch-timing mixture (latch_uncertainty)")
    if getattr(est, "rate_uncertainty", "none") != "none" and (
        len(getattr(est, "train_log_rates_", [])) >= 2
    ):
        out.append("rate bridge between the trained ramp rates (rate_uncertainty)")
    if getattr(est, "variance_floor_", None) is not None:
        out.append("leave-one-experiment-out residual-variance floor (residual_variance)")
    if getattr(est, "noise_by_freq_", None):
        out.append("per-dither-frequency noise floor (noise_model)")
    return out


def ml_program_from(
    model,
    with_std: bool = True,
    approximate_didt: bool = False,
    name: str | None = None,
    step_s: float = 1e-3,
    stop_time_s: float = 23.0,
) -> FmuProgram:
    """The FMU program of a fitted ``GPBaseline`` / ``GPWithDerivative`` /
    ``SVCPartitionedGP`` / ``HybridModel``.

    Parameters
    ----------
    model : estimator
        Fitted. Its features (a hybrid's: its residual model's) must be among
        :data:`EXACT_FEATURES` and :data:`CAUSAL_FEATURES`.
    with_std : bool
        Output the predictive standard deviation (bar): the regime GP's std given its
        coarse std bins, with the GP's constant observation noise (see
        :class:`~.ml.GPSpec`). That is the estimator's std only without the terms
        :func:`std_terms_not_exported` lists for it: a partitioned model's latch-timing
        mixture (it widens the band *before* a predicted switch too, which a causal FMU
        cannot know), the rate bridge between trained ramp rates (two more GP means per
        step), the leave-one-experiment-out residual-variance floor and the per-frequency
        noise floor. Where the model has them, the FMU's std is smaller than
        ``predict(return_std=True)``'s.
    approximate_didt : bool
        Accept the centred ``didt_mA_s`` / ``direction`` and compute causal stand-ins: the
        FMU then differs from the model at ramp reversals (approximate export).
    name : str, optional
        Model identifier (default ``clutch_<class name>``).
    step_s : float
        Communication step of the FMU's default experiment (s). The FMU is correct at any
        communication step: its causal dI/dt resamples the current to the 1 ms samples of
        the features (:class:`~.ml.DidtSpec`) and a longer step is split internally.
    stop_time_s : float
        Default experiment stop time (s).

    Raises
    ------
    FmuError
        For a feature the FMU cannot compute (naming it and what to do), a classifier it
        cannot export, or a hybrid whose physics is not a PhysicsPredictor.
    """
    kind = type(model).__name__
    ident = name or f"clutch_{kind.lower()}"
    physics = None
    est = model
    if getattr(model, "form_", "residual") == "physics":
        raise FmuError(
            f"this {kind} chose its physics form (its residual model did not generalize in "
            "leave-one-experiment-out): export the physics fit itself "
            "(`clutchlab export-fmu FIT.json`)"
        )
    if hasattr(model, "residual_") and getattr(model, "form_", "residual") == "standalone":
        # A hybrid that chose its standalone form predicts with its ML model alone.
        est = model.residual_
        features = _fmu_features(est, kind, approximate_didt)
    elif hasattr(model, "residual_"):
        est = model.residual_
        features = _fmu_features(est, kind, approximate_didt)
        physics = _physics_program(model, kind)
    else:
        features = _fmu_features(model, kind, approximate_didt)
    didt = _didt_spec(est, features)
    lag = LagSpec(float(getattr(est, "lag_s_", 0.0))) if "current_lag_mA" in features else None
    if hasattr(est, "gp_"):
        gps = {0: gp_spec(est.gp_, with_std, noise=True)}
        decision = None
    else:
        gps = {g: gp_spec(gp, with_std, noise=True) for g, gp in est.gps_.items()}
        decision = None
        if est.decision_ is not None:
            decision = decision_spec(est.decision_, getattr(est, "classifier_columns_", None))
        elif len(gps) > 1:
            raise FmuError(f"cannot export the {kind}: two GPs but no decision function")
        else:
            gps = {0: next(iter(gps.values()))}
    return ml_program(
        gps,
        features,
        decision=decision,
        didt=didt,
        physics=physics,
        with_std=with_std,
        name=ident,
        lag=lag,
        latched_line=getattr(est, "latched_reference_", "none") == "line",
        step_s=step_s,
        stop_time_s=stop_time_s,
    )
