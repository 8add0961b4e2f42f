"""Named model variants of the validation protocol (DESIGN §5) implemented here."""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType

from ..errors import ModelError
from .base import TraceEstimator
from .estimators import GPBaseline, GPWithDerivative, SVCPartitionedGP
from .features import DIDT_FEATURES
from .hybrid import HybridModel

__all__ = ["PAPER_FAITHFUL", "VARIANTS", "make_variant", "paper_faithful"]

#: Settings of the paper's stage 3 as published, beside clutchlab's defaults: the nominal
#: current (no lag), the rational-quadratic kernel, the RBF-SVC classifier, the latched GP
#: on the pressure itself (no line-pressure reference) and the GPs' own predictive std (no
#: latch-timing mixture, rate bridge or per-frequency noise floor).
PAPER_FAITHFUL: MappingProxyType[str, object] = MappingProxyType(
    {
        "features": DIDT_FEATURES,
        "lag_s": 0.0,
        "kernel": "rq",
        "latch_model": "classifier",
        "latched_reference": "none",
        "latch_uncertainty": "none",
        "rate_uncertainty": "none",
        "noise_model": "constant",
    }
)


def paper_faithful(**params) -> SVCPartitionedGP:
    """``SVCPartitionedGP`` with :data:`PAPER_FAITHFUL` (``params`` override them)."""
    return SVCPartitionedGP(**{**PAPER_FAITHFUL, **params})


#: Variant name → estimator factory (``gp_base``, ``gp_didt``, ``paper_svc_gp``, ``hybrid``,
#: and ``paper_faithful``, the paper's stage 3 as published).
VARIANTS: MappingProxyType[str, Callable[..., TraceEstimator]] = MappingProxyType(
    {
        "gp_base": GPBaseline,
        "gp_didt": GPWithDerivative,
        "paper_svc_gp": SVCPartitionedGP,
        "hybrid": HybridModel,
        "paper_faithful": paper_faithful,
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
