"""Data layer: canonical signals, traces, datasets and their file formats (DESIGN §3).

A dataset is a folder with ``manifest.json`` and one file per experiment (CSV, Parquet or
MF4); each experiment is a :class:`Trace` of canonical signals (:data:`SIGNALS`) in canonical
units. Logs with other channel names and units are read through a :class:`ChannelMap`;
every problem of a log is collected into one :class:`~clutchlab.errors.DataError`.
"""

from __future__ import annotations

from .autocorrelation import lagged_sums
from .channel_map import ChannelMap, ChannelSpec, load_channel_map
from .check import CheckResult, check_path
from .convert import convert
from .dataset import Dataset
from .demodulate import (
    DitherEstimate,
    demodulate_dither,
    demodulate_trace,
    didt_period_samples,
    nominal_current,
    nominal_didt,
)
from .derived import (
    causal_didt,
    causal_window,
    didt,
    dither_period_mean,
    dither_period_samples,
    first_crossing,
    first_order_lag,
)
from .experiments import as_traces
from .formats import FORMATS, FileFormat
from .io_csv import read_csv, write_csv
from .io_dataset import DatasetScan, load_dataset, save_dataset, scan_dataset
from .io_mat import write_mat, write_mat73
from .io_mf4 import read_mf4, write_mf4
from .io_parquet import read_parquet, write_parquet
from .json_file import MODEL_FILE_KINDS, model_doc_kind, model_file_kind, read_json_object
from .metrics import pressure_metrics
from .options import ReadOptions
from .output import OWNED_NAME, check_output, owned_files, write_file_atomic, write_folder_atomic
from .ramps import order_ramps, ramp_rate_mA_s, ramps_fastest_first
from .reading import check_log, read_log
from .report import LoadReport
from .signals import CANONICAL_ORDER, LINE_PRESSURE_BAR, SIGNALS, SignalSpec, unit_of
from .timebase import Timing
from .trace import Trace
from .units import convert_units, parse_unit
from .validate import validate_trace

__all__ = [
    "CANONICAL_ORDER",
    "FORMATS",
    "LINE_PRESSURE_BAR",
    "MODEL_FILE_KINDS",
    "OWNED_NAME",
    "SIGNALS",
    "ChannelMap",
    "ChannelSpec",
    "CheckResult",
    "Dataset",
    "DatasetScan",
    "DitherEstimate",
    "FileFormat",
    "LoadReport",
    "ReadOptions",
    "SignalSpec",
    "Timing",
    "Trace",
    "as_traces",
    "causal_didt",
    "causal_window",
    "check_log",
    "check_output",
    "check_path",
    "convert",
    "convert_units",
    "demodulate_dither",
    "demodulate_trace",
    "didt",
    "didt_period_samples",
    "dither_period_mean",
    "dither_period_samples",
    "first_crossing",
    "first_order_lag",
    "lagged_sums",
    "load_channel_map",
    "load_dataset",
    "model_doc_kind",
    "model_file_kind",
    "nominal_current",
    "nominal_didt",
    "order_ramps",
    "owned_files",
    "parse_unit",
    "pressure_metrics",
    "ramp_rate_mA_s",
    "ramps_fastest_first",
    "read_csv",
    "read_json_object",
    "read_log",
    "read_mf4",
    "read_parquet",
    "save_dataset",
    "scan_dataset",
    "unit_of",
    "validate_trace",
    "write_csv",
    "write_file_atomic",
    "write_folder_atomic",
    "write_mat",
    "write_mat73",
    "write_mf4",
    "write_parquet",
]
