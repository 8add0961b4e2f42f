"""The fitted variants of an evaluation as files, for ``predict`` and ``export-fmu``.

``clutchlab evaluate`` and ``clutchlab demo`` fit every variant; the report folder keeps
them under ``models/`` so that the models scored there are the models a user then predicts
new logs with or exports as an FMU — without fitting again.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from ..errors import ClutchlabError

__all__ = ["MODELS_FOLDER", "model_files"]

#: Folder of the saved models inside a report folder.
MODELS_FOLDER = "models"

#: Variants with nothing of their own to save, and why.
_NOT_SAVED = {
    "physics_default": "datasheet values: `clutchlab params --out design.json` writes them",
    "physics_fmu": "the FMU given to the evaluation is the model",
}


def _fit_result_files(name: str, model: Any) -> dict[str, bytes]:
    result = model.fitter_.result_
    return {f"{MODELS_FOLDER}/{name}.json": (result.to_json() + "\n").encode("utf-8")}


def _estimator_files(name: str, model: Any) -> dict[str, bytes]:
    from ..residual_ml import save_model

    with tempfile.TemporaryDirectory(prefix="clutchlab-model-") as tmp:
        path = Path(tmp) / f"{name}.json"
        npz = save_model(model, path)
        return {
            f"{MODELS_FOLDER}/{name}.json": path.read_bytes(),
            f"{MODELS_FOLDER}/{npz.name}": npz.read_bytes(),
        }


def model_files(models: dict[str, Any]) -> tuple[dict[str, dict[str, bytes]], dict[str, str]]:
    """Files of the fitted models of an evaluation (``Evaluation.models``).

    ``physics_fitted`` is written as a ``fit-physics`` result (``models/physics_fitted.json``),
    the ML variants and the hybrids as ``train`` writes a model (``models/<variant>.json`` +
    ``.npz``; an augmented hybrid with the effects its discovery added, in its physics).

    Parameters
    ----------
    models : dict of str to object
        Variant name → fitted model.

    Returns
    -------
    (dict of str to dict of str to bytes, dict of str to str)
        Variant name → its files (relative path → content); and variant name → why it has
        no file (nothing of its own to save, or a part that cannot be saved without pickle).
    """
    saved: dict[str, dict[str, bytes]] = {}
    skipped: dict[str, str] = {}
    for name, model in models.items():
        if name in _NOT_SAVED:
            skipped[name] = _NOT_SAVED[name]
            continue
        target = getattr(model, "hybrid_", None) or model  # augmented_hybrid: its hybrid
        try:
            if hasattr(target, "fitter_"):
                saved[name] = _fit_result_files(name, target)
            else:
                saved[name] = _estimator_files(name, target)
        except ClutchlabError as exc:
            skipped[name] = str(exc).splitlines()[0]
    return saved, skipped
