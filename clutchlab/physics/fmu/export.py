"""Export a fitted physics model as an FMU."""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path

from ...data import model_file_kind, read_json_object
from ...errors import ClutchlabError, FitError, FitResultError, FitWarning
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..settings import SimulationSettings
from .build import build_fmu
from .errors import FmuError
from .physics import check_export_options, physics_program

__all__ = ["design_source", "export_physics_fmu", "physics_source", "source_origin"]


def physics_source(source) -> tuple[CircuitModel, ParameterSet]:
    """The model and parameter values of a fitted physics model.

    Parameters
    ----------
    source : path-like, FitResult, PhysicsFitter or (CircuitModel, ParameterSet)
        A fit JSON written by ``clutchlab fit-physics`` / ``PhysicsFitter.save``, a parameter
        file of a design before any fit (:func:`design_source`), a fit result, a fitted
        fitter, or a model with its parameters.

    Raises
    ------
    FmuError
        When ``source`` is none of these (a JSON that is not a fit result is named).
    """
    model, params, _ = _resolve(source)
    return model, params


def source_origin(source) -> dict[str, str]:
    """Where the parameter values of ``source`` come from, as written into the FMU.

    Parameters
    ----------
    source : path-like, FitResult, PhysicsFitter or (CircuitModel, ParameterSet)
        As :func:`physics_source`.

    Returns
    -------
    dict
        ``"source"``: ``"fit"`` (a fit result), ``"design"`` (a parameter file: datasheet
        or edited values, never fitted) or ``"given"`` (a model and its parameters);
        for a fit also ``"fit_converged"`` (``"true"`` / ``"false"``) and ``"fit_status"``
        (the solver's status); ``"summary"``: the same in words, for the description.
    """
    return _resolve(source)[2]


def _fit_origin(result) -> dict[str, str]:
    converged = bool(result.success)
    summary = (
        f"fitted (fit status: {result.status})"
        if converged
        else f"fitted, NOT CONVERGED: the fit's best iterate (fit status: {result.status})"
    )
    return {
        "source": "fit",
        "fit_converged": "true" if converged else "false",
        "fit_status": str(result.status),
        "summary": summary,
    }


def _resolve(source) -> tuple[CircuitModel, ParameterSet, dict[str, str]]:
    """The model, its parameter values and their origin (:func:`source_origin`)."""
    from ..fit import FitResult, PhysicsFitter

    if isinstance(source, tuple) and len(source) == 2:
        model, params = source
        if isinstance(model, CircuitModel) and isinstance(params, ParameterSet):
            return model, params, {"source": "given", "summary": "as given"}
    if isinstance(source, PhysicsFitter):
        if not hasattr(source, "result_"):
            raise FmuError("the PhysicsFitter is not fitted; fit it or load a fit JSON first")
        return source.model_, source.params_, _fit_origin(source.result_)
    if isinstance(source, FitResult):
        return source.model(), source.params(), _fit_origin(source)
    if isinstance(source, str | Path) and Path(source).is_file() and zipfile.is_zipfile(source):
        raise FmuError(
            f"{source}: is an FMU (a zip archive), not a model to export; give the fit JSON "
            "(clutchlab fit-physics --out), a design file (clutchlab params --out) or a "
            "model of clutchlab train"
        )
    if isinstance(source, str | Path) and _is_parameter_file(Path(source)):
        model, params = design_source(source)
        summary = f"a design before any fit (parameter file {Path(source).name})"
        return model, params, {"source": "design", "summary": summary}
    if isinstance(source, str | Path):
        try:  # the content is checked as it is read (FitResult.from_json)
            result = FitResult.from_json(Path(source))
        except FitResultError as exc:  # every problem of the content, one per line
            raise FmuError(
                f"{source}: not a fitted physics model", exc.problems or [str(exc)]
            ) from exc
        except FitError as exc:
            raise FmuError(f"{source}: not a fitted physics model ({exc})") from exc
        try:
            return result.model(), result.params(), _fit_origin(result)
        except ClutchlabError as exc:  # not expected after the check; named if it happens
            raise FmuError(f"{source}: the fitted model cannot be rebuilt: {exc}") from exc
    raise FmuError(
        f"cannot export {type(source).__name__}: expected a fit JSON path, FitResult, "
        "fitted PhysicsFitter or (CircuitModel, ParameterSet)"
    )


def design_source(path: str | Path) -> tuple[CircuitModel, ParameterSet]:
    """The model and values of a design before any fit: a parameter file.

    A parameter file (:meth:`~clutchlab.physics.ParameterSet.to_json`) holds values, not the
    model they are for; the model is the datasheet circuit with every effect (or flexible
    law) that declares one of the file's parameters switched on. Parameters the file does
    not list keep their defaults.

    Parameters
    ----------
    path : path-like
        ``{"parameters": {name: {"value": v, "unit": u}}}``, values in each parameter's unit.

    Returns
    -------
    (CircuitModel, ParameterSet)

    Raises
    ------
    FmuError
        Listing every problem of the file: a name no model has, a wrong unit, a value that is
        not a number or lies outside its bounds.
    """
    from ..effects import EFFECTS, FLEXIBLE_LAWS, effect_of_parameter

    doc = read_json_object(path) or {}
    names = list(doc["parameters"]) if isinstance(doc.get("parameters"), dict) else []
    base = {p.name for p in CircuitModel().parameters}
    owners = dict.fromkeys(o for n in names if n not in base and (o := effect_of_parameter(n)))
    laws = [(EFFECTS.get(o) or FLEXIBLE_LAWS[o])() for o in owners]
    model = CircuitModel().with_effects(*laws)
    try:
        params = ParameterSet.from_json(model.parameters, Path(path))
    except ClutchlabError as exc:
        raise FmuError(
            f"{path}: not a usable parameter file", getattr(exc, "problems", None) or [str(exc)]
        ) from exc
    return model, params


def _is_parameter_file(path: Path) -> bool:
    """Whether ``path`` is a JSON object whose only key is ``parameters``."""
    return model_file_kind(path) == "design"


def export_physics_fmu(
    source,
    path: str | Path,
    drive: str = "command",
    substeps: int | None = None,
    name: str | None = None,
    step_s: float = 1e-3,
    stop_time_s: float = 23.0,
    settings: SimulationSettings | None = None,
) -> Path:
    """Write an FMI 2.0 co-simulation FMU of a fitted physics model.

    Parameters
    ----------
    source : path-like, FitResult, PhysicsFitter or (CircuitModel, ParameterSet)
        The fitted model (see :func:`physics_source`).
    path : path-like
        ``.fmu`` file to write.
    drive : {"command", "measured"}
        Inputs: nominal current + dither (``command``, co-simulation with a controller)
        or the measured coil current (``measured``, replaying logs); see
        :func:`~clutchlab.physics.fmu.physics.physics_program`.
    substeps : int, optional
        ROS2 steps per internal step (1 … 16; default: the simulator's, 4). The internal
        step is at most 1 ms (:data:`~clutchlab.physics.fmu.physics.INTERNAL_STEP_S`),
        whatever the communication step.
    name : str, optional
        Model identifier (default ``clutch_circuit_<drive>``).
    step_s : float
        Communication step of the default experiment (s), 1 ms for a 1 kHz loop. Only the
        default experiment: a longer step (e.g. 10 ms) is split into internal steps.
    stop_time_s : float
        Default experiment stop time (s).
    settings : SimulationSettings, optional
        Settling time and default dither waveform.

    Returns
    -------
    Path
        The FMU written. Its description and vendor annotation say where the parameter
        values come from (:func:`source_origin`): a fit (and whether it converged) or a
        design before any fit.

    Raises
    ------
    FmuError
        ``source`` is not a fitted model, or ``substeps`` / ``step_s`` / ``stop_time_s``
        are out of range (checked first, before the model is read or anything compiled).

    Warns
    -----
    FitWarning
        ``source`` is a fit that did not converge (stopped at a limit): the FMU holds its
        best iterate, and says so in its description.
    """
    check_export_options(substeps, step_s, stop_time_s)
    model, params, origin = _resolve(source)
    if origin.get("fit_converged") == "false":
        warnings.warn(
            f"the fit did not converge ({origin['fit_status']}): the FMU holds its best "
            "iterate and its description says NOT CONVERGED; refit with more time "
            "(fit-physics --time-limit) for a converged model",
            FitWarning,
            stacklevel=2,
        )
    program = physics_program(
        model,
        params,
        drive,
        substeps,
        settings,
        name,
        step_s=step_s,
        stop_time_s=stop_time_s,
        origin=origin,
    )
    return build_fmu(program, path)
