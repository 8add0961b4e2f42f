"""Design studies before hardware: sweep model parameters and dither settings.

A :class:`SweepSpec` (TOML, :func:`load_spec`) names the model, the stand scenario (ramps,
dither, a current step) and the design variables with their ranges (grid or Latin
hypercube). :func:`run_sweep` evaluates every design point — in local processes or on a Dask
cluster, with the same numbers either way — and computes the engineering metrics a
calibration engineer reads (regulated gain, latch-on / latch-off current, hysteresis width
per ramp rate, step response time, dither ripple). Results are appended to Parquet part
files as they finish, so a killed sweep restarts where it stopped; a failing point is
recorded with its error. :func:`write_figures` draws the tornado and metric-vs-variable
charts.
"""

from .evaluate import STATUS_FAILED, STATUS_OK, DesignEvaluator, evaluate_batch
from .figures import plot_metrics_vs_variables, plot_tornado, write_figures
from .metrics import METRIC_UNITS, MetricSettings, metric_names
from .runner import SweepResult, run_sweep
from .sampling import DesignPoint, design_points, point_id
from .scenario import DitherChoice, ramp_trace, step_trace
from .sensitivity import sensitivity_table
from .spec import (
    SCENARIO_VARIABLES,
    ModelSpec,
    SamplingSpec,
    ScenarioSpec,
    SimulationSpec,
    SpecError,
    StepSpec,
    SweepSpec,
    Variable,
    load_spec,
)
from .store import ResultStore, UnfinishedSweepWarning, read_results

__all__ = [
    "METRIC_UNITS",
    "SCENARIO_VARIABLES",
    "STATUS_FAILED",
    "STATUS_OK",
    "DesignEvaluator",
    "DesignPoint",
    "DitherChoice",
    "MetricSettings",
    "ModelSpec",
    "ResultStore",
    "SamplingSpec",
    "ScenarioSpec",
    "SimulationSpec",
    "SpecError",
    "StepSpec",
    "SweepResult",
    "SweepSpec",
    "UnfinishedSweepWarning",
    "Variable",
    "design_points",
    "evaluate_batch",
    "load_spec",
    "metric_names",
    "plot_metrics_vs_variables",
    "plot_tornado",
    "point_id",
    "ramp_trace",
    "read_results",
    "run_sweep",
    "sensitivity_table",
    "step_trace",
    "write_figures",
]
