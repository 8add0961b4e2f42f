"""FMI unit definitions of clutchlab's engineering units, and conversions through SI.

An FMI 2.0 ``<Unit>`` has a name and an optional ``<BaseUnit>``: exponents of the SI base
units and ``value_SI = factor · value + offset``. clutchlab's units (``mA``, ``bar``, ``°C``,
``cm³`` …) get ASCII names in the FMU (``degC``, ``cm3``) so that every tool can read them;
the base-unit definition lets an importer convert between any two units of one quantity.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FMI_UNITS", "FmiUnit", "convertible", "fmi_unit", "from_si", "lookup", "to_si"]


@dataclass(frozen=True)
class FmiUnit:
    """One FMI unit: its name in the FMU and its relation to SI.

    Attributes
    ----------
    name : str
        ASCII name written into ``modelDescription.xml``.
    exponents : dict
        Exponents of the SI base units (``kg``, ``m``, ``s``, ``A``, ``K``, ``mol``, ``cd``,
        ``rad``).
    factor : float
        ``value_SI = factor · value + offset``.
    offset : float
        See ``factor`` (273.15 for °C).
    """

    name: str
    exponents: tuple[tuple[str, int], ...] = ()
    factor: float = 1.0
    offset: float = 0.0


def _u(name: str, factor: float = 1.0, offset: float = 0.0, **exp: int) -> FmiUnit:
    return FmiUnit(name, tuple(sorted(exp.items())), factor, offset)


#: clutchlab unit string → FMI unit. ``"-"`` (dimensionless) has none.
FMI_UNITS: dict[str, FmiUnit] = {
    "s": _u("s", s=1),
    "ms": _u("ms", 1e-3, s=1),
    "m": _u("m", m=1),
    "mm": _u("mm", 1e-3, m=1),
    "mm/s": _u("mm/s", 1e-3, m=1, s=-1),
    "kg": _u("kg", kg=1),
    "g": _u("g", 1e-3, kg=1),
    "N": _u("N", kg=1, m=1, s=-2),
    "N/mm": _u("N/mm", 1e3, kg=1, s=-2),
    "N/A": _u("N/A", kg=1, m=1, s=-2, A=-1),
    "N·s/m": _u("N.s/m", kg=1, s=-1),
    "A": _u("A", A=1),
    "mA": _u("mA", 1e-3, A=1),
    "mA/s": _u("mA/s", 1e-3, A=1, s=-1),
    "Pa": _u("Pa", kg=1, m=-1, s=-2),
    "bar": _u("bar", 1e5, kg=1, m=-1, s=-2),
    "bar/s": _u("bar/s", 1e5, kg=1, m=-1, s=-3),
    "bar/s²": _u("bar/s2", 1e5, kg=1, m=-1, s=-4),
    "GPa": _u("GPa", 1e9, kg=1, m=-1, s=-2),
    "kg/m³": _u("kg/m3", kg=1, m=-3),
    "cm³": _u("cm3", 1e-6, m=3),
    "mm³/(s·bar)": _u("mm3/(s.bar)", 1e-9 / 1e5, kg=-1, m=4, s=1),
    "bar·s/cm³": _u("bar.s/cm3", 1e5 / 1e-6, kg=1, m=-4, s=-1),
    "%": _u("%", 1e-2),
    "1/mm²": _u("1/mm2", 1e6, m=-2),
    "1/K": _u("1/K", K=-1),
    "K": _u("K", K=1),
    "°C": _u("degC", 1.0, 273.15, K=1),
    "Hz": _u("Hz", s=-1),
}

_BY_FMI_NAME = {u.name: u for u in FMI_UNITS.values()}
_ALIASES = {"°C": "degC", "deg C": "degC", "C": "degC", "1/s": "Hz"}


def fmi_unit(unit: str) -> FmiUnit | None:
    """The FMI unit of a clutchlab unit string, or ``None`` for ``"-"`` / ``""``.

    Raises
    ------
    KeyError
        For a unit clutchlab does not know.
    """
    if unit in ("-", ""):
        return None
    return FMI_UNITS[unit]


def lookup(name: str | None, declared: dict[str, FmiUnit] | None = None) -> FmiUnit | None:
    """An FMI unit by its FMU name: the FMU's own definition first, then clutchlab's table."""
    if name is None or name in ("", "-", "1"):
        return None
    if declared and name in declared and declared[name].exponents:
        return declared[name]
    name = _ALIASES.get(name, name)
    if name in _BY_FMI_NAME:
        return _BY_FMI_NAME[name]
    return FMI_UNITS.get(name) or (declared or {}).get(name)


def convertible(a: FmiUnit | None, b: FmiUnit | None) -> bool:
    """Whether values in ``a`` can be converted to ``b`` (same SI dimension)."""
    if a is None or b is None:
        return a is b or a == b
    return dict(a.exponents) == dict(b.exponents)


def to_si(value, unit: FmiUnit | None):
    """``value`` (in ``unit``) in SI; unchanged for a dimensionless unit."""
    return value if unit is None else value * unit.factor + unit.offset


def from_si(value, unit: FmiUnit | None):
    """``value`` (SI) in ``unit``; unchanged for a dimensionless unit."""
    return value if unit is None else (value - unit.offset) / unit.factor
