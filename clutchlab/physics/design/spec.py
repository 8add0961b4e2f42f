"""The sweep specification: model, scenario, design variables, sampling — read from TOML.

A spec is validated as a whole: every problem (unknown parameter, range outside the
parameter's bounds, unknown ramp, misspelt key, …) is collected and raised in one
:class:`SpecError`.
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

from ...data import LINE_PRESSURE_BAR
from ...errors import ModelError
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..stand.scenarios import RAMPS, RampProfile
from .metrics import MetricSettings

__all__ = [
    "SCENARIO_VARIABLES",
    "ModelSpec",
    "SamplingSpec",
    "ScenarioSpec",
    "SimulationSpec",
    "SpecError",
    "StepSpec",
    "SweepSpec",
    "Variable",
    "load_spec",
]

#: Design variables that are not model parameters: name → (unit, lower, upper, description).
SCENARIO_VARIABLES: dict[str, tuple[str, float, float, str]] = {
    "dither_amp_scale": ("-", 0.0, 2.25, "factor on the dither amplitude shape (≤ 225 mA)"),
    "dither_freq_Hz": ("Hz", 10.0, 250.0, "dither frequency"),
}

WAVEFORMS = ("sine", "triangle", "square")

#: Largest dither amplitude of the stand and the source paper (mA).
MAX_DITHER_MA = 225.0


class SpecError(ModelError):
    """A sweep spec with problems; the message lists every one.

    Parameters
    ----------
    problems : list of str
        Each problem, naming the table and key.
    source : str
        The spec file (or ``"spec"``).
    """

    def __init__(self, problems: list[str], source: str = "spec") -> None:
        self.problems = list(problems)
        super().__init__(f"{source}: invalid sweep spec:\n  - " + "\n  - ".join(self.problems))


@dataclass(frozen=True)
class ModelSpec:
    """Which model, and the parameter values that stay fixed over the sweep.

    Attributes
    ----------
    effects : tuple of str
        Library effects switched on.
    baseline : {"default", "stand"}
        Starting values: the datasheet defaults or the synthetic stand's as-built values.
    parameters : dict of str to float
        Fixed values replacing the baseline (each in its parameter's unit).
    """

    effects: tuple[str, ...] = ()
    baseline: Literal["default", "stand"] = "default"
    parameters: dict[str, float] = field(default_factory=dict)

    def build(self) -> CircuitModel:
        """The frozen model with the effects switched on."""
        return _model(tuple(self.effects))

    def base_params(self, model: CircuitModel) -> ParameterSet:
        """Baseline values with the fixed overrides applied."""
        values: dict[str, float] = {}
        if self.baseline == "stand":
            from ..stand import as_built_values

            names = {p.name for p in model.parameters}
            values = {k: v for k, v in as_built_values().items() if k in names}
        return model.params(**(values | dict(self.parameters)))


@dataclass(frozen=True)
class StepSpec:
    """Current step of the response-time scenario.

    Attributes
    ----------
    from_mA, to_mA : float
        Nominal current before and after the step (mA).
    hold_s : float
        Time at ``from_mA`` before the step (s).
    duration_s : float
        Time at ``to_mA`` after the step (s).
    """

    from_mA: float = 300.0
    to_mA: float = 700.0
    hold_s: float = 0.3
    duration_s: float = 0.5

    def problems(self) -> list[str]:
        """What is wrong with this step (empty when nothing is), each naming its key."""
        out = []
        values = (self.from_mA, self.to_mA, self.hold_s, self.duration_s)
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
            return [f"[scenario.step] needs finite numbers, got {values}"]
        if not (0 <= self.from_mA <= 1100 and 0 <= self.to_mA <= 1100):
            out.append("[scenario.step] from_mA and to_mA must be in 0–1100 mA")
        if self.from_mA == self.to_mA or self.hold_s <= 0 or self.duration_s <= 0:
            out.append("[scenario.step] needs from_mA ≠ to_mA, hold_s > 0, duration_s > 0")
        return out

    def __post_init__(self) -> None:
        if problems := self.problems():
            raise SpecError(problems, "StepSpec")


@dataclass(frozen=True)
class ScenarioSpec:
    """The excitation of every design point: stand ramps, a dither setting, a current step.

    Attributes
    ----------
    ramps : tuple of RampProfile
        Ramp profiles (the stand's ``fast`` / ``medium`` / ``slow`` or custom ones).
    dither_freq_Hz : float
        Dither frequency (Hz) unless the design variable ``dither_freq_Hz`` sets it.
    dither_shape : str
        Dither amplitude shape (a key of ``DITHER_SHAPES``).
    dither_waveform : {"sine", "triangle", "square"}
        Dither waveform.
    step : StepSpec or None
        Current step for the response time; None: no step scenario.
    line_pressure_bar, prime_pressure_bar : float
        Constant supply and exhaust back-fill pressure (bar).
    oil_temp_C : float
        Constant oil temperature (°C).
    """

    ramps: tuple[RampProfile, ...] = (RAMPS["fast"],)
    dither_freq_Hz: float = 50.0
    dither_shape: str = "B"
    dither_waveform: str = "sine"
    step: StepSpec | None = field(default_factory=StepSpec)
    line_pressure_bar: float = LINE_PRESSURE_BAR
    prime_pressure_bar: float = 0.5
    oil_temp_C: float = 40.0


@dataclass(frozen=True)
class SimulationSpec:
    """Simulator settings of every design point.

    Attributes
    ----------
    substeps : int
        ROS2 steps per sample.
    sample_rate_Hz : float
        Output grid (Hz).
    settle_s : float
        Settling run at the first inputs before each trace (s).
    """

    substeps: int = 4
    sample_rate_Hz: float = 1000.0
    settle_s: float = 0.5


@dataclass(frozen=True)
class Variable:
    """One design variable: a model parameter or a scenario variable, with its range.

    Attributes
    ----------
    name : str
        Model parameter name (``clutchlab params``) or a key of :data:`SCENARIO_VARIABLES`.
    low, high : float
        Range, in the variable's unit.
    scale : {"linear", "log"}
        Spacing of grid levels and of the Latin-hypercube strata.
    levels : int
        Grid levels (grid sampling only).
    values : tuple of float
        Explicit grid values (grid sampling; replaces ``levels``).
    unit : str
        Unit (filled in from the parameter).
    """

    name: str
    low: float
    high: float
    scale: Literal["linear", "log"] = "linear"
    levels: int = 3
    values: tuple[float, ...] = ()
    unit: str = ""


@dataclass(frozen=True)
class SamplingSpec:
    """How design points are drawn.

    Attributes
    ----------
    method : {"lhs", "grid"}
        Latin hypercube (``n`` points, ``seed``) or full factorial grid.
    n : int
        Number of points (lhs).
    seed : int
        Seed of the Latin hypercube.
    """

    method: Literal["lhs", "grid"] = "lhs"
    n: int = 0
    seed: int = 0


@dataclass(frozen=True)
class SweepSpec:
    """A complete design study.

    Attributes
    ----------
    model, scenario, simulation, metrics, sampling
        The parts, see their classes.
    variables : tuple of Variable
        Design variables.
    name : str
        Label of the study.
    source : str
        Where the spec came from (for messages).
    """

    model: ModelSpec
    scenario: ScenarioSpec
    simulation: SimulationSpec
    metrics: MetricSettings
    sampling: SamplingSpec
    variables: tuple[Variable, ...]
    name: str = "sweep"
    source: str = "spec"

    def core(self) -> dict[str, Any]:
        """Everything a point's result depends on besides its design vector (plain JSON)."""
        return {
            "model": asdict(self.model) | {"effects": list(self.model.effects)},
            "scenario": asdict(self.scenario),
            "simulation": asdict(self.simulation),
            "metrics": asdict(self.metrics),
        }

    @property
    def core_hash(self) -> str:
        """Hash (16 hex) of :meth:`core`: equal for specs that give equal point results."""
        text = json.dumps(self.core(), sort_keys=True, default=list)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @property
    def variable_names(self) -> tuple[str, ...]:
        """Names of the design variables, in spec order."""
        return tuple(v.name for v in self.variables)

    @classmethod
    def from_dict(cls, doc: dict[str, Any], source: str = "spec") -> SweepSpec:
        """Build and validate a spec from a parsed TOML document.

        Raises
        ------
        SpecError
            Listing every problem found.
        """
        from .spec_parse import parse_spec

        return parse_spec(doc, source)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec (TOML).

    Parameters
    ----------
    path : path
        The spec file.

    Returns
    -------
    SweepSpec

    Raises
    ------
    SpecError
        For a missing, unreadable or non-UTF-8 file, invalid TOML, or any invalid entry
        (all problems listed).
    """
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a BOM of Windows editors
    except FileNotFoundError:
        raise SpecError([f"file not found: {path}"], str(path)) from None
    except IsADirectoryError:
        raise SpecError([f"{path} is a folder; give the spec file (TOML)"], str(path)) from None
    except UnicodeDecodeError as exc:
        raise SpecError(
            [f"not a text file in UTF-8 (byte {exc.start}: {exc.reason}); a spec is TOML"],
            str(path),
        ) from None
    except OSError as exc:
        raise SpecError([f"cannot read: {exc.strerror or exc}"], str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise SpecError([f"not valid TOML: {exc}"], str(path)) from None
    from .spec_parse import parse_spec

    return parse_spec(doc, str(path))


@lru_cache(maxsize=16)
def _model(effects: tuple[str, ...]) -> CircuitModel:
    """The model with ``effects`` on (built once per process: parsing specs stays cheap)."""
    return CircuitModel().with_effects(*effects)
