"""Fit every variant on the training ramps and score it on the test ramp (DESIGN §5).

:func:`evaluate` is the whole comparison: it builds each variant from the registry
(:mod:`~clutchlab.validation.variants`), fits it through the :class:`Protocol` (training
experiments only), scores it on the test experiments, and collects what the report needs.
:meth:`Evaluation.to_dict` is the content of ``metrics.json``; the HTML and Markdown reports
are rendered from that same dictionary.
"""

from __future__ import annotations

import datetime as _dt
import math
import platform
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from .. import __version__
from ..data import Dataset
from ..errors import ClutchlabError, DataError
from .hysteresis import HysteresisCurve, hysteresis_curve
from .protocol import ExperimentReference, Protocol, VariantScore
from .settings import AnalysisSettings
from .variants import (
    VariantContext,
    VariantSpec,
    available_variants,
    fmu_variants,
    get_variant,
    unavailable_variants,
    variant_names,
)

__all__ = ["SCHEMA", "Evaluation", "evaluate", "resolve_variants", "versions"]

#: Identifier of the ``metrics.json`` layout.
SCHEMA = "clutchlab.validation.report/1"

#: Variants drawn in the hysteresis-band figure (paper Fig. 5), when present.
BAND_VARIANTS: tuple[str, ...] = ("physics_default", "physics_fitted", "paper_svc_gp")


def versions() -> dict[str, str]:
    """Versions of clutchlab, Python, the numerical libraries and the platform."""
    out = {"clutchlab": __version__, "python": sys.version.split()[0]}
    for mod in ("numpy", "scipy", "casadi", "sklearn", "matplotlib", "pandas"):
        try:
            out[mod] = str(__import__(mod).__version__)
        except Exception:  # pragma: no cover - an optional library missing or broken
            out[mod] = "unavailable"
    out["platform"] = platform.platform()
    return out


def _order(overrides: Mapping[str, VariantSpec]) -> list[str]:
    """Report order: the registry's, extra variants after ``physics_fitted`` (else first)."""
    names = variant_names()
    extra = [n for n in overrides if n not in names]
    at = names.index("physics_fitted") + 1 if "physics_fitted" in names else 0
    return names[:at] + extra + names[at:]


def resolve_variants(
    requested: Sequence[str] | None, overrides: Mapping[str, VariantSpec] | None = None
) -> list[str]:
    """The variants to run, in report order, with the ones they require added.

    Parameters
    ----------
    requested : sequence of str or None
        Variant names; None for every available variant.
    overrides : mapping of str to VariantSpec, optional
        Specs used instead of (or besides) the registry's, e.g. those of
        :func:`~clutchlab.validation.variants.fmu_variants`.

    Returns
    -------
    list of str

    Raises
    ------
    ClutchlabError
        Naming unknown or unavailable variants (an explicit request is never skipped).
    """
    overrides = dict(overrides or {})

    def spec_of(name: str) -> VariantSpec:
        return overrides[name] if name in overrides else get_variant(name)

    order = _order(overrides)
    if requested is None:
        wanted = {n for n in available_variants() if spec_of(n).on_request is None}
        wanted |= {n for n, sp in overrides.items() if sp.availability() is None}
    else:
        wanted = set(requested)
        missing = {k: v for k, v in unavailable_variants().items() if k not in overrides}
        missing |= {n: why for n, sp in overrides.items() if (why := sp.availability())}
        unknown = sorted(n for n in wanted if n not in order and n not in missing)
        blocked = sorted(n for n in wanted if n in missing)
        problems = [f"unknown variant {n!r}" for n in unknown]
        problems += [f"variant {n!r} is not available: {missing[n]}" for n in blocked]
        if problems:
            raise ClutchlabError(
                "; ".join(problems) + f". Available: {', '.join(available_variants())}"
            )
    stack = list(wanted)
    while stack:
        for r in spec_of(stack.pop()).requires:
            if r not in wanted:
                wanted.add(r)
                stack.append(r)
    return [n for n in order if n in wanted]


@dataclass
class Evaluation:
    """Outcome of :func:`evaluate`: scores, fitted models, and what the report draws.

    Attributes
    ----------
    protocol : Protocol
        The split used.
    scores : dict
        Variant name → :class:`VariantScore` (scored variants, report order).
    models : dict
        Variant name → fitted model.
    fit_own_s : dict
        Variant name → wall time of its own ``fit`` (s), without required variants.
    failed : dict
        Variant name → error text, for variants whose fit or scoring failed.
    unavailable : dict
        Variant name → why it could not be built here.
    specs : dict
        Variant name → its :class:`VariantSpec` (as registered when evaluated).
    curves : dict
        ``source → experiment → HysteresisCurve`` (dither-period mean) for the hysteresis
        bands: ``"measured"`` and the variants of :data:`BAND_VARIANTS` present, on every
        experiment of the train and test ramps (training ramps in sample).
    classifier_comparison : object or None
        The latch-classifier comparison of :mod:`clutchlab.residual_ml`, when it provides one.
    timings : dict
        Wall times of the stages, s.
    command : str
        The command line that produced it.
    created_utc : str
        ISO time stamp.
    """

    protocol: Protocol
    scores: dict[str, VariantScore]
    models: dict[str, Any]
    fit_own_s: dict[str, float]
    failed: dict[str, str]
    unavailable: dict[str, str]
    specs: dict[str, VariantSpec] = field(default_factory=dict)
    curves: dict[str, dict[str, HysteresisCurve]] = field(default_factory=dict)
    classifier_comparison: Any = None
    timings: dict[str, float] = field(default_factory=dict)
    command: str = ""
    created_utc: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def references(self) -> dict[str, ExperimentReference]:
        """The measured side of the test experiments, by name."""
        first = next(iter(self.scores.values()), None)
        return first.reference if first is not None else {}

    def discovery_result(self) -> Any:
        """The closing-the-loop discovery behind ``augmented_hybrid`` (None without it)."""
        model = self.models.get("augmented_hybrid")
        return getattr(getattr(model, "physics_", None), "result_", None)

    def discovery(self) -> dict[str, Any] | None:
        """Summary of ``augmented_hybrid``'s discovery on the training experiments: what was
        added, and per iteration the decision, training RMSE before / after (bar) and the
        evidence table (score statistic, p-value, explained share, significance, ΔBIC of the
        refits: on the screening subset and on every training experiment)."""
        result = self.discovery_result()
        if result is None:
            return None
        from .discover import alternative_note

        model = self.models["augmented_hybrid"]
        iterations = []
        for it in result.iterations:
            rows = []
            for c in it.candidates:
                refit = c.refit or {}
                screen = refit if refit.get("scope") == "screening" else refit.get("screen", {})
                rows.append(
                    {
                        "effect": c.effect,
                        "statistic": c.statistic,
                        "p_value": c.p_value,
                        "share": c.share,
                        "significant": c.significant,
                        "status": c.status,
                        "delta_bic_screening": screen.get("delta_bic"),
                        "delta_bic": None if refit is screen else refit.get("delta_bic"),
                        "flexible_alternatives": alternative_note(refit),
                    }
                )
            iterations.append(
                {
                    "index": it.index,
                    "effect": it.effect,
                    "decision": it.decision,
                    "train_rmse_before_bar": it.before.train["rmse_bar"],
                    "train_rmse_after_bar": it.after.train["rmse_bar"],
                    "screening": it.reference.get("screening", {}).get("subset"),
                    "candidates": rows,
                    "wall_s": it.wall_s,
                }
            )
        return {
            "summary": result.summary,
            "added": list(result.added),
            "wall_s": result.wall_s,
            "time_limited": result.time_limited,
            "time_limit_s": result.settings.get("time_limit_s"),
            "baseline_reused": getattr(model.physics_, "baseline", None) is not None,
            "hybrid_reused": bool(getattr(model, "reused_hybrid_", False)),
            "iterations": iterations,
        }

    def physics_fit(self) -> dict[str, Any] | None:
        """Summary of the ``physics_fitted`` fit: status, the wall-time (s) and iteration
        limits it ran under (None for a fit given, not made here), parameters ± standard
        errors."""
        model = self.models.get("physics_fitted")
        res = getattr(model, "result_", None)
        if res is None:
            return None
        specs = {}
        try:
            specs = {p.name: p for p in res.model().parameters}
        except Exception:  # pragma: no cover - effects unknown to this version
            specs = {}
        params = {}
        for n in res.free:
            spec = specs.get(n)
            params[n] = {
                "value": res.values[n],
                "std_error": res.std_errors.get(n, float("nan")),
                "unit": res.units.get(n, ""),
                "default": spec.default if spec is not None else float("nan"),
                # not known when the sensitivities diverged (the report shows n/a)
                "identifiable": None
                if getattr(res, "uncertainty_note", "")
                else n not in res.unidentifiable,
                "description": spec.description if spec is not None else "",
            }
        # the limits it ran under, for the report to say which one to raise (None for a fit
        # made before and given, e.g. --physics-model)
        given = getattr(model, "fitted", None) is not None
        limits = None if given else (getattr(model, "settings", None) or _default_fit_settings())
        return {
            "status": res.status,
            "converged": bool(getattr(model, "converged_", res.success)),
            "time_limit_s": getattr(limits, "time_limit_s", None),
            "max_iter": getattr(limits, "max_iter", None),
            "iterations": res.iterations,
            "wall_s": res.wall_s,
            "effects": list(res.effects),
            "parameters": params,
            "unidentifiable": list(res.unidentifiable),
            "train_rmse_bar": {k: v["rmse_bar"] for k, v in res.per_experiment.items()},
            # what the model is when not the solver's best iterate (the staged start)
            "note": getattr(res, "note", ""),
            # why standard errors are not reported ("" when they are)
            "uncertainty_note": getattr(res, "uncertainty_note", ""),
            # what they allow for (residuals; NaN for a fit made before it was recorded)
            "residual_correlation_time": getattr(res, "residual_correlation_time", math.nan),
        }

    def to_dict(self) -> dict[str, Any]:
        """The ``metrics.json`` document (every number of the report comes from it).

        Returns
        -------
        dict
            ``{"variants": {name: {metric: value}}, "raw": {...}, "details": {...},
            "per_experiment": {...}, "failed", "unavailable", "split", "dataset",
            "physics_fit", "analysis", "timings", "versions", "command", ...}``; units as
            in the metric keys (bar, %, mA, s).
        """
        details = {}
        for name, sc in self.scores.items():
            spec = self.specs[name]
            details[name] = {
                "description": spec.description,
                "layer": spec.layer,
                "requires": list(spec.requires),
                "fit_own_s": self.fit_own_s.get(name, 0.0),
                "uncertainty": any(p.std_bar is not None for p in sc.predictions.values()),
                **sc.details,
            }
        p = self.protocol
        return {
            "schema": SCHEMA,
            "variants": {n: dict(sc.metrics) for n, sc in self.scores.items()},
            "raw": {n: dict(sc.raw) for n, sc in self.scores.items()},
            "details": details,
            "per_experiment": {n: sc.per_experiment for n, sc in self.scores.items()},
            "failed": dict(self.failed),
            "unavailable": dict(self.unavailable),
            "split": {
                "train_ramps": list(p.train_ramps),
                "test_ramps": list(p.test_ramps),
                "train": p.train_names,
                "test": p.test_names,
                # ramp rates (mA/s) and the test experiments outside the training ones
                "ramp_rates_mA_s": p.ramp_rates,
            },
            "dataset": p.dataset_summary,
            "physics_fit": self.physics_fit(),
            "discovery": self.discovery(),
            "classifier_comparison": (
                self.classifier_comparison.to_dict()
                if hasattr(self.classifier_comparison, "to_dict")
                else None
            ),
            "analysis": asdict(p.settings),
            # over what the primary ("dither-period mean") scores are averaged, per test
            # experiment: a log without a dither has a 1-sample window (its raw signal)
            "averaging": {n: ref.averaging for n, ref in self.references.items()},
            "timings": dict(self.timings),
            "versions": versions(),
            "command": self.command,
            "created_utc": self.created_utc,
            **self.extra,
        }


def _default_fit_settings() -> Any:
    """The fit settings a ``physics_fitted`` built without settings runs under."""
    from ..physics.fit import FitSettings

    return FitSettings()


def _period_curve(ref: ExperimentReference, pressure: np.ndarray, s: AnalysisSettings):
    return hysteresis_curve(
        ref.current_mA, ref.period_mean(pressure), ref.direction, ref.line_bar, s
    )


def _band_curves(ev: Evaluation, progress: bool) -> dict[str, dict[str, HysteresisCurve]]:
    """Hysteresis curves of measured and band variants on every train and test experiment."""
    p, s = ev.protocol, ev.protocol.settings
    train_refs = {t.name: ExperimentReference.of(t, s) for t in p.train_traces()}
    test_refs = ev.references
    curves: dict[str, dict[str, HysteresisCurve]] = {"measured": {}}
    for refs in (train_refs, test_refs):
        for n, ref in refs.items():
            curves["measured"][n] = _period_curve(ref, ref.measured_bar, s)
    names = [n for n in BAND_VARIANTS if n in ev.scores]
    traces = {t.name: t for t in p.train_traces()}
    for name in tqdm(names, desc="in-sample hysteresis", disable=not progress, leave=False):
        model, out = ev.models[name], {}
        for n, ref in train_refs.items():
            out[n] = _period_curve(ref, np.asarray(model.predict(traces[n]), dtype=float), s)
        for n, ref in test_refs.items():
            out[n] = _period_curve(ref, ev.scores[name].predictions[n].mean_bar, s)
        curves[name] = out
    return curves


def _classifier_comparison(protocol: Protocol, progress: bool, random_state: int) -> Any:
    """The latch-classifier comparison of residual_ml (paper Table 1 / Fig. 2).

    Leave-one-experiment-out over the **training** experiments only.
    """
    from .. import residual_ml as ml  # a failing import is an error, not a missing table

    return ml.compare_classifiers(
        list(protocol.train_traces()), random_state=random_state, progress=progress
    )


def evaluate(
    dataset: Dataset,
    variants: Sequence[str] | None = None,
    *,
    train: Sequence[str] = ("fast", "slow"),
    test: Sequence[str] = ("medium",),
    physics_model: Any = None,
    physics_settings: Any = None,
    options: Mapping[str, Mapping[str, Any]] | None = None,
    analysis: AnalysisSettings | None = None,
    on_error: str = "raise",
    progress: bool = True,
    classifiers: bool | None = None,
    bands: bool = True,
    command: str = "",
    random_state: int = 0,
    physics_fmu: Any = None,
) -> Evaluation:
    """Fit each variant on the training ramps, score it on the test ramps.

    Parameters
    ----------
    dataset : Dataset
        Experiments in the data contract.
    variants : sequence of str, optional
        Variant names (:func:`~clutchlab.validation.variants.variant_names`); every
        available one by default. Variants they require are added.
    train, test : sequence of str
        Ramp labels (default fast + slow, and medium).
    physics_model : CircuitModel, optional
        Model structure of the physics variants (effects); the base circuit by default.
    physics_settings : FitSettings, optional
        Settings of the physics fit.
    options : mapping, optional
        Keyword arguments per variant name for its model's constructor.
    analysis : AnalysisSettings, optional
        Hysteresis bins (mA) and latch margin (bar) of the metrics.
    on_error : {"raise", "report"}
        A variant that fails: raise, or record it under ``failed`` and go on.
    progress : bool
        Progress bars.
    classifiers : bool, optional
        Run the latch-classifier comparison (paper Table 1 / Fig. 2, leave-one-experiment-out
        on the training experiments) when residual_ml offers it. Default: when a
        residual_ml variant is among the scored ones, and left out (the report says why)
        when the data cannot support it (fewer than 2 training experiments, one latch
        state); True: such data are a failure of the comparison.
    bands : bool
        Compute the in-sample hysteresis curves of the hysteresis-band figure (paper Fig. 5).
    command : str
        Command line recorded in the report.
    random_state : int
        Seed handed to randomized models.
    physics_fmu : FmuPhysics, optional
        An FMU as the physics model (:class:`clutchlab.physics.fmu.FmuPhysics`, simulated
        with FMPy on each experiment's inputs, with its timeout): scored as the variant
        ``physics_fmu`` (beside ``physics_fitted``, like it), and the physics under
        ``hybrid`` instead of the fitted in-process model
        (:func:`~clutchlab.validation.variants.fmu_variants`).

    Returns
    -------
    Evaluation

    Raises
    ------
    DataError
        Bad split labels.
    ClutchlabError
        Unknown or unavailable variants requested; with ``on_error="raise"``, a variant
        whose fit or scoring fails (the original exception).
    """
    if on_error not in ("raise", "report"):
        raise ValueError(f"on_error must be 'raise' or 'report', got {on_error!r}")
    t_start = time.perf_counter()
    overrides = fmu_variants(physics_fmu) if physics_fmu is not None else {}
    names = resolve_variants(variants, overrides)
    protocol = Protocol(dataset, train=train, test=test, settings=analysis)
    missing = {
        n: r
        for n, r in unavailable_variants().items()
        if n not in overrides or overrides[n].availability() is not None
    }
    ev = Evaluation(
        protocol=protocol,
        scores={},
        models={},
        fit_own_s={},
        failed={},
        unavailable={n: r for n, r in missing.items() if variants is None or n in variants}
        | (
            {
                n: f"not run by default: {get_variant(n).on_request}"
                for n in available_variants()
                if get_variant(n).on_request is not None and n not in names
            }
            if variants is None
            else {}
        ),
        command=command,
        created_utc=_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    )
    if physics_fmu is not None:
        ev.extra["physics_fmu"] = {
            "fmu": str(getattr(physics_fmu, "fmu", "")),
            "label": str(getattr(physics_fmu, "label", "")),
            "timeout_s": getattr(physics_fmu, "timeout_s", None),
        }
        if hasattr(physics_fmu, "parameter_summary"):
            summary = physics_fmu.parameter_summary()
            ev.extra["physics_fmu"] |= {
                "parameters_set": summary["set"],
                "parameters_from_trace": sorted(summary["from_trace"]),
                "parameters_at_start_value": summary["start_value"],
            }
    total_fit: dict[str, float] = {}
    bar = tqdm(names, desc="variants", unit="variant", disable=not progress)
    for name in bar:
        bar.set_postfix_str(name)
        t_variant = time.perf_counter()
        spec = ev.specs[name] = overrides.get(name) or get_variant(name)
        broken = [r for r in spec.requires if r not in ev.models]
        if broken:
            ev.failed[name] = f"requires {', '.join(broken)}, which failed"
            continue
        try:
            ctx = VariantContext(
                fitted={r: ev.models[r] for r in spec.requires},
                physics_model=physics_model,
                physics_settings=physics_settings,
                options=dict(options or {}),
                progress=progress,
                random_state=random_state,
            )
            model, fit_s = protocol.fit(spec.build(ctx))
            total_fit[name] = fit_s + sum(total_fit[r] for r in spec.requires)
            score = protocol.score(name, model, fit_s=total_fit[name], std_for=(protocol.featured,))
        except Exception as exc:
            if on_error == "raise":
                raise
            ev.failed[name] = f"{type(exc).__name__}: {exc}"
            continue
        ev.models[name], ev.fit_own_s[name], ev.scores[name] = model, fit_s, score
        ev.timings[f"{name}_s"] = time.perf_counter() - t_variant
    bar.close()
    if bands and ev.scores:
        t0 = time.perf_counter()
        ev.curves = _band_curves(ev, progress)
        ev.timings["hysteresis_bands_s"] = time.perf_counter() - t0
    chosen = classifiers is None
    if chosen:
        classifiers = any(ev.specs[n].layer == "residual_ml" for n in ev.scores)
    if not classifiers:
        ev.extra["classifier_comparison_skipped"] = (
            "no paper-pipeline (ML) variant was evaluated"
            if chosen
            else "not asked for (classifiers=False; --no-classifiers)"
        )
    if classifiers:
        t0 = time.perf_counter()
        try:
            ev.classifier_comparison = _classifier_comparison(protocol, progress, random_state)
        except DataError as exc:
            if chosen:  # not asked for by name: data it cannot run on leave it out
                ev.extra["classifier_comparison_skipped"] = f"not possible on these data: {exc}"
            elif on_error == "raise":
                raise
            else:
                ev.failed["classifier_comparison"] = f"{type(exc).__name__}: {exc}"
        except Exception as exc:
            if on_error == "raise":
                raise
            ev.failed["classifier_comparison"] = f"{type(exc).__name__}: {exc}"
        ev.timings["classifier_comparison_s"] = time.perf_counter() - t0
    ev.timings["evaluate_s"] = time.perf_counter() - t_start
    return ev
