"""Error metrics of the validation protocol (DESIGN §5 names).

The pressure metrics live in the data layer so that the physics fit reports the same
numbers; they are re-exported here, where the protocol uses them.
"""

from ..data.metrics import pressure_metrics

__all__ = ["pressure_metrics"]
