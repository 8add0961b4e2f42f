"""Experiment metadata as JSON: in ``manifest.json`` and embedded in Parquet / MF4 files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .trace import Trace

__all__ = ["embedded_meta_json", "json_default", "parse_embedded_meta"]


def json_default(value: Any) -> Any:
    """JSON form of numpy scalars / arrays and paths (``json.dumps(default=...)``).

    Raises
    ------
    TypeError
        For any other type (the value is not JSON serializable).
    """
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} value {value!r} is not JSON serializable")


def embedded_meta_json(trace: Trace) -> str:
    """``{"name": ..., "meta": {...}, "units": {...}}`` of ``trace`` as JSON text."""
    return json.dumps(
        {"name": trace.name, "meta": trace.meta, "units": trace.units},
        default=json_default,
        allow_nan=False,
        ensure_ascii=False,
    )


def parse_embedded_meta(text: bytes | str) -> dict[str, Any] | None:
    """Inverse of :func:`embedded_meta_json`; None if ``text`` is not such a JSON object."""
    try:
        data = json.loads(text)
    except (ValueError, TypeError, RecursionError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("meta", {}), dict):
        return None
    return data
