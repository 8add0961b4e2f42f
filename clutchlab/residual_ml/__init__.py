"""The paper's pipeline: latch classifiers, SVC-partitioned local GPs, hybrid residual model.

Reproduces Bagla & Schneider (CTI 2020; DESIGN §1) as estimators with the scikit-learn
contract that train on traces (:mod:`~clutchlab.residual_ml.base`):

- :class:`GPBaseline` (``gp_base``): one GP on nominal current, dither amplitude, frequency;
- :class:`GPWithDerivative` (``gp_didt``): + dI/dt (rate and direction of travel);
- :class:`SVCPartitionedGP` (``paper_svc_gp``): a latch decision and one GP per latch
  state — the paper's final model (RBF-SVC classifier, rational-quadratic GPs; the
  ``paper_faithful`` variant); clutchlab's defaults decide the latch state with the local
  latch-event law (:mod:`~clutchlab.residual_ml.latch_local`) and choose the kernel;
- :class:`HybridModel` (``hybrid``): physics prediction + partitioned GP on its residual.

The GPs (:class:`LocalGPRegressor`) scale to ~10⁶ samples by binning redundant 1 kHz ramp
samples, blocked marginal-likelihood hyperparameters and knot-based prediction along traces.
Models are saved as JSON + NPZ (:func:`save_model`, :func:`load_model`).
"""

from __future__ import annotations

from .base import TraceEstimator, as_traces
from .binning import Bins, grid_bins
from .classifiers import (
    CLASSIFIERS,
    RBF_FEATURE_WEIGHTS,
    BinnedClassifier,
    ColumnWeights,
    make_classifier,
)
from .compare import ClassifierComparison, compare_classifiers
from .estimators import (
    DEFAULT_LATCH_MODEL,
    GP_PRESSURE_RATE_SCALE,
    LATCH_BANDWIDTH,
    LATCH_MODELS,
    LATCH_RATE_SCALE,
    LATCH_RATE_SCALES,
    PRESSURE_RATE_SCALE,
    GPBaseline,
    GPWithDerivative,
    SVCPartitionedGP,
    mean_only,
)
from .evaluate import leave_one_experiment_out, score_traces
from .features import (
    BASE_FEATURES,
    DIDT_FEATURES,
    FEATURES,
    PHYSICS_FEATURES,
    FeatureBuilder,
    direction_of_travel,
    target_pressure,
)
from .hybrid import HYBRID_FEATURES, HybridModel
from .kernels import KERNELS, KernelSpec, kernel_spec
from .labels import EVENT, LATCHED, UNLATCHED, LatchLabelRule, latch_labels
from .lag import LAG_GRID_S, LagSelection, select_lag
from .latch_local import LocalEventDecision, censored_share, line_coupling, local_law
from .latch_summary import LATCH_NAMES, latch_decision_text
from .latch_timing import LatchTiming
from .local_gp import LocalGPRegressor, log_marginal_likelihood
from .model_check import check_model, check_model_document
from .persist import load_model, no_substeps_message, save_model
from .physics import DefaultPhysics as DefaultPhysics  # deprecated alias, not in __all__
from .physics import PhysicsPredictor
from .rate_probe import between_rate_inputs, play_faster, ramp_rate
from .residual_variance import fit_variance_floor, loeo_residuals, variance_floor
from .step import StepPredictor, step_predictor
from .variants import VARIANTS, make_variant

__all__ = [
    "BASE_FEATURES",
    "CLASSIFIERS",
    "DEFAULT_LATCH_MODEL",
    "DIDT_FEATURES",
    "EVENT",
    "FEATURES",
    "GP_PRESSURE_RATE_SCALE",
    "HYBRID_FEATURES",
    "KERNELS",
    "LAG_GRID_S",
    "LATCHED",
    "LATCH_BANDWIDTH",
    "LATCH_MODELS",
    "LATCH_NAMES",
    "LATCH_RATE_SCALE",
    "LATCH_RATE_SCALES",
    "PHYSICS_FEATURES",
    "PRESSURE_RATE_SCALE",
    "RBF_FEATURE_WEIGHTS",
    "UNLATCHED",
    "VARIANTS",
    "BinnedClassifier",
    "Bins",
    "ClassifierComparison",
    "ColumnWeights",
    "FeatureBuilder",
    "GPBaseline",
    "GPWithDerivative",
    "HybridModel",
    "KernelSpec",
    "LagSelection",
    "LatchLabelRule",
    "LatchTiming",
    "LocalEventDecision",
    "LocalGPRegressor",
    "PhysicsPredictor",
    "SVCPartitionedGP",
    "StepPredictor",
    "TraceEstimator",
    "as_traces",
    "between_rate_inputs",
    "censored_share",
    "check_model",
    "check_model_document",
    "compare_classifiers",
    "direction_of_travel",
    "fit_variance_floor",
    "grid_bins",
    "kernel_spec",
    "latch_decision_text",
    "latch_labels",
    "leave_one_experiment_out",
    "line_coupling",
    "load_model",
    "local_law",
    "loeo_residuals",
    "log_marginal_likelihood",
    "make_classifier",
    "make_variant",
    "mean_only",
    "no_substeps_message",
    "play_faster",
    "ramp_rate",
    "save_model",
    "score_traces",
    "select_lag",
    "step_predictor",
    "target_pressure",
    "variance_floor",
]
