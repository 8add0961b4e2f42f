"""The outcome of a physics fit: values, uncertainty, identifiability, per-experiment errors."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ...errors import FitError
from ..effects import make_effect
from ..model import CircuitModel
from ..parameters import ParameterSet

__all__ = ["FitResult", "identifiability"]

#: A parameter whose relative standard error exceeds this is reported unidentifiable.
REL_SE_LIMIT = 0.5
#: Singular values (unit-norm columns) below this fraction of the largest mark
#: directions along which parameters trade off exactly (collinear sensitivities).
SV_RATIO_LIMIT = 1e-3


def identifiability(
    jz: np.ndarray, names: list[str], rel_se: np.ndarray
) -> tuple[list[float], list[str], list[dict]]:
    """SVD of the output sensitivities ``jz`` (residuals × scaled parameters), columns normalized.

    Returns the singular values, the names of unidentifiable parameters (large
    relative standard error, or dominating a direction whose singular value is
    below ``SV_RATIO_LIMIT`` of the largest) and, per weak direction, its loadings.
    """
    # Unit-norm columns: the SVD then measures collinearity; magnitude is judged by rel_se.
    norms = np.linalg.norm(jz, axis=0)
    _, sv, vt = np.linalg.svd(jz / np.where(norms > 0, norms, 1.0), full_matrices=False)
    weak = []
    bad = {n for n, r in zip(names, rel_se, strict=True) if not np.isfinite(r) or r > REL_SE_LIMIT}
    for s, v in zip(sv, vt, strict=True):
        if s < SV_RATIO_LIMIT * sv[0]:
            load = {n: float(c) for n, c in zip(names, v, strict=True) if abs(c) > 0.3}
            weak.append({"singular_value": float(s), "loadings": load})
            bad |= set(load)
    return [float(s) for s in sv], sorted(bad, key=names.index), weak


@dataclass
class FitResult:
    """What :class:`PhysicsFitter` found.

    Attributes
    ----------
    effects : list of str
        Effects switched on in the fitted model.
    values : dict
        Every parameter value (engineering units), fitted or fixed.
    units : dict
        Unit of every parameter.
    free : list of str
        Fitted parameters.
    std_errors : dict
        Standard error of each free parameter (its unit), from the Gauss–Newton
        Fisher information with the residual variance estimated from the fit.
    correlation : list of list
        Correlation matrix of the free parameters (order of ``free``).
    singular_values : list of float
        Of the output sensitivities to the scaled free parameters.
    unidentifiable : list of str
        Free parameters the data cannot determine.
    weak_directions : list of dict
        Near-null directions of the sensitivities with their parameter loadings.
    per_experiment : dict
        ``name -> {"rmse_bar", "fit_pct"}`` of the dither-period-mean pressure.
    per_experiment_values : dict
        ``name -> {param: value}`` for per-experiment parameters.
    cost_history : list of float
        ½‖r‖² at each new iterate.
    status : str
        Solver status.
    success : bool
        Converged (or acceptable).
    iterations : int
        Solver iterations of the best start.
    wall_s : float
        Wall time of the fit (s).
    train : list of str
        Experiments fitted on.
    settings : dict
        The fit settings used.
    """

    effects: list[str]
    values: dict[str, float]
    units: dict[str, str]
    free: list[str]
    std_errors: dict[str, float]
    correlation: list[list[float]]
    singular_values: list[float]
    unidentifiable: list[str]
    weak_directions: list[dict]
    per_experiment: dict[str, dict[str, float]]
    per_experiment_values: dict[str, dict[str, float]]
    cost_history: list[float]
    status: str
    success: bool
    iterations: int
    wall_s: float
    train: list[str]
    settings: dict = field(default_factory=dict)

    def model(self) -> CircuitModel:
        """The fitted model structure (base circuit + the effects)."""
        return CircuitModel().with_effects(*(make_effect(e) for e in self.effects))

    def params(self) -> ParameterSet:
        """The fitted values as a ParameterSet of :meth:`model`."""
        return self.model().params(**self.values)

    def table(self) -> str:
        """Free parameters with standard errors, as text."""
        lines = [f"{'parameter':18s} {'value':>12s} {'± std err':>12s}  unit"]
        for n in self.free:
            flag = "  (not identifiable)" if n in self.unidentifiable else ""
            lines.append(
                f"{n:18s} {self.values[n]:12.5g} {self.std_errors.get(n, math.nan):12.3g}  "
                f"{self.units[n]}{flag}"
            )
        return "\n".join(lines)

    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text (written to ``path`` when given, atomically)."""
        text = json.dumps(asdict(self), indent=2, ensure_ascii=False, allow_nan=True)
        if path is not None:
            path = Path(path)
            tmp = path.with_suffix(path.suffix + ".part")
            tmp.write_text(text + "\n", encoding="utf-8")
            tmp.replace(path)
        return text

    @classmethod
    def from_json(cls, source: str | Path) -> FitResult:
        """Read what :meth:`to_json` wrote (a path or the JSON text)."""
        text = str(source)
        if not text.lstrip().startswith("{"):
            try:
                text = Path(source).read_text(encoding="utf-8")
            except OSError as exc:
                raise FitError(f"cannot read fit result {source}: {exc}") from exc
        try:
            doc = json.loads(text)
            return cls(**doc)
        except (json.JSONDecodeError, TypeError) as exc:
            raise FitError(f"not a clutchlab fit result: {exc}") from exc
