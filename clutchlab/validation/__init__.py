"""Validation: split protocol, metrics, figures and reports (DESIGN §5)."""

from .demo import run_demo
from .metrics import pressure_metrics

__all__ = ["pressure_metrics", "run_demo"]
