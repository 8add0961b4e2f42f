"""Save and load fitted estimators as JSON (parameters, metadata) + NPZ (arrays), no pickle.

``save_model(model, "m.json")`` writes ``m.json`` and ``m.npz`` beside it (``"m.npz"`` as
the model's name is refused: the JSON would be written over its arrays; a file clutchlab did
not write is never replaced); ``load_model``
reads them back (``numpy.load(..., allow_pickle=False)``). A loaded model predicts exactly
what the saved one did: the GP weights ``K⁻¹y`` and the classifier's support vectors and
coefficients are stored, not refitted. A hybrid model's physics is stored as its model
structure and parameter values (:class:`~clutchlab.residual_ml.physics.PhysicsPredictor`).

Both directions go through one check (:func:`~clutchlab.residual_ml.model_check.
check_model_document`): a file with a missing or mistyped key, an array of the wrong shape,
a non-finite value or a zero scale is refused with every problem listed, and a model that
would write such a file is not written. The array file is read only from beside the JSON.
"""

from __future__ import annotations

import json
import math
import zipfile
import zlib
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator

from ..data.json_file import read_json_object
from ..data.output import check_output, write_file_atomic
from ..errors import ClutchlabError, ModelError, ModelFileError, OutputError
from ..physics.fit.fitter import check_savable
from .estimators import SVCPartitionedGP
from .hybrid import HybridModel
from .labels import LatchLabelRule
from .latch_timing import LatchTiming
from .local_gp import LocalGPRegressor
from .model_check import (
    DECISIONS,
    FORMAT,
    FORMAT_VERSIONS,
    MODEL_CLASSES,
    check_model_document,
    npz_name_problem,
)
from .physics import PhysicsPredictor

__all__ = [
    "FORMAT",
    "check_model_destination",
    "load_model",
    "model_document",
    "no_substeps_message",
    "save_model",
]

_VERSION = FORMAT_VERSIONS[-1]


def no_substeps_message(path) -> str:
    """Why ``--substeps`` is refused for the saved ML model at ``path`` (predict, export-fmu).

    Parameters
    ----------
    path : path-like
        The model file, named in the message.

    Returns
    -------
    str
    """
    return (
        f"{path}: --substeps sets the ROS2 steps of a fitted physics model; an ML model has "
        "none to set (a hybrid's physics keeps the substeps it was trained with)"
    )


_CLASSES = MODEL_CLASSES
#: Errors numpy and zipfile raise on a damaged or hostile NPZ: truncated, not a zip, an
#: object array that would need pickle, a bad header or compressed stream, a zip member
#: flagged encrypted (RuntimeError) or with an unsupported method or flag
#: (NotImplementedError).
_NPZ_ERRORS = (
    OSError,
    ValueError,
    EOFError,
    KeyError,
    RuntimeError,
    NotImplementedError,
    zipfile.BadZipFile,
    zlib.error,
)


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
    """The physics of a hybrid as a :class:`PhysicsPredictor`: a fitted PhysicsFitter, or an
    estimator wrapping one (``fitter_``: the evaluation's ``physics_fitted``) or holding a
    fitted model and values (``model_``, ``params_``: the discovery's augmented physics),
    each simulated as they are, with the default 4 substeps."""
    if isinstance(phys, PhysicsPredictor):
        return phys
    fitter = getattr(phys, "fitter_", None)
    if fitter is not None and hasattr(fitter, "model_"):
        return PhysicsPredictor.from_fitter(fitter)
    if hasattr(phys, "model_") and hasattr(phys, "params_"):
        if hasattr(phys, "_check_fitted"):  # a fitted PhysicsFitter
            return PhysicsPredictor.from_fitter(phys)
        trained = tuple(getattr(phys, "train_experiments_", None) or ())
        check_savable(phys.model_)
        return PhysicsPredictor(tuple(phys.model_.effect_names), phys.params_.changed(), 4, trained)
    raise ModelError(
        f"physics of type {type(phys).__name__} cannot be saved; use a PhysicsPredictor or a "
        "fitted PhysicsFitter"
    )


def _put(arrays: dict, prefix: str, values: dict) -> None:
    for k, v in values.items():
        arrays[f"{prefix}.{k}"] = np.asarray(v)


def _get(arrays, prefix: str) -> dict:
    p = prefix + "."
    return {k[len(p) :]: v for k, v in arrays.items() if k.startswith(p)}


def _state(est, arrays: dict, prefix: str) -> dict:
    state = {
        "feature_names": list(est.feature_names_),
        "train_experiments": list(est.train_experiments_),
        "n_features_in": int(est.n_features_in_),
        "lag_s": float(getattr(est, "lag_s_", 0.0)),
    }
    if isinstance(est, HybridModel):
        state["physics"] = None if est.physics_ is None else _as_predictor(est.physics_).to_dict()
        state["form"] = getattr(est, "form_", "residual")
        state["form_scores"] = dict(getattr(est, "form_scores_", {}))
        kappa = float(getattr(est, "standalone_handicap_", math.nan))
        state["standalone_handicap"] = kappa if math.isfinite(kappa) else None
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
        state["latched_reference"] = getattr(est, "latched_reference_", "none")
        timing = getattr(est, "latch_timing_", None)
        state["latch_timing"] = None if timing is None else timing.to_dict()
        state["train_log_rates"] = [float(u) for u in getattr(est, "train_log_rates_", [])]
        state["noise_by_freq"] = {
            str(g): [float(c), float(v)] for g, (c, v) in getattr(est, "noise_by_freq_", {}).items()
        }
        dec = est.decision_
        if dec is None:
            state["decision"] = None
        else:
            if not isinstance(dec, tuple(DECISIONS.values())):
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
    state["train_log_rates"] = [float(u) for u in getattr(est, "train_log_rates_", [])]
    floor = getattr(est, "variance_floor_", None)
    state["variance_floor"] = None
    if floor is not None:
        meta, arr = floor.get_state()
        state["variance_floor"] = meta
        _put(arrays, prefix + "floor", arr)
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
        # Files written before the residual-form choice hold the residual form.
        est.form_ = state.get("form", "residual")
        est.form_scores_ = {k: float(v) for k, v in state.get("form_scores", {}).items()}
        kappa = state.get("standalone_handicap")  # not in files written before it was measured
        est.standalone_handicap_ = math.nan if kappa is None else float(kappa)
        r = state["residual"]
        res = _CLASSES[r["class"]](**_params_from(r["params"]))
        _restore(res, r["state"], arrays, prefix + "residual")
        est.residual_ = res
        return
    if isinstance(est, SVCPartitionedGP):
        est.classifier_columns_ = list(state["classifier_columns"])
        est.classifier_train_accuracy_ = float(state["classifier_train_accuracy"])
        est.single_state_ = state["single_state"]
        # Files written before the line reference: the latched GP learned the pressure.
        est.latched_reference_ = state.get("latched_reference", "none")
        # Files written before the latch-timing mixture: the GP std alone.
        timing = state.get("latch_timing")
        est.latch_timing_ = None if timing is None else LatchTiming.from_dict(timing)
        est.train_log_rates_ = [float(u) for u in state.get("train_log_rates", [])]
        est.noise_by_freq_ = {
            int(g): (float(c), float(v)) for g, (c, v) in state.get("noise_by_freq", {}).items()
        }
        est.classifier_ = None
        kind = state["decision"]
        if kind is None:
            est.decision_ = None
        else:
            cls = DECISIONS[kind]
            est.decision_ = cls.from_arrays(_get(arrays, prefix + "clf"))
        est.gps_ = {}
        for g, meta in state["gps"].items():
            est.gps_[int(g)] = _gp_from(meta, _get(arrays, f"{prefix}gp{g}"))
        return
    est.gp_ = _gp_from(state["gp"], _get(arrays, prefix + "gp"))
    # Files written before the rate bridge and the residual-variance floor: neither.
    est.train_log_rates_ = [float(u) for u in state.get("train_log_rates", [])]
    floor = state.get("variance_floor")
    est.variance_floor_ = None if floor is None else _gp_from(floor, _get(arrays, prefix + "floor"))


def _gp_from(meta: dict, arrays: dict) -> LocalGPRegressor:
    """A :class:`LocalGPRegressor` from its saved state."""
    gp = LocalGPRegressor().set_params(kernel=meta["kernel"], ard=meta["ard"])
    return gp.set_state(meta, arrays)


def model_document(model, npz_name: str) -> tuple[dict, dict[str, np.ndarray]]:
    """The JSON document and the arrays :func:`save_model` writes for ``model``.

    Parameters
    ----------
    model : GPBaseline, GPWithDerivative, SVCPartitionedGP or HybridModel
        Fitted estimator.
    npz_name : str
        File name of the NPZ, recorded in the document.

    Returns
    -------
    doc : dict
        JSON-ready document (format, version, class, parameters, learned state).
    arrays : dict of str to numpy.ndarray
        The arrays, by name.

    Raises
    ------
    ModelError
        If the model is of another class or holds a part that cannot be written without
        pickle (e.g. a gradient-boosting classifier, an unknown physics object), or lacks
        part of its fitted state.
    """
    if type(model).__name__ not in _CLASSES or not isinstance(model, BaseEstimator):
        raise ModelError(f"cannot save a {type(model).__name__}; known: {', '.join(_CLASSES)}")
    model._check_fitted()
    arrays: dict[str, np.ndarray] = {}
    try:
        doc = {
            "format": FORMAT,
            "version": _VERSION,
            "class": type(model).__name__,
            "params": _params(model),
            "state": _state(model, arrays, ""),
            "arrays": npz_name,
        }
    except (AttributeError, KeyError, TypeError) as exc:  # a fitted attribute deleted or replaced
        raise ModelError(
            f"the {type(model).__name__} lacks part of its fitted state ({exc!r}); refit it"
        ) from exc
    return doc, arrays


def save_model(model, path: str | Path) -> Path:
    """Write a fitted estimator to ``path`` (JSON) and ``path`` with suffix ``.npz``.

    The model is checked first (:func:`~clutchlab.residual_ml.model_check.check_model`):
    nothing is written for a model whose file would not load.

    The destination is checked first too: the JSON and the NPZ must be two different
    files, and an existing file is replaced only when clutchlab wrote it (a model JSON, and
    the NPZ that JSON names); anything else standing there is refused by name.

    Parameters
    ----------
    model : GPBaseline, GPWithDerivative, SVCPartitionedGP or HybridModel
        Fitted estimator.
    path : path-like
        JSON file to write (``.json`` suffix recommended; never ``.npz``, the name of the
        arrays file written beside it).

    Returns
    -------
    pathlib.Path
        The NPZ file written beside the JSON.

    Raises
    ------
    ModelError
        If the model is of another class or holds a part that cannot be written without
        pickle (e.g. a gradient-boosting classifier, an unknown physics object).
    ModelFileError
        If its state is not valid (non-finite arrays, zero scales, ...), listing every
        problem.
    OutputError
        Before anything is written: if ``path`` ends in ``.npz`` (the JSON would be written
        over its own arrays), the two names lead to one file, either is a folder or lies
        in one that cannot be written, or a file there was not written by clutchlab (a
        JSON that is not a clutchlab model, an NPZ that no model JSON at ``path`` names).
    """
    path = Path(path)
    npz = _destination(path)
    doc, arrays = model_document(model, npz.name)
    check_model_document(doc, arrays, f"{type(model).__name__} to be saved as {path}")
    text = json.dumps(doc, indent=2, allow_nan=True) + "\n"
    # each file atomically, the JSON (which names the arrays) last
    write_file_atomic(npz, lambda tmp: _savez(tmp, arrays), overwrite=True)
    write_file_atomic(path, text.encode("utf-8"), overwrite=True)
    return npz


#: Largest existing JSON read to decide whether clutchlab wrote it (a model JSON holds
#: parameters and metadata only, its arrays are in the NPZ).
_MAX_OWN_JSON_BYTES = 64 * 2**20


def _own_document(path: Path) -> dict | None:
    """The model document at ``path`` if it is a clutchlab model JSON, else None."""
    doc = read_json_object(path, max_bytes=_MAX_OWN_JSON_BYTES)
    return doc if doc is not None and doc.get("format") == FORMAT else None


def _destination(path: Path) -> Path:
    """The NPZ to be written beside the model JSON ``path``, once both may be written.

    Raises
    ------
    OutputError
        As :func:`save_model` says, before anything is written.
    """
    try:
        npz = path.with_suffix(".npz")
    except ValueError:  # no file name: "", ".", a folder ending in "/.."
        raise OutputError(f"{str(path)!r}: not a file name for a model") from None
    if path.suffix.lower() == ".npz" or npz == path:
        json_name = path.with_suffix(".json").name
        raise OutputError(
            f"{path}: a model is saved as a JSON file with its arrays beside it as a .npz of "
            f"the same name; give the JSON's name (e.g. {json_name}, which writes "
            f"{json_name} + {npz.name}), not the .npz's"
        )
    check_output(path, kind="file", overwrite=True, what="model file")
    check_output(npz, kind="file", overwrite=True, what="model arrays file")
    try:
        same = path.exists() and npz.exists() and path.samefile(npz)
    except OSError:
        same = False
    if same:
        raise OutputError(f"{path} and {npz}: are one file; a model needs two (JSON + NPZ)")
    doc = _own_document(path)
    if path.exists() and doc is None:
        raise OutputError(
            f"{path}: exists and is not a clutchlab model file; it is not replaced (choose "
            "another name, or remove it)"
        )
    if (npz.exists() or npz.is_symlink()) and (doc is None or doc.get("arrays") != npz.name):
        raise OutputError(
            f"{npz}: exists and is not the arrays file of a clutchlab model saved as "
            f"{path.name}; it is not replaced (choose another name, or remove it)"
        )
    return npz


def check_model_destination(path: str | Path) -> Path:
    """Refuse, before any fit, a model JSON name :func:`save_model` would refuse.

    Parameters
    ----------
    path : path-like
        The model JSON to be written (its NPZ goes beside it).

    Returns
    -------
    pathlib.Path
        The NPZ that will be written beside the JSON.

    Raises
    ------
    OutputError
        As :func:`save_model` does before writing (a ``.npz`` name, a folder in the way, a
        file there that clutchlab did not write: a JSON that is not a clutchlab model, an
        NPZ that no model JSON at ``path`` names).
    """
    return _destination(Path(path))


def _savez(path: Path, arrays: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as fh:  # a file object: NumPy adds no ".npz" to the temporary name
        np.savez(fh, **arrays)


def _read_arrays(path: Path, name: str) -> tuple[dict[str, np.ndarray] | None, str | None]:
    """Every array of the NPZ ``name`` beside ``path``, read without pickle, and never
    from outside the JSON's folder; ``(arrays, None)`` or ``(None, problem)``."""
    npz = path.with_name(name)  # a bare file name: checked by the document check
    where = f"array file {name}"
    try:
        real = npz.resolve(strict=True)
    except (OSError, RuntimeError):
        return None, f"{where}: missing"
    if real.parent != path.parent.resolve():
        return None, f"{where}: links outside the model's folder ({real}); refused"
    if not real.is_file():
        return None, f"{where}: not a regular file"
    try:
        f = np.load(real, allow_pickle=False)
        if not isinstance(f, np.lib.npyio.NpzFile):
            return None, f"{where}: not an NPZ archive"
        with f:
            return {k: f[k] for k in f.files}, None
    except _NPZ_ERRORS as exc:
        return None, f"{where}: cannot be read: {type(exc).__name__}: {exc}"


def load_model(path: str | Path):
    """Read an estimator written by :func:`save_model`.

    Nothing is built before the document and every array have passed
    :func:`~clutchlab.residual_ml.model_check.check_model_document`; the NPZ is read
    without pickle and only from the JSON's folder.

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
        If the file is not a clutchlab model.
    ModelFileError
        (a ModelError) If its content is not valid — missing or mistyped keys, arrays
        missing, of inconsistent shapes, non-finite or zero scales, an unknown class or
        format version, an array file outside the model's folder — listing every problem
        with the file, key and array.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        raise ModelError(f"cannot read model file {path}: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelError(f"{path} is not a clutchlab residual_ml model (format {FORMAT!r})")
    arrays, problem = None, None
    if npz_name_problem(doc.get("arrays")) is None:  # else the check names it; nothing is read
        arrays, problem = _read_arrays(path, doc["arrays"])
    problems = [problem] if problem else []
    try:
        check_model_document(doc, arrays, str(path))
    except ModelFileError as exc:
        problems += exc.problems
    if problems:
        raise ModelFileError(f"{path}: not a valid clutchlab model", problems)
    try:
        model = _CLASSES[doc["class"]](**_params_from(doc["params"]))
        _restore(model, doc["state"], arrays, "")
    except ClutchlabError as exc:
        raise ModelFileError(f"{path}: not a valid clutchlab model", [str(exc)]) from exc
    return model
