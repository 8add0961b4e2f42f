"""Engineering units of parameters and signals, and their factor to SI.

Parameters are stored and reported in engineering units (mm, bar, N/mm, g, ms …);
the model equations work in SI. :data:`SI_FACTOR` converts one into the other.
"""

from __future__ import annotations

from ..errors import ModelError

__all__ = ["SI_FACTOR", "to_si", "unit_shown"]

#: Multiply a value in the key's unit by this factor to get SI.
SI_FACTOR: dict[str, float] = {
    "-": 1.0,
    "s": 1.0,
    "ms": 1e-3,
    "m": 1.0,
    "mm": 1e-3,
    "mm/s": 1e-3,
    "kg": 1.0,
    "g": 1e-3,
    "N": 1.0,
    "N/mm": 1e3,
    "N/A": 1.0,
    "N·s/m": 1.0,
    "A": 1.0,
    "mA": 1e-3,
    "Pa": 1.0,
    "bar": 1e5,
    "bar/s": 1e5,
    "bar/s²": 1e5,
    "GPa": 1e9,
    "kg/m³": 1.0,
    "cm³": 1e-6,
    "mm³/(s·bar)": 1e-9 / 1e5,
    "bar·s/cm³": 1e5 / 1e-6,
    "%": 1e-2,
    "1/mm²": 1e6,
    "1/K": 1.0,
    "°C": 1.0,
    "Hz": 1.0,
}


def to_si(value, unit: str):
    """Convert ``value`` given in ``unit`` to SI.

    Parameters
    ----------
    value : float or casadi.SX or numpy.ndarray
        Value in engineering unit ``unit``.
    unit : str
        A key of :data:`SI_FACTOR`.

    Returns
    -------
    Same type as ``value``, in SI units.
    """
    try:
        return value * SI_FACTOR[unit]
    except KeyError:
        raise ModelError(f"unknown unit {unit!r}; known: {', '.join(SI_FACTOR)}") from None


#: Units written otherwise where a person reads them (tables, listings): "N/A" (newton per
#: ampere) reads as "not applicable" in an engineering table. Files keep the unit as is.
_UNIT_SHOWN = {"N/A": "N·A⁻¹"}


def unit_shown(unit: str) -> str:
    """A parameter's unit as tables and listings write it (``"N/A"`` → ``"N·A⁻¹"``).

    Parameters
    ----------
    unit : str
        The unit as the model declares it (a key of :data:`SI_FACTOR`).

    Returns
    -------
    str
        The unit for a reader; files (fit JSON, metrics.json) keep ``unit``.
    """
    return _UNIT_SHOWN.get(unit, unit)
