"""Save and load fitted estimators as JSON (parameters, metadata) + NPZ (arrays), no pickle.

``save_model(model, "m.json")`` writes ``m.json`` and ``m.npz`` beside it; ``load_model``
reads them back (``numpy.load(..., allow_pickle=False)``). A loaded model predicts exactly
what the saved one did: the GP weights ``K⁻¹y`` and the classifier's support vectors and
coefficients are stored, not refitted. A hybrid model's physics is stored as its model
structure and parameter values (:class:`~clutchlab.residual_ml.physics.PhysicsPredictor`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator

from ..errors import ModelError
from .classifiers import KernelDecision, LinearDecision
from .estimators import GPBaseline, GPWithDerivative, SVCPartitionedGP
from .hybrid import HybridModel
from .labels import LatchLabelRule
from .local_gp import LocalGPRegressor
from .physics import PhysicsPredictor

__all__ = ["FORMAT", "load_model", "save_model"]

#: Format tag written into every model JSON.
FORMAT = "clutchlab.residual_ml"
_VERSION = 1
_CLASSES = {c.__name__: c for c in (GPBaseline, GPWithDerivative, SVCPartitionedGP, HybridModel)}


def _param_to_json(value):
    if isinstance(value, LatchLabelRule):
        return {"__rule__": value.to_dict()}
    if isinstance(value, PhysicsPredictor):
        return {"__physics__": value.to_dict()}
    if isinstance(value, BaseEstimator):
        return {"__estimator__": {"class": type(value).__name__, "params": _params(value)}}
    if isinstance(value, tuple | list):
        return [_param_to_json(v) for v in value]
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, np.integer | np.floating):
        return value.item()
    raise ModelError(f"cannot write parameter value of type {type(value).__name__} as JSON")


def _param_from_json(value):
    if isinstance(value, dict):
        if "__rule__" in value:
            return LatchLabelRule.from_dict(value["__rule__"])
        if "__physics__" in value:
            return PhysicsPredictor.from_dict(value["__physics__"])
        if "__estimator__" in value:
            spec = value["__estimator__"]
            return _CLASSES[spec["class"]](**_params_from(spec["params"]))
    if isinstance(value, list):
        return tuple(_param_from_json(v) for v in value)
    return value


def _params(est) -> dict:
    params = est.get_params(deep=False)
    if isinstance(est, HybridModel) and params.get("physics") is not None:
        phys = params["physics"]
        if not isinstance(phys, PhysicsPredictor):
            params["physics"] = _as_predictor(phys)
    return {k: _param_to_json(v) for k, v in params.items()}


def _params_from(d: dict) -> dict:
    return {k: _param_from_json(v) for k, v in d.items()}


def _as_predictor(phys) -> PhysicsPredictor:
    if isinstance(phys, PhysicsPredictor):
        return phys
    if hasattr(phys, "model_") and hasattr(phys, "params_"):  # a fitted PhysicsFitter
        return PhysicsPredictor.from_fitter(phys)
    raise ModelError(
        f"physics of type {type(phys).__name__} cannot be saved; use a PhysicsPredictor or a "
        "fitted PhysicsFitter"
    )


def _put(arrays: dict, prefix: str, values: dict) -> None:
    for k, v in values.items():
        arrays[f"{prefix}.{k}"] = np.asarray(v)


def _get(arrays, prefix: str) -> dict:
    p = prefix + "."
    return {k[len(p) :]: arrays[k] for k in arrays.files if k.startswith(p)}


def _state(est, arrays: dict, prefix: str) -> dict:
    state = {
        "feature_names": list(est.feature_names_),
        "train_experiments": list(est.train_experiments_),
        "n_features_in": int(est.n_features_in_),
        "lag_s": float(getattr(est, "lag_s_", 0.0)),
    }
    if isinstance(est, HybridModel):
        state["physics"] = None if est.physics_ is None else _as_predictor(est.physics_).to_dict()
        state["residual"] = {
            "class": type(est.residual_).__name__,
            "params": _params(est.residual_),
            "state": _state(est.residual_, arrays, prefix + "residual"),
        }
        return state
    if isinstance(est, SVCPartitionedGP):
        state["classifier_columns"] = [int(c) for c in est.classifier_columns_]
        state["classifier_train_accuracy"] = est.classifier_train_accuracy_
        state["single_state"] = est.single_state_
        dec = est.decision_
        if dec is None:
            state["decision"] = None
        else:
            if not isinstance(dec, KernelDecision | LinearDecision):
                dec.arrays()  # raises ModelError naming the classifier
            state["decision"] = dec.kind
            _put(arrays, prefix + "clf", dec.arrays())
        state["gps"] = {}
        for g, gp in est.gps_.items():
            meta, arr = gp.get_state()
            state["gps"][str(g)] = meta
            _put(arrays, f"{prefix}gp{g}", arr)
        return state
    meta, arr = est.gp_.get_state()
    state["gp"] = meta
    _put(arrays, prefix + "gp", arr)
    return state


def _restore(est, state: dict, arrays, prefix: str) -> None:
    est.feature_names_ = list(state["feature_names"])
    est.train_experiments_ = list(state["train_experiments"])
    est.n_features_in_ = int(state["n_features_in"])
    est.lag_s_ = float(state.get("lag_s", 0.0))  # files written before the lag feature: 0
    if isinstance(est, HybridModel):
        est.physics_ = (
            None if state["physics"] is None else PhysicsPredictor.from_dict(state["physics"])
        )
        r = state["residual"]
        res = _CLASSES[r["class"]](**_params_from(r["params"]))
        _restore(res, r["state"], arrays, prefix + "residual")
        est.residual_ = res
        return
    if isinstance(est, SVCPartitionedGP):
        est.classifier_columns_ = list(state["classifier_columns"])
        est.classifier_train_accuracy_ = float(state["classifier_train_accuracy"])
        est.single_state_ = state["single_state"]
        est.classifier_ = None
        kind = state["decision"]
        if kind is None:
            est.decision_ = None
        else:
            cls = KernelDecision if kind == KernelDecision.kind else LinearDecision
            est.decision_ = cls.from_arrays(_get(arrays, prefix + "clf"))
        est.gps_ = {}
        for g, meta in state["gps"].items():
            gp = LocalGPRegressor().set_params(kernel=meta["kernel"], ard=meta["ard"])
            est.gps_[int(g)] = gp.set_state(meta, _get(arrays, f"{prefix}gp{g}"))
        return
    gp = LocalGPRegressor().set_params(kernel=state["gp"]["kernel"], ard=state["gp"]["ard"])
    est.gp_ = gp.set_state(state["gp"], _get(arrays, prefix + "gp"))


def save_model(model, path: str | Path) -> Path:
    """Write a fitted estimator to ``path`` (JSON) and ``path`` with suffix ``.npz``.

    Parameters
    ----------
    model : GPBaseline, GPWithDerivative, SVCPartitionedGP or HybridModel
        Fitted estimator.
    path : path-like
        JSON file to write (``.json`` suffix recommended).

    Returns
    -------
    pathlib.Path
        The NPZ file written beside the JSON.

    Raises
    ------
    ModelError
        If the model is of another class or holds a part that cannot be written without
        pickle (e.g. a gradient-boosting classifier, an unknown physics object).
    """
    if type(model).__name__ not in _CLASSES:
        raise ModelError(f"cannot save a {type(model).__name__}; known: {', '.join(_CLASSES)}")
    model._check_fitted()
    path = Path(path)
    npz = path.with_suffix(".npz")
    arrays: dict[str, np.ndarray] = {}
    doc = {
        "format": FORMAT,
        "version": _VERSION,
        "class": type(model).__name__,
        "params": _params(model),
        "state": _state(model, arrays, ""),
        "arrays": npz.name,
    }
    text = json.dumps(doc, indent=2, allow_nan=True) + "\n"
    np.savez(npz, **arrays)
    path.write_text(text, encoding="utf-8")
    return npz


def load_model(path: str | Path):
    """Read an estimator written by :func:`save_model`.

    Parameters
    ----------
    path : path-like
        The model JSON (its NPZ is found beside it).

    Returns
    -------
    GPBaseline, GPWithDerivative, SVCPartitionedGP or HybridModel
        The fitted estimator.

    Raises
    ------
    ModelError
        If the file is not a clutchlab model or its arrays are missing.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ModelError(f"cannot read model file {path}: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelError(f"{path} is not a clutchlab residual_ml model (format {FORMAT!r})")
    if doc.get("class") not in _CLASSES:
        raise ModelError(f"{path}: unknown model class {doc.get('class')!r}")
    npz = path.with_name(doc["arrays"])
    if not npz.exists():
        raise ModelError(f"{path}: array file {npz} is missing")
    model = _CLASSES[doc["class"]](**_params_from(doc["params"]))
    with np.load(npz, allow_pickle=False) as arrays:
        _restore(model, doc["state"], arrays, "")
    return model
