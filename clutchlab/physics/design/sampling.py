"""Design points of a sweep: full-factorial grid or Latin hypercube, each with a stable id."""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass

import numpy as np

from .spec import SweepSpec, Variable

__all__ = ["DesignPoint", "design_points", "point_id"]


@dataclass(frozen=True)
class DesignPoint:
    """One point of the design.

    Attributes
    ----------
    index : int
        Position in the design (0-based).
    point_id : str
        Hash of the spec core and the design vector (see :func:`point_id`).
    values : dict of str to float
        Design-variable values, each in its variable's unit.
    """

    index: int
    point_id: str
    values: dict[str, float]


def point_id(core_hash: str, values: dict[str, float]) -> str:
    """Stable id of a design point: SHA-256 of the spec core hash and the exact values.

    Values are hashed by their exact binary representation (``float.hex``), so the id is the
    same on every machine and the same for a point that reappears in an extended design.

    Parameters
    ----------
    core_hash : str
        :attr:`SweepSpec.core_hash`.
    values : dict of str to float
        Design vector (variable units).

    Returns
    -------
    str
        16 hex characters.
    """
    vec = {k: float(v).hex() for k, v in sorted(values.items())}
    text = json.dumps({"core": core_hash, "x": vec}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _from_unit(var: Variable, u: np.ndarray) -> np.ndarray:
    """Map ``u`` in [0, 1] onto the variable's range (linear or log spacing)."""
    if var.scale == "log":
        return np.exp(np.log(var.low) + u * (np.log(var.high) - np.log(var.low)))
    return var.low + u * (var.high - var.low)


def _grid_levels(var: Variable) -> np.ndarray:
    if var.values:
        return np.array(var.values, dtype=float)
    levels = _from_unit(var, np.linspace(0.0, 1.0, var.levels))
    levels[0], levels[-1] = var.low, var.high  # exact ends, no exp/log round-off
    return levels


def design_points(spec: SweepSpec) -> list[DesignPoint]:
    """All design points of ``spec``, in a reproducible order.

    ``grid``: the full factorial product of each variable's levels (last variable fastest).
    ``lhs``: ``n`` points of a Latin hypercube (SciPy ``qmc.LatinHypercube`` on
    ``numpy.random.default_rng(seed)``) mapped onto each variable's range, linear or log.
    Duplicate design vectors (a grid with repeated values) are kept once.

    Returns
    -------
    list of DesignPoint
    """
    names = spec.variable_names
    if spec.sampling.method == "grid":
        rows = list(itertools.product(*(_grid_levels(v) for v in spec.variables)))
        matrix = np.array(rows, dtype=float).reshape(len(rows), len(names))
    else:
        from scipy.stats import qmc

        rng = np.random.default_rng(spec.sampling.seed)
        try:
            sampler = qmc.LatinHypercube(d=len(names), rng=rng)
        except TypeError:  # SciPy < 1.15 names it seed (same stream for a Generator)
            sampler = qmc.LatinHypercube(d=len(names), seed=rng)
        unit = sampler.random(spec.sampling.n)
        matrix = np.column_stack([_from_unit(v, unit[:, k]) for k, v in enumerate(spec.variables)])
    core = spec.core_hash
    points, seen = [], set()
    for row in matrix:
        values = {n: float(x) for n, x in zip(names, row, strict=True)}
        pid = point_id(core, values)
        if pid in seen:
            continue
        seen.add(pid)
        points.append(DesignPoint(len(points), pid, values))
    return points
