"""Data layer: canonical signals, traces, datasets and their file formats (DESIGN §3).

A dataset is a folder with ``manifest.json`` and one file per experiment; each experiment is
a :class:`Trace` of canonical signals (:data:`SIGNALS`) in canonical units.
"""

from __future__ import annotations

from .dataset import Dataset
from .io_csv import read_csv, write_csv
from .io_dataset import load_dataset, save_dataset
from .signals import CANONICAL_ORDER, SIGNALS, SignalSpec, unit_of
from .trace import Trace

__all__ = [
    "CANONICAL_ORDER",
    "SIGNALS",
    "Dataset",
    "SignalSpec",
    "Trace",
    "load_dataset",
    "read_csv",
    "save_dataset",
    "unit_of",
    "write_csv",
]
