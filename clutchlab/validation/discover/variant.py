"""The ``augmented_hybrid`` variant (DESIGN §5): physics after closing the loop + residual GP.

:class:`AugmentedPhysics` runs :func:`~.loop.discover` on the training experiments it is
given (the protocol hands it nothing else) and predicts with the augmented, refitted model;
:class:`AugmentedHybrid` puts the residual model of ``hybrid``
(:class:`clutchlab.residual_ml.HybridModel`) on top of it. :func:`register` adds the
variant to :mod:`clutchlab.validation.variants`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from ...data import Trace
from ..variants import VariantContext, VariantSpec, get_variant, register_variant
from .loop import discover
from .settings import DiscoverySettings

__all__ = ["AugmentedHybrid", "AugmentedPhysics", "register"]


def _check_fitted(model: Any, attr: str) -> None:
    if not hasattr(model, attr):
        raise NotFittedError(f"this {type(model).__name__} is not fitted yet; call fit(traces)")


class AugmentedPhysics(BaseEstimator):
    """Circuit model augmented by :func:`discover` on the training experiments, refitted.

    Parameters
    ----------
    model : CircuitModel, optional
        Starting structure (effects already declared); the base circuit by default.
    settings : DiscoverySettings, optional
        Discovery settings. Every experiment handed to :meth:`fit` is trained on:
        ``fit.train_ramps`` is set to their ramp labels and ``test_ramps`` to none.
    baseline : FitResult, optional
        A physics fit of ``model`` on the same training experiments (``physics_fitted``'s):
        the discovery starts from it instead of fitting the base model again.

    Attributes
    ----------
    result_ : DiscoveryResult
        The discovery (evidence, effects added, errors before and after on training).
    effects_ : list of str
        Effects added.
    model_, params_ : CircuitModel, ParameterSet
        The augmented model and its fitted parameters (engineering units).
    train_experiments_ : list of str
        Names of the experiments fitted on.
    """

    def __init__(
        self, model: Any = None, settings: DiscoverySettings | None = None, baseline: Any = None
    ) -> None:
        self.model = model
        self.settings = settings
        self.baseline = baseline

    def fit(self, traces: Sequence[Trace]) -> AugmentedPhysics:
        """Discover and add the missing effects on ``traces``; returns self.

        Raises
        ------
        FitError
            When the baseline model cannot be fitted at all.
        """
        traces = list(traces)
        base = self.settings or DiscoverySettings(progress=False)
        ramps = tuple(dict.fromkeys(str(t.ramp) for t in traces))
        settings = replace(base, fit=replace(base.fit, train_ramps=ramps), test_ramps=())
        self.result_ = discover(traces, self.model, settings, baseline=self.baseline)
        self.effects_ = list(self.result_.added)
        self.model_ = self.result_.best_model
        self.params_ = self.result_.params
        self.train_experiments_ = [t.name for t in traces]
        return self

    def predict_outputs(self, trace: Trace) -> dict[str, np.ndarray]:
        """Every output of the augmented model on ``trace`` (name → per-sample array; bar)."""
        from ...physics import simulate

        _check_fitted(self, "model_")
        res = simulate(self.model_, self.params_, trace)
        return {k: np.asarray(v, dtype=float) for k, v in res.outputs.items()}

    def predict(self, trace: Trace) -> np.ndarray:
        """Clutch pressure (bar) of the augmented model on ``trace``."""
        return self.predict_outputs(trace)["clutch_pressure_bar"]


class AugmentedHybrid(BaseEstimator):
    """``augmented_hybrid``: :class:`AugmentedPhysics` plus the hybrid's residual model.

    Parameters
    ----------
    physics : AugmentedPhysics, optional
        Unfitted augmented physics (default settings by default); fitted in :meth:`fit`.
    residual : object, optional
        Residual model of :class:`clutchlab.residual_ml.HybridModel` (its default when None).
    hybrid : HybridModel, optional
        The ``hybrid`` variant, fitted on the same experiments on the physics fit that
        ``physics.baseline`` is: when the discovery adds no effect, the augmented physics
        *is* that fit, and this hybrid is taken as it is instead of being fitted again.

    Attributes
    ----------
    physics_ : AugmentedPhysics
        The fitted augmented physics.
    hybrid_ : HybridModel
        Physics plus the residual model fitted on its training residual.
    """

    def __init__(
        self, physics: AugmentedPhysics | None = None, residual: Any = None, hybrid: Any = None
    ) -> None:
        self.physics = physics
        self.residual = residual
        self.hybrid = hybrid

    def fit(self, traces: Sequence[Trace]) -> AugmentedHybrid:
        """Close the loop on ``traces``, then fit the residual model; returns self."""
        from ...residual_ml import HybridModel

        traces = list(traces)
        phys = self.physics if self.physics is not None else AugmentedPhysics()
        self.physics_ = phys.fit(traces)
        self.reused_hybrid_ = self._unchanged(traces)
        if self.reused_hybrid_:
            self.hybrid_ = self.hybrid
        else:
            self.hybrid_ = HybridModel(physics=self.physics_, residual=self.residual).fit(traces)
        self.train_experiments_ = [t.name for t in traces]
        return self

    def _unchanged(self, traces: list[Trace]) -> bool:
        """Whether the given ``hybrid`` can stand for this one: nothing added, the discovery
        ended at its baseline fit, the hybrid stands on that very fit, was fitted on these
        experiments, and with the residual model asked for here."""
        base = self.physics_.baseline
        if self.hybrid is None or base is None or self.physics_.effects_:
            return False
        on_base = getattr(getattr(self.hybrid, "physics", None), "result_", None) is base
        names = sorted(t.name for t in traces)
        trained = sorted(getattr(self.hybrid, "train_experiments_", []) or [])
        same = dict(self.physics_.params_.values) == dict(base.params().values)
        same_residual = getattr(self.hybrid, "residual", None) is self.residual
        return on_base and same and trained == names and same_residual

    def predict(self, trace: Trace, return_std: bool = False):
        """Clutch pressure (bar) on ``trace``; with ``return_std`` also its std (bar)."""
        _check_fitted(self, "hybrid_")
        if return_std:
            return self.hybrid_.predict(trace, return_std=True)
        return self.hybrid_.predict(trace)


def _build(ctx: VariantContext) -> AugmentedHybrid:
    options = dict(ctx.options.get("augmented_hybrid", {}))
    settings = options.pop("settings", None)
    # a moment on time.perf_counter by which the discovery must end (the demo's budget):
    # its time limit is what is left when the variant is built, just before it runs
    deadline = options.pop("discovery_deadline", None)
    if settings is None:
        fit = ctx.physics_settings
        settings = DiscoverySettings(progress=ctx.progress)
        if fit is not None:
            settings = replace(settings, fit=fit)
    if deadline is not None:
        left = max(float(deadline) - time.perf_counter(), 1.0)
        own = settings.time_limit_s
        settings = replace(settings, time_limit_s=left if own is None else min(own, left))
    hybrid = ctx.fitted.get("hybrid")
    physics = getattr(hybrid, "physics", None)
    baseline = getattr(physics, "result_", None)
    physics = AugmentedPhysics(ctx.physics_model, settings, baseline=baseline)
    return AugmentedHybrid(physics=physics, hybrid=hybrid, **options)


def _available() -> str | None:
    try:
        reason = get_variant("hybrid").availability()
    except KeyError:
        return "the hybrid variant is not registered"
    return None if reason is None else f"needs the hybrid's residual model: {reason}"


def register(replace_existing: bool = False) -> VariantSpec:
    """Register ``augmented_hybrid`` with :func:`clutchlab.validation.variants.register_variant`.

    Parameters
    ----------
    replace_existing : bool
        Replace an already registered ``augmented_hybrid``.

    Returns
    -------
    VariantSpec
    """
    spec = VariantSpec(
        "augmented_hybrid",
        "physics after closing the loop (discover: effects added, refitted) "
        "+ SVC-partitioned GP on its residual",
        _build,
        requires=("hybrid",),
        availability=_available,
        layer="validation.discover",
        on_request=(
            "fitting it runs a whole closing-the-loop discovery (minutes to tens of minutes); "
            "ask for it by name (clutchlab evaluate --variants ...,augmented_hybrid)"
        ),
    )
    return register_variant(spec, replace=replace_existing)
