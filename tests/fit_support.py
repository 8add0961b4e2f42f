"""A fit result made without fitting: what ``clutchlab fit-physics`` writes, at given values."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import FitResult


def synthetic_fit(
    changes: Mapping[str, float] | None = None,
    effects: Iterable[str] = (),
    train: Iterable[str] = (),
    status: str = "synthetic (tests)",
) -> FitResult:
    """A converged-looking FitResult whose values are the datasheet's with ``changes``
    (engineering units; the changed parameters count as the free ones), fitted on ``train``."""
    changes = dict(changes or {})
    model = CircuitModel().with_effects(*effects)
    params = model.params(**changes)
    return FitResult(
        effects=list(effects),
        values={n: float(params[n]) for n in params},
        units={p.name: p.unit for p in model.parameters},
        free=list(changes),
        std_errors={},
        correlation=[],
        singular_values=[],
        unidentifiable=[],
        weak_directions=[],
        per_experiment={},
        per_experiment_values={},
        cost_history=[],
        status=status,
        success=True,
        iterations=0,
        wall_s=0.0,
        train=list(train),
        settings={},
    )
