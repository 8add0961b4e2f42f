"""A JSON object read from a file, to tell what kind of clutchlab file it is."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["MODEL_FILE_KINDS", "model_doc_kind", "model_file_kind", "read_json_object"]


def read_json_object(path: str | Path, max_bytes: int | None = None) -> dict[str, Any] | None:
    """The JSON object in ``path``, or None when there is none to read.

    Used to recognize a file before it is loaded and checked (a fit result, a parameter
    file, a saved model): what the file is decides which loader names its problems.

    Parameters
    ----------
    path : path-like
        The file.
    max_bytes : int, optional
        Larger files are not read (None: no limit).

    Returns
    -------
    dict or None
        None when the file is missing, not a regular file, larger than ``max_bytes``, not
        UTF-8 JSON, nested too deeply, or holds something other than an object.
    """
    path = Path(path)
    try:
        if max_bytes is not None and (not path.is_file() or path.stat().st_size > max_bytes):
            return None
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None


#: The model files clutchlab writes as JSON, by kind (what :func:`model_file_kind` returns).
MODEL_FILE_KINDS = {
    "fit": "a fitted physics model (clutchlab fit-physics)",
    "ml": "a model of clutchlab train",
    "physics": "a physics model description (PhysicsPredictor)",
    "design": "a design's parameter file (clutchlab params --out)",
}


def model_doc_kind(doc: dict[str, Any] | None) -> str | None:
    """Which model a JSON object is by its keys (a key of :data:`MODEL_FILE_KINDS`), None for
    anything else; only recognized here, checked by the kind's own loader.

    ``ml``: a ``"format"`` key (``residual_ml.save_model``); ``physics``: ``"kind":
    "PhysicsPredictor"``; ``design``: a ``"parameters"`` key only (``ParameterSet.to_json``);
    ``fit``: ``values``, ``free``, ``status`` and ``effects`` (``FitResult.to_json``).
    """
    if doc is None:
        return None
    if "format" in doc:
        return "ml"
    if doc.get("kind") == "PhysicsPredictor":
        return "physics"
    if set(doc) == {"parameters"}:
        return "design"
    if {"values", "free", "status", "effects"} <= set(doc):
        return "fit"
    return None


def model_file_kind(path: str | Path) -> str | None:
    """:func:`model_doc_kind` of the JSON object in ``path`` (None when there is none)."""
    return model_doc_kind(read_json_object(path))
