"""Engineering units of the logged channels and their conversion to the canonical units.

Units are data here: every unit a channel map or a file may declare is listed in
:data:`UNITS` with its dimension and its affine relation ``canonical = value·scale + offset``
to the canonical unit of that dimension (s, mA, bar, °C, Hz). Unit names are matched
case-insensitively after normalization (``"µ"``/``"μ"`` → ``"u"``, degree sign and a leading
``"deg"`` dropped), so ``"kPa"``, ``"KPA"``, ``"degF"``, ``"°F"`` and ``"F"`` are all accepted.

Pressures are gauge pressures: a log in absolute pressure needs ``offset = -1.01325`` (bar)
in its channel map entry.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ..errors import DataError

__all__ = [
    "CANONICAL_UNITS",
    "UNITS",
    "Unit",
    "convert_units",
    "dimension_of",
    "parse_unit",
    "split_header_unit",
]


@dataclass(frozen=True)
class Unit:
    """One engineering unit and how to convert it to the canonical unit of its dimension.

    Parameters
    ----------
    symbol : str
        Display symbol, e.g. ``"kPa"``.
    dimension : str
        ``"time"``, ``"current"``, ``"pressure"``, ``"temperature"`` or ``"frequency"``.
    scale, offset : float
        ``canonical = value * scale + offset`` (canonical units: s, mA, bar, °C, Hz).
    """

    symbol: str
    dimension: str
    scale: float
    offset: float = 0.0


_PSI_BAR = 0.0689475729317831  # 1 psi in bar (NIST: 6894.757 Pa)

_UNIT_LIST = (
    Unit("s", "time", 1.0),
    Unit("ms", "time", 1e-3),
    Unit("us", "time", 1e-6),
    Unit("ns", "time", 1e-9),
    Unit("min", "time", 60.0),
    Unit("A", "current", 1e3),
    Unit("mA", "current", 1.0),
    Unit("uA", "current", 1e-3),
    Unit("bar", "pressure", 1.0),
    Unit("mbar", "pressure", 1e-3),
    Unit("Pa", "pressure", 1e-5),
    Unit("hPa", "pressure", 1e-3),
    Unit("kPa", "pressure", 1e-2),
    Unit("MPa", "pressure", 10.0),
    Unit("psi", "pressure", _PSI_BAR),
    Unit("°C", "temperature", 1.0),
    Unit("°F", "temperature", 5.0 / 9.0, -32.0 * 5.0 / 9.0),
    Unit("K", "temperature", 1.0, -273.15),
    Unit("Hz", "frequency", 1.0),
    Unit("kHz", "frequency", 1e3),
)

#: Canonical unit symbol of each dimension.
CANONICAL_UNITS: MappingProxyType[str, str] = MappingProxyType(
    {"time": "s", "current": "mA", "pressure": "bar", "temperature": "°C", "frequency": "Hz"}
)

_ALIASES = {
    "sec": "s",
    "second": "s",
    "seconds": "s",
    "msec": "ms",
    "usec": "us",
    "amp": "A",
    "amps": "A",
    "psig": "psi",
    "c": "°C",
    "celsius": "°C",
    "f": "°F",
    "fahrenheit": "°F",
    "kelvin": "K",
    "1/s": "Hz",
}

#: Accepted units by normalized name (see :func:`parse_unit`).
UNITS: MappingProxyType[str, Unit] = MappingProxyType(
    {
        **{u.symbol.lower().replace("°", ""): u for u in _UNIT_LIST},
        **{
            alias: next(u for u in _UNIT_LIST if u.symbol == sym) for alias, sym in _ALIASES.items()
        },
    }
)


def _normalize(text: str) -> str:
    key = text.strip().replace("µ", "u").replace("μ", "u").replace("°", "").replace(" ", "")
    key = key.lower()
    if key.startswith("deg") and len(key) > 3:
        key = key[3:]
    return key


def parse_unit(text: str) -> Unit:
    """The :class:`Unit` named by ``text``.

    Parameters
    ----------
    text : str
        Unit name as written in a file or channel map, e.g. ``"kPa"``, ``"degF"``, ``"µs"``.

    Returns
    -------
    Unit

    Raises
    ------
    DataError
        If the unit is not known; the message lists the known units.
    """
    unit = UNITS.get(_normalize(text)) if isinstance(text, str) else None
    if unit is None:
        known = ", ".join(u.symbol for u in _UNIT_LIST)
        raise DataError(f"unknown unit {text!r}; known units: {known}")
    return unit


def dimension_of(canonical_unit: str) -> str:
    """Dimension of a canonical unit (``"mA"`` → ``"current"``).

    Parameters
    ----------
    canonical_unit : str
        One of the canonical units s, mA, bar, °C, Hz.

    Returns
    -------
    str
    """
    return parse_unit(canonical_unit).dimension


def convert_units(values: np.ndarray, unit: str, to: str) -> np.ndarray:
    """Convert values from ``unit`` to the unit ``to`` of the same dimension.

    Parameters
    ----------
    values : numpy.ndarray
        Values in ``unit``.
    unit : str
        Unit of ``values`` (any name accepted by :func:`parse_unit`).
    to : str
        Target unit, e.g. the canonical unit of a signal (``"mA"``).

    Returns
    -------
    numpy.ndarray
        float64 values in ``to``. Overflow gives ±inf (reported by validation), not an error.

    Raises
    ------
    DataError
        If either unit is unknown or the dimensions differ (``"bar"`` to ``"mA"``).
    """
    src, dst = parse_unit(unit), parse_unit(to)
    if src.dimension != dst.dimension:
        raise DataError(
            f"unit {unit!r} is a {src.dimension} unit; {to!r} needs a {dst.dimension} unit"
        )
    x = np.asarray(values, dtype=np.float64)
    if src == dst:
        return x
    with np.errstate(over="ignore", invalid="ignore"):
        canonical = x * src.scale + src.offset
        return (canonical - dst.offset) / dst.scale


#: ``name [unit]`` column header.
_UNIT_HEADER = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\[\]]*)\]$")
#: ``name (unit)`` column header (a unit only if :func:`parse_unit` knows it).
_PAREN_UNIT_HEADER = re.compile(r"^(?P<name>.*?)\s*\((?P<unit>[^()]*)\)$")


def split_header_unit(
    header: str, wanted: Callable[[str], bool] | None = None
) -> tuple[str, str | None]:
    """Column name and unit of a column header: ``"P_CL [kPa]"`` or ``"P_CL (kPa)"`` →
    ``("P_CL", "kPa")``.

    Used for CSV headers and Parquet column names alike (a spreadsheet's or a logger's
    export carries the unit in the name). An array index (``"P[0]"``) stays in the name,
    as does text in parentheses that is not a known unit (``"P(clutch)"``,
    ``"pressure (gauge)"``). A header in parentheses that a channel map names whole
    (``wanted(header)``, a map written for the header as it stands) keeps its name whole,
    and its unit is still the file's: a map that gives another unit for it is refused as
    for ``name [unit]``, not applied to values logged in the header's unit
    (``"P_clutch (bar)"`` read as kPa would be 100 × off).

    Parameters
    ----------
    header : str
        The column's name as the file holds it.
    wanted : callable, optional
        ``wanted(name)``: whether a channel map names this column (see above).

    Returns
    -------
    tuple of (str, str or None)
        The name, and the unit text (None when the header carries none).
    """
    match = _UNIT_HEADER.match(header)
    if match and match["name"] and not match["unit"].strip().isdigit():
        return match["name"], match["unit"].strip() or None
    match = _PAREN_UNIT_HEADER.match(header)
    if match and match["name"]:
        try:
            parse_unit(match["unit"])
        except DataError:
            return header, None
        named_whole = wanted is not None and wanted(header)
        return (header if named_whole else match["name"]), match["unit"].strip()
    return header, None
