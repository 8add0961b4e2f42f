"""The compared variants (DESIGN §5): one registry, whichever layer a model comes from.

A variant is a name and a factory that returns an **unfitted** model with

- ``fit(train_traces) -> self`` — receives the training experiments only, and
- ``predict(trace) -> ndarray`` — clutch pressure per sample (bar); optionally
  ``predict(trace, return_std=True) -> (mean, std)`` (bar).

The protocol neither knows nor cares whether the model is physics or machine learning.
Variants of :mod:`clutchlab.residual_ml` appear as soon as that package provides them
(:func:`available_variants`); later ones (``augmented_hybrid``, closing the loop) are added
with :func:`register_variant`.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from ..data import Trace
from ..errors import ClutchlabError, FitError

__all__ = [
    "DESIGN_VARIANTS",
    "FMU_VARIANT",
    "DefaultPhysics",
    "FittedPhysics",
    "VariantContext",
    "VariantSpec",
    "available_variants",
    "fmu_variants",
    "get_variant",
    "predict_with_std",
    "register_variant",
    "supports_std",
    "unavailable_variants",
    "variant_names",
]

#: The variants of DESIGN §5, in report order.
DESIGN_VARIANTS: tuple[str, ...] = (
    "physics_default",
    "physics_fitted",
    "gp_base",
    "gp_didt",
    "paper_svc_gp",
    "hybrid",
    "augmented_hybrid",
)


@dataclass(frozen=True)
class VariantContext:
    """What a variant factory may use to build its (unfitted) model.

    Attributes
    ----------
    fitted : mapping of str to object
        Fitted models of the variants listed in the spec's ``requires`` (e.g. ``hybrid``
        gets the fitted ``physics_fitted``).
    physics_model : CircuitModel or None
        Model structure (effects) of ``physics_fitted``; the base circuit when None.
    physics_settings : FitSettings or None
        Settings of the physics fit; the defaults when None. Its ``train_ramps`` is
        irrelevant: the protocol hands the fit the training experiments only.
    options : mapping of str to mapping
        Extra keyword arguments per variant name, passed to the model's constructor.
    progress : bool
        Whether models may show progress bars.
    random_state : int
        Seed for randomized models.
    """

    fitted: Mapping[str, Any] = field(default_factory=dict)
    physics_model: Any = None
    physics_settings: Any = None
    options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    progress: bool = False
    random_state: int = 0


@dataclass(frozen=True)
class VariantSpec:
    """A named variant.

    Attributes
    ----------
    name : str
        Name used in reports and JSON.
    description : str
        One line for the report.
    build : callable
        ``build(context) -> model``: an unfitted model (see the module docstring).
    requires : tuple of str
        Variants whose fitted models ``build`` takes from ``context.fitted``.
    availability : callable
        ``availability() -> str | None``: None when the variant can be built, else the
        reason it cannot (e.g. the layer providing it is not there yet).
    layer : str
        Where the model comes from (``physics``, ``residual_ml``, …), for the report.
    on_request : str or None
        When set, the variant runs only when asked for by name (not among "every available
        variant"); the text says why (e.g. its fit is a whole discovery) for the report.
    """

    name: str
    description: str
    build: Callable[[VariantContext], Any]
    requires: tuple[str, ...] = ()
    availability: Callable[[], str | None] = lambda: None
    layer: str = "physics"
    on_request: str | None = None


_REGISTRY: dict[str, VariantSpec] = {}


def register_variant(spec: VariantSpec, *, replace: bool = False) -> VariantSpec:
    """Add a variant to the registry (e.g. ``augmented_hybrid`` once closing the loop lands).

    Parameters
    ----------
    spec : VariantSpec
        The variant.
    replace : bool
        Replace a registered variant of the same name.

    Returns
    -------
    VariantSpec
        ``spec``.

    Raises
    ------
    ValueError
        If the name is taken (and ``replace`` is false) or a required variant is unknown.
    """
    if spec.name in _REGISTRY and not replace:
        raise ValueError(f"variant {spec.name!r} is already registered")
    unknown = [r for r in spec.requires if r not in _REGISTRY and r != spec.name]
    if unknown:
        raise ValueError(f"variant {spec.name!r} requires unknown variant(s) {unknown}")
    _REGISTRY[spec.name] = spec
    return spec


def variant_names() -> list[str]:
    """Every registered variant, DESIGN §5 order first, then registration order."""
    design = [n for n in DESIGN_VARIANTS if n in _REGISTRY]
    return design + [n for n in _REGISTRY if n not in design]


def get_variant(name: str) -> VariantSpec:
    """The registered variant ``name``.

    Raises
    ------
    KeyError
        Naming the registered variants.
    """
    try:
        return _REGISTRY[name]
    except KeyError:
        raise KeyError(
            f"unknown variant {name!r}; registered: {', '.join(variant_names())}"
        ) from None


def unavailable_variants() -> dict[str, str]:
    """Registered variants that cannot be built here, with the reason."""
    out = {}
    for name in variant_names():
        reason = _REGISTRY[name].availability()
        if reason is None:
            reason = next(
                (f"requires {r}: {why}" for r in _REGISTRY[name].requires if (why := _why(r))),
                None,
            )
        if reason is not None:
            out[name] = reason
    for name in DESIGN_VARIANTS:
        if name not in _REGISTRY:
            out[name] = "not implemented yet"
    return out


def _why(name: str) -> str | None:
    spec = _REGISTRY.get(name)
    return "not registered" if spec is None else spec.availability()


def available_variants() -> list[str]:
    """Registered variants that can be built here, in report order."""
    missing = unavailable_variants()
    return [n for n in variant_names() if n not in missing]


def supports_std(model: Any) -> bool:
    """Whether ``model.predict`` takes ``return_std`` (a predictive standard deviation)."""
    try:
        return "return_std" in inspect.signature(model.predict).parameters
    except (TypeError, ValueError):
        return False


def predict_with_std(model: Any, trace: Trace) -> tuple[np.ndarray, np.ndarray | None]:
    """Prediction (bar) and, when the model offers it, its predictive standard deviation (bar).

    Parameters
    ----------
    model : object
        Fitted model with ``predict(trace)``; ``predict(trace, return_std=True)`` is used
        when its signature has ``return_std``.
    trace : Trace
        Experiment to predict.

    Returns
    -------
    mean : numpy.ndarray
        Clutch pressure, bar.
    std : numpy.ndarray or None
        Standard deviation, bar; None when the model does not give one.
    """
    if supports_std(model):
        mean, std = model.predict(trace, return_std=True)
        return np.asarray(mean, dtype=float), np.asarray(std, dtype=float)
    return np.asarray(model.predict(trace), dtype=float), None


# ---- physics variants ---------------------------------------------------------------------


def _outputs(model: Any, params: Any, trace: Trace) -> dict[str, np.ndarray]:
    """Simulated model outputs on ``trace`` (the hybrid model uses the pilot pressure too)."""
    from ..physics import simulate

    res = simulate(model, params, trace)
    return {k: np.asarray(v, dtype=float) for k, v in res.outputs.items()}


def _check_fitted(model: Any, attr: str) -> None:
    if not hasattr(model, attr):
        raise NotFittedError(f"this {type(model).__name__} is not fitted yet; call fit(traces)")


class DefaultPhysics(BaseEstimator):
    """``physics_default``: the circuit model with datasheet parameters, never fitted.

    The stand-in of the paper's Amesim model. ``fit`` learns nothing; it only records the
    training experiments (sklearn contract: state ends in ``_``). ``predict_outputs`` gives
    every model output (e.g. the pilot pressure a hybrid model uses as a feature).

    Parameters
    ----------
    model : CircuitModel, optional
        Model structure; the base circuit by default.
    """

    def __init__(self, model: Any = None) -> None:
        self.model = model

    def fit(self, traces: Sequence[Trace]) -> DefaultPhysics:
        """Record the training experiments (nothing is estimated); returns self."""
        from ..physics import CircuitModel

        self.model_ = self.model or CircuitModel()
        self.train_experiments_ = [t.name for t in traces]
        return self

    def predict_outputs(self, trace: Trace) -> dict[str, np.ndarray]:
        """Every model output on ``trace`` (name → per-sample array; pressures in bar)."""
        _check_fitted(self, "model_")
        return _outputs(self.model_, None, trace)

    def predict(self, trace: Trace) -> np.ndarray:
        """Clutch pressure (bar) of the default-parameter model on ``trace``."""
        return self.predict_outputs(trace)["clutch_pressure_bar"]


class FittedPhysics(BaseEstimator):
    """``physics_fitted``: the circuit model fitted to the training experiments.

    Wraps :class:`~clutchlab.physics.fit.PhysicsFitter`. A fit that stops before
    convergence (iteration or time limit) keeps its best iterate when
    ``accept_best_iterate``; ``converged_`` and ``result_.status`` say so, and the report
    shows it.

    Parameters
    ----------
    model : CircuitModel, optional
        Model structure (effects); the base circuit by default.
    settings : FitSettings, optional
        Fit settings; the defaults by default.
    accept_best_iterate : bool
        Keep the best iterate of a non-converged fit instead of raising (default True).
    fitted : PhysicsFitter or FitResult, optional
        A fit made before (e.g. ``clutchlab fit-physics``): used as is, not refitted, after
        checking that it was fitted on exactly the training experiments given to
        :meth:`fit` (a fit that saw a test experiment is refused).
    """

    def __init__(
        self,
        model: Any = None,
        settings: Any = None,
        accept_best_iterate: bool = True,
        fitted: Any = None,
    ) -> None:
        self.model = model
        self.settings = settings
        self.accept_best_iterate = accept_best_iterate
        self.fitted = fitted

    def fit(self, traces: Sequence[Trace]) -> FittedPhysics:
        """Fit on ``traces`` (the training experiments); returns self.

        Raises
        ------
        FitError
            When the fit fails without a usable iterate (or does not converge and
            ``accept_best_iterate`` is false).
        """
        from ..physics.fit import FitResult, PhysicsFitter

        if self.fitted is not None:
            fitter = self.fitted
            if isinstance(fitter, FitResult):
                fitter = PhysicsFitter.load(fitter.to_json())
            names = sorted(t.name for t in traces)
            if sorted(fitter.result_.train) != names:
                raise FitError(
                    "the given physics fit was made on other experiments "
                    f"({', '.join(sorted(fitter.result_.train))}) than this evaluation's "
                    f"training experiments ({', '.join(names)}); refit it on the training ramps"
                )
            check_fit_effects(fitter.result_, self.model)
            self.fitter_ = fitter
            self.result_ = fitter.result_
            self.converged_ = bool(fitter.result_.success)
            self.train_experiments_ = list(self.result_.train)
            return self
        fitter = PhysicsFitter(self.model, self.settings)
        try:
            fitter.fit(list(traces))
            # a fit stopped at its iteration or time limit returns (with a FitWarning)
            # its best iterate, marked not converged: say so
            converged = bool(fitter.result_.success)
        except FitError as exc:
            best = getattr(exc, "result", None)
            if best is None or not self.accept_best_iterate:
                raise
            fitter = PhysicsFitter.load(best.to_json())
            converged = False
        _check_moved(fitter.result_, self.model)
        self.fitter_ = fitter
        self.result_ = fitter.result_
        self.converged_ = converged
        self.train_experiments_ = list(self.result_.train)
        return self

    def predict_outputs(self, trace: Trace) -> dict[str, np.ndarray]:
        """Every output of the fitted model on ``trace`` (name → per-sample array; bar)."""
        _check_fitted(self, "fitter_")
        return _outputs(self.fitter_.model_, self.fitter_.params_, trace)

    def predict(self, trace: Trace) -> np.ndarray:
        """Clutch pressure (bar) of the fitted model on ``trace``."""
        return self.predict_outputs(trace)["clutch_pressure_bar"]


def check_fit_effects(result: Any, model: Any) -> None:
    """Refuse a given physics fit that lacks an effect the evaluation's model declares.

    Parameters
    ----------
    result : FitResult
        The fit made before (``clutchlab fit-physics``), used as ``physics_fitted``.
    model : CircuitModel or None
        The model structure asked for (``--effects``); None: the base circuit.

    Raises
    ------
    FitError
        Naming the effects the fit lacks (scoring it would report a model without them
        under a report that says they were on).
    """
    wanted = tuple(getattr(model, "effect_names", ()) or ())
    missing = [e for e in wanted if e not in result.effects]
    if missing:
        raise FitError(
            f"the given physics fit lacks the effect(s) {', '.join(missing)} asked for "
            f"(its effects: {', '.join(result.effects) or 'none'}); refit it with "
            "`clutchlab fit-physics --effects ...`, or leave those effects out"
        )


def _check_moved(result: Any, model: Any) -> None:
    """Refuse a fit result that holds the start values although the cost went down.

    Guards against a fit stopped between its stages (time limit reached after the pre-fit)
    whose result falls back to the start parameters: scoring that as ``physics_fitted`` would
    silently report the datasheet model.
    """
    from ..physics import CircuitModel

    history = list(result.cost_history)
    if len(history) < 2 or not min(history) < history[0]:
        return
    start = (model or CircuitModel()).default_params()
    if all(result.values[n] == start[n] for n in result.free):
        raise FitError(
            f"the physics fit lowered its cost from {history[0]:.4g} to {min(history):.4g} "
            f"but its result holds the start parameters (status {result.status!r}, "
            f"{result.wall_s:.0f} s; e.g. the time limit ran out between pre-fit and "
            "refinement); raise FitSettings.time_limit_s"
        )


def _build_default(ctx: VariantContext) -> DefaultPhysics:
    return DefaultPhysics(ctx.physics_model, **ctx.options.get("physics_default", {}))


def _build_fitted(ctx: VariantContext) -> FittedPhysics:
    from ..physics.fit import FitSettings

    settings = ctx.physics_settings or FitSettings(progress=ctx.progress)
    return FittedPhysics(ctx.physics_model, settings, **ctx.options.get("physics_fitted", {}))


register_variant(
    VariantSpec(
        "physics_default",
        "circuit model, datasheet parameters (the paper's Amesim baseline), not fitted",
        _build_default,
    )
)
register_variant(
    VariantSpec(
        "physics_fitted",
        "circuit model, parameters fitted to the training experiments (CasADi + IPOPT)",
        _build_fitted,
    )
)


# ---- machine-learning variants (clutchlab.residual_ml) ------------------------------------

#: Estimator class per ML variant, used when residual_ml has no ``make_variant`` registry.
_ML_CLASSES: dict[str, str] = {
    "gp_base": "GPBaseline",
    "gp_didt": "GPWithDerivative",
    "paper_svc_gp": "SVCPartitionedGP",
    "hybrid": "HybridModel",
    "paper_faithful": "paper_faithful",
}
_ML_DESCRIPTIONS: dict[str, str] = {
    "gp_base": "GP on nominal current, dither amplitude and frequency (paper stage 1)",
    "gp_didt": "GP on lagged current, dither amplitude and frequency, dI/dt (paper stage 2)",
    "paper_svc_gp": "one GP per latch state on the lagged current, the latched one below line "
    "pressure; latch state from the local latch-event law, or from the RBF-SVC when the "
    "training data hold fewer than two latch events of a direction, e.g. one training "
    "experiment (its latch decision says which; paper stage 3, clutchlab's defaults)",
    "hybrid": "fitted physics + SVC-partitioned GP on its residual",
    "paper_faithful": "paper stage 3 as published: RBF-SVC on nominal current, dI/dt and "
    "dither, one rational-quadratic GP per latch state, no lag, no line-pressure reference",
}
#: Variants whose model takes the fitted physics (keyword ``physics``).
_NEEDS_PHYSICS: dict[str, str] = {"hybrid": "physics_fitted"}


def _residual_ml():
    return importlib.import_module("clutchlab.residual_ml")


def _ml_available(name: str) -> Callable[[], str | None]:
    def check() -> str | None:
        try:
            ml = _residual_ml()
        except (ImportError, ClutchlabError) as exc:  # the layer does not import
            return f"clutchlab.residual_ml does not import ({type(exc).__name__}: {exc})"
        registry = getattr(ml, "VARIANTS", None)
        if hasattr(ml, "make_variant") and registry is not None:
            return None if name in registry else "not in clutchlab.residual_ml.VARIANTS"
        if hasattr(ml, _ML_CLASSES[name]):
            return None
        return f"clutchlab.residual_ml provides neither make_variant nor {_ML_CLASSES[name]}"

    return check


def _ml_build(name: str) -> Callable[[VariantContext], Any]:
    def build(ctx: VariantContext) -> Any:
        ml = _residual_ml()
        kwargs = dict(ctx.options.get(name, {}))
        if name in _NEEDS_PHYSICS:
            kwargs.setdefault("physics", ctx.fitted[_NEEDS_PHYSICS[name]])
        if hasattr(ml, "make_variant") and name in getattr(ml, "VARIANTS", {}):
            return ml.make_variant(name, **kwargs)
        return getattr(ml, _ML_CLASSES[name])(**kwargs)

    return build


for _name, _cls in _ML_CLASSES.items():
    register_variant(
        VariantSpec(
            _name,
            _ML_DESCRIPTIONS[_name],
            _ml_build(_name),
            requires=(_NEEDS_PHYSICS[_name],) if _name in _NEEDS_PHYSICS else (),
            availability=_ml_available(_name),
            layer="residual_ml",
        )
    )


# ---- an FMU as the physics (clutchlab evaluate --physics-fmu) -----------------------------

#: Name of the variant scoring a physics FMU (as ``physics_fitted`` is scored).
FMU_VARIANT = "physics_fmu"


def _fmu_parameter_text(fmu: Any) -> str:
    """The FMU's parameters for the variant's description: those set, those set from each
    experiment, those left at the FMU's start value (empty without ``parameter_summary``)."""
    if not hasattr(fmu, "parameter_summary"):
        return ""
    summary = fmu.parameter_summary()
    given = ", ".join(f"{k} = {v:g}" for k, v in summary["set"].items())
    parts = [f"parameters set: {given or 'none'}"]
    if summary["from_trace"]:
        parts.append("set from each experiment: " + ", ".join(summary["from_trace"]))
    left = summary["start_value"]
    if left:
        parts.append(f"left at the FMU's start value ({len(left)}): " + ", ".join(left))
    return "; " + "; ".join(parts)


def fmu_variants(fmu: Any) -> dict[str, VariantSpec]:
    """Variant specs that use an FMU as the physics model, overriding the registry.

    ``physics_fmu`` scores the FMU itself (nothing is fitted; scored like
    ``physics_fitted``); ``hybrid`` trains its residual model on top of the FMU instead of
    the fitted in-process physics. The description of ``physics_fmu`` (in the report and
    ``metrics.json``) lists the FMU's parameters set, set from each experiment and left at
    the FMU's start value.

    Parameters
    ----------
    fmu : FmuPhysics
        The FMU as a physics model (:class:`clutchlab.physics.fmu.FmuPhysics`: simulated
        with FMPy on each experiment's inputs, with its timeout).

    Returns
    -------
    dict of str to VariantSpec
        ``{"physics_fmu": ..., "hybrid": ...}``.
    """
    label = getattr(fmu, "label", type(fmu).__name__)
    specs = {
        FMU_VARIANT: VariantSpec(
            FMU_VARIANT,
            f"physics model from the FMU {label} (FMI 2.0, simulated with FMPy), not fitted"
            + _fmu_parameter_text(fmu),
            lambda ctx: fmu,
            layer="physics (FMU)",
        )
    }

    def build_hybrid(ctx: VariantContext) -> Any:
        ml = _residual_ml()
        kwargs = dict(ctx.options.get("hybrid", {}))
        if "physics" not in kwargs:
            kwargs["physics"] = ctx.fitted[FMU_VARIANT]
        if hasattr(ml, "make_variant") and "hybrid" in getattr(ml, "VARIANTS", {}):
            return ml.make_variant("hybrid", **kwargs)
        return getattr(ml, _ML_CLASSES["hybrid"])(**kwargs)

    specs["hybrid"] = VariantSpec(
        "hybrid",
        f"FMU physics ({label}) + SVC-partitioned GP on its residual",
        build_hybrid,
        requires=(FMU_VARIANT,),
        availability=_ml_available("hybrid"),
        layer="residual_ml",
    )
    return specs
