"""Validation: split protocol, metrics, figures and reports (DESIGN §5).

- :class:`Protocol` owns the train / test split and scores fitted models only;
- :mod:`~clutchlab.validation.variants` names the compared models, whichever layer they come
  from (:func:`register_variant` adds new ones);
- :func:`evaluate` fits and scores every variant; :func:`write_report` writes
  ``report.html`` (interactive Plotly figures, :func:`interactive_figures`), ``report.md``,
  ``metrics.json`` and ``metrics.csv`` from one dictionary;
- :func:`run_demo` is ``clutchlab demo``: the embedded stand end to end.
"""

from .demo import (
    DEMO_BUDGET_S,
    DEMO_FIT_TIME_LIMIT_S,
    DEMO_RESERVE_S,
    DemoResult,
    run_demo,
    stand_data,
)
from .evaluate import SCHEMA, Evaluation, evaluate, resolve_variants, versions
from .figures import (
    VARIANT_COLORS,
    FigureSpec,
    plot_classifier_comparison,
    plot_hysteresis_bands,
    plot_prediction_vs_time,
    plot_pressure_vs_current,
    plot_residuals,
    plot_uncertainty,
    report_figures,
)
from .hysteresis import (
    FALLING,
    RISING,
    HysteresisCurve,
    branch_direction,
    current_bins,
    hysteresis_curve,
    hysteresis_width_error,
)
from .interactive import interactive_figures
from .latch import LatchCurrents, latch_currents, latch_error
from .metrics import (
    ACCURACY_KEYS,
    METRIC_KEYS,
    SIGNAL_KINDS,
    TIMING_KEYS,
    ExperimentComparison,
    compare_experiment,
    coverage_regions,
    error_by_region,
    interval_coverage,
    pool_comparisons,
    pressure_metrics,
)
from .predict import (
    ExperimentPrediction,
    LoadedModel,
    load_predictor,
    overall_metrics,
    predict_traces,
    prediction_table,
)
from .predict_figure import prediction_figure
from .protocol import (
    EvaluationError,
    ExperimentReference,
    LeakageError,
    Prediction,
    Protocol,
    VariantScore,
    inputs_only,
    is_fitted,
)
from .report import (
    METRIC_LABELS,
    ReportFiles,
    fmt,
    jsonable,
    metrics_csv,
    render_html,
    render_markdown,
    write_json,
    write_report,
)
from .settings import AnalysisSettings
from .variants import (
    DESIGN_VARIANTS,
    DefaultPhysics,
    FittedPhysics,
    VariantContext,
    VariantSpec,
    available_variants,
    get_variant,
    predict_with_std,
    register_variant,
    supports_std,
    unavailable_variants,
    variant_names,
)

__all__ = [
    "ACCURACY_KEYS",
    "DEMO_BUDGET_S",
    "DEMO_FIT_TIME_LIMIT_S",
    "DEMO_RESERVE_S",
    "DESIGN_VARIANTS",
    "FALLING",
    "METRIC_KEYS",
    "METRIC_LABELS",
    "RISING",
    "SCHEMA",
    "SIGNAL_KINDS",
    "TIMING_KEYS",
    "VARIANT_COLORS",
    "AnalysisSettings",
    "DefaultPhysics",
    "DemoResult",
    "Evaluation",
    "EvaluationError",
    "ExperimentComparison",
    "ExperimentPrediction",
    "ExperimentReference",
    "FigureSpec",
    "FittedPhysics",
    "HysteresisCurve",
    "LatchCurrents",
    "LeakageError",
    "LoadedModel",
    "Prediction",
    "Protocol",
    "ReportFiles",
    "VariantContext",
    "VariantScore",
    "VariantSpec",
    "available_variants",
    "branch_direction",
    "compare_experiment",
    "coverage_regions",
    "current_bins",
    "error_by_region",
    "evaluate",
    "fmt",
    "get_variant",
    "hysteresis_curve",
    "hysteresis_width_error",
    "inputs_only",
    "interactive_figures",
    "interval_coverage",
    "is_fitted",
    "jsonable",
    "latch_currents",
    "latch_error",
    "load_predictor",
    "metrics_csv",
    "overall_metrics",
    "plot_classifier_comparison",
    "plot_hysteresis_bands",
    "plot_prediction_vs_time",
    "plot_pressure_vs_current",
    "plot_residuals",
    "plot_uncertainty",
    "pool_comparisons",
    "predict_traces",
    "predict_with_std",
    "prediction_figure",
    "prediction_table",
    "pressure_metrics",
    "register_variant",
    "render_html",
    "render_markdown",
    "report_figures",
    "resolve_variants",
    "run_demo",
    "stand_data",
    "supports_std",
    "unavailable_variants",
    "variant_names",
    "versions",
    "write_json",
    "write_report",
]

# closing the loop's variant (DESIGN §5), run when asked for by name
from .discover.variant import register as _register_augmented

_register_augmented(replace_existing=True)
