"""Canonical signals of the data contract (DESIGN §3), as data.

Every trace stores its signals under these names, in these units. A channel map (to come)
renames and converts other names and units into them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

from ..errors import DataError

__all__ = [
    "CANONICAL_ORDER",
    "CURRENT_SIGNALS",
    "LINE_PRESSURE_BAR",
    "SIGNALS",
    "SignalSpec",
    "unit_of",
]


#: Nominal line (supply) pressure (bar, gauge; DESIGN §3): assumed where a trace does not log
#: ``line_pressure_bar``, and the reference of every default that needs a line pressure.
LINE_PRESSURE_BAR = 17.7


@dataclass(frozen=True)
class SignalSpec:
    """Specification of one canonical signal.

    Parameters
    ----------
    name : str
        Canonical column name, e.g. ``"clutch_pressure_bar"``.
    unit : str
        Engineering unit of the stored values (``"s"``, ``"mA"``, ``"Hz"``, ``"bar"``, ``"°C"``).
    required : bool
        True if every trace must carry the signal. ``current_mA`` and ``current_cmd_mA`` are
        each False: one of the two (:data:`CURRENT_SIGNALS`) is required.
    default : float or None
        Constant value, in ``unit``, assumed when the signal is absent (line pressure 17.7 bar,
        prime pressure 0.5 bar); None when there is no default.
    description : str
        One-line meaning of the signal.
    plausible_min, plausible_max : float
        Plausible range of values, in ``unit``. Values outside it usually mean a wrong unit
        (current logged in A instead of mA, pressure in Pa instead of bar).
    """

    name: str
    unit: str
    required: bool
    default: float | None
    description: str
    plausible_min: float
    plausible_max: float


_CURRENT_RANGE = (-300.0, 2000.0)  # mA
_PRESSURE_RANGE = (-1.0, 60.0)  # bar

_SPECS = (
    SignalSpec("time_s", "s", True, None, "strictly increasing sample time", -math.inf, math.inf),
    SignalSpec(
        "current_mA",
        "mA",
        False,
        None,
        "measured solenoid current, dither included (this or current_cmd_mA is required)",
        *_CURRENT_RANGE,
    ),
    SignalSpec(
        "current_cmd_mA",
        "mA",
        False,
        None,
        "nominal commanded solenoid current, no dither (this or current_mA is required)",
        *_CURRENT_RANGE,
    ),
    SignalSpec(
        "dither_amp_mA",
        "mA",
        False,
        None,
        "commanded dither amplitude (demodulated from current_mA if absent)",
        0.0,
        500.0,
    ),
    SignalSpec(
        "dither_freq_Hz",
        "Hz",
        False,
        None,
        "commanded dither frequency (demodulated from current_mA if absent)",
        0.0,
        500.0,
    ),
    SignalSpec(
        "clutch_pressure_bar",
        "bar",
        True,
        None,
        "measured clutch pressure, gauge",
        *_PRESSURE_RANGE,
    ),
    SignalSpec(
        "line_pressure_bar",
        "bar",
        False,
        LINE_PRESSURE_BAR,
        "measured line pressure",
        *_PRESSURE_RANGE,
    ),
    SignalSpec(
        "prime_pressure_bar",
        "bar",
        False,
        0.5,
        "measured prime / exhaust backfill pressure",
        *_PRESSURE_RANGE,
    ),
    SignalSpec("oil_temp_C", "°C", False, None, "oil temperature", -40.0, 180.0),
)

#: Canonical signals by name, in canonical column order (read-only mapping).
SIGNALS: MappingProxyType[str, SignalSpec] = MappingProxyType({s.name: s for s in _SPECS})

#: Canonical signal names in column order (files and DataFrames use this order).
CANONICAL_ORDER: tuple[str, ...] = tuple(SIGNALS)

#: The current signals of which every trace needs at least one.
CURRENT_SIGNALS: tuple[str, ...] = ("current_mA", "current_cmd_mA")


def unit_of(name: str) -> str:
    """Unit of a canonical signal.

    Parameters
    ----------
    name : str
        Canonical signal name, e.g. ``"current_mA"``.

    Returns
    -------
    str
        Engineering unit, e.g. ``"mA"``.

    Raises
    ------
    DataError
        If ``name`` is not a canonical signal.
    """
    try:
        return SIGNALS[name].unit
    except (KeyError, TypeError):
        raise DataError(
            f"unknown signal {name!r}; canonical signals: {', '.join(CANONICAL_ORDER)}"
        ) from None
