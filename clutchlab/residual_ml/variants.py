"""Named model variants of the validation protocol (DESIGN §5) implemented here."""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType

from ..errors import ModelError
from .base import TraceEstimator
from .estimators import GPBaseline, GPWithDerivative, SVCPartitionedGP
from .hybrid import HybridModel

__all__ = ["VARIANTS", "make_variant"]

#: Variant name → estimator class (``gp_base``, ``gp_didt``, ``paper_svc_gp``, ``hybrid``).
VARIANTS: MappingProxyType[str, Callable[..., TraceEstimator]] = MappingProxyType(
    {
        "gp_base": GPBaseline,
        "gp_didt": GPWithDerivative,
        "paper_svc_gp": SVCPartitionedGP,
        "hybrid": HybridModel,
    }
)


def make_variant(name: str, **params) -> TraceEstimator:
    """A fresh (unfitted) estimator of variant ``name``.

    Parameters
    ----------
    name : str
        One of :data:`VARIANTS`.
    **params
        Estimator parameters (e.g. ``kernel="rbf"``; ``physics=...`` for ``hybrid``).

    Returns
    -------
    TraceEstimator

    Raises
    ------
    ModelError
        If the name is unknown or a parameter is not one of the estimator's.
    """
    try:
        cls = VARIANTS[name]
    except KeyError:
        raise ModelError(f"unknown variant {name!r}; known: {', '.join(VARIANTS)}") from None
    try:
        return cls(**params)
    except TypeError as exc:
        raise ModelError(f"variant {name!r}: {exc}") from None
