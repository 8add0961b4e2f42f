"""Export a fitted physics model as an FMU."""

from __future__ import annotations

import json
from pathlib import Path

from ...errors import ClutchlabError, FitError, FitResultError
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..settings import SimulationSettings
from .build import build_fmu
from .errors import FmuError
from .physics import check_export_options, physics_program

__all__ = ["export_physics_fmu", "physics_source"]


def physics_source(source) -> tuple[CircuitModel, ParameterSet]:
    """The model and parameter values of a fitted physics model.

    Parameters
    ----------
    source : path-like, FitResult, PhysicsFitter or (CircuitModel, ParameterSet)
        A fit JSON written by ``clutchlab fit-physics`` / ``PhysicsFitter.save``, a fit
        result, a fitted fitter, or a model with its parameters.

    Raises
    ------
    FmuError
        When ``source`` is none of these (a JSON that is not a fit result is named).
    """
    from ..fit import FitResult, PhysicsFitter

    if isinstance(source, tuple) and len(source) == 2:
        model, params = source
        if isinstance(model, CircuitModel) and isinstance(params, ParameterSet):
            return model, params
    if isinstance(source, PhysicsFitter):
        if not hasattr(source, "result_"):
            raise FmuError("the PhysicsFitter is not fitted; fit it or load a fit JSON first")
        return source.model_, source.params_
    if isinstance(source, FitResult):
        return source.model(), source.params()
    if isinstance(source, str | Path):
        try:  # the content is checked as it is read (FitResult.from_json)
            result = FitResult.from_json(Path(source))
        except FitResultError as exc:  # every problem of the content, one per line
            problems = exc.problems or [str(exc)]
            if _is_parameter_file(Path(source)):
                problems = [*problems, _PARAMETER_FILE_HINT]
            raise FmuError(f"{source}: not a fitted physics model", problems) from exc
        except FitError as exc:
            raise FmuError(f"{source}: not a fitted physics model ({exc})") from exc
        try:
            return result.model(), result.params()
        except ClutchlabError as exc:  # not expected after the check; named if it happens
            raise FmuError(f"{source}: the fitted model cannot be rebuilt: {exc}") from exc
    raise FmuError(
        f"cannot export {type(source).__name__}: expected a fit JSON path, FitResult, "
        "fitted PhysicsFitter or (CircuitModel, ParameterSet)"
    )


#: What to do with a parameter file (:meth:`ParameterSet.to_json`): before any fit, a design
#: is exported from Python; the file holds values, not the model (its effects) they are for.
_PARAMETER_FILE_HINT = (
    "this is a parameter file (ParameterSet.to_json): it holds values, not the model they "
    "are for; to export a design before any fit, from Python: model = CircuitModel()"
    ".with_effects(...); params = ParameterSet.from_json(model.parameters, FILE); "
    "export_physics_fmu((model, params), OUT) (clutchlab.physics.fmu)"
)


def _is_parameter_file(path: Path) -> bool:
    """Whether ``path`` is a JSON object whose only key is ``parameters``."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(doc, dict) and set(doc) == {"parameters"}


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
        The FMU written.

    Raises
    ------
    FmuError
        ``source`` is not a fitted model, or ``substeps`` / ``step_s`` / ``stop_time_s``
        are out of range (checked first, before the model is read or anything compiled).
    """
    check_export_options(substeps, step_s, stop_time_s)
    model, params = physics_source(source)
    program = physics_program(
        model, params, drive, substeps, settings, name, step_s=step_s, stop_time_s=stop_time_s
    )
    return build_fmu(program, path)
