"""Channel maps: which source channel of a log holds which canonical signal, in which unit.

A channel map is a TOML file (read with :mod:`tomllib`)::

    description = "Stand B logger, CSV export"

    [signals]                       # canonical signal = source channel (+ unit)
    time_s = { channel = "Time", unit = "ms" }
    current_mA = { channel = "I_VFS", unit = "A" }
    current_cmd_mA = "I_cmd"        # short form: the source is already in the canonical unit
    clutch_pressure_bar = { channel = "P_clutch", unit = "kPa" }
    line_pressure_bar = { channel = "P_line_abs", unit = "bar", offset = -1.01325 }
    oil_temp_C = { channel = "T_oil", unit = "degF" }

    [defaults]                      # constants for optional signals a log does not have
    prime_pressure_bar = 0.5
    dither_freq_Hz = 50.0

Entry fields: ``channel`` (source name, required), ``unit`` (source unit; when omitted, the
unit stored in the file — MF4 channel unit, Parquet field metadata, ``name [unit]`` or
``name (unit)`` CSV header — or else the canonical unit), ``scale`` and ``offset`` (applied
after the unit conversion, offset in the canonical unit:
``canonical = convert_units(raw, unit, canonical_unit) * scale + offset``) and, for MF4 files
whose channel name occurs in several groups, ``group`` (0-based group index).

Signals a map does not mention are looked up under their canonical name, but a source channel
the map assigns to one signal is never also taken that way for another (``current_cmd_mA =
"current_mA"`` leaves ``current_mA`` absent, with a note). Source channels the map does not
use are ignored (a log without a map must have canonical names only).
"""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ..errors import DataError
from .paths import check_input_file
from .signals import CANONICAL_ORDER, CURRENT_SIGNALS, SIGNALS
from .units import parse_unit

__all__ = ["ChannelMap", "ChannelMapLike", "ChannelSpec", "load_channel_map"]

#: Signals that may not get a constant default (a constant time or current makes no sense).
_NO_DEFAULT = ("time_s", "clutch_pressure_bar", *CURRENT_SIGNALS)
_ENTRY_FIELDS = ("channel", "unit", "scale", "offset", "group", "source")
_TOP_KEYS = ("description", "signals", "defaults")


@dataclass(frozen=True)
class ChannelSpec:
    """Where one canonical signal comes from.

    Parameters
    ----------
    channel : str
        Source channel (column) name in the log.
    unit : str or None
        Unit of the source values; None means the unit stored in the file, or else the
        canonical unit of the signal.
    scale : float
        Factor applied after the unit conversion (dimensionless).
    offset : float
        Added after scaling, in the canonical unit of the signal (e.g. -1.01325 bar to turn
        absolute into gauge pressure).
    group : int or None
        MF4 channel group (0-based) when the channel name occurs in several groups.
    source : str or None
        MF4 source or device the channel was logged from, as the measurement tool wrote it
        (the channel group's acquisition name, or a source name or path), when the channel
        name occurs under several sources.
    """

    channel: str
    unit: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    group: int | None = None
    source: str | None = None


def _close(name: str, known: tuple[str, ...] | list[str]) -> str:
    match = difflib.get_close_matches(str(name), list(known), n=1, cutoff=0.6)
    return f" (did you mean {match[0]!r}?)" if match else ""


@dataclass(frozen=True)
class ChannelMap:
    """Source channel → canonical signal, with units and defaults (see module docstring).

    Parameters
    ----------
    signals : mapping of str to ChannelSpec
        Canonical signal name to its source.
    defaults : mapping of str to float
        Canonical signal name to a constant, in the signal's canonical unit, used when the
        log does not have the signal.
    description : str
        Free text.
    source : pathlib.Path or None
        TOML file the map was read from (for messages).
    """

    signals: Mapping[str, ChannelSpec] = field(default_factory=dict)
    defaults: Mapping[str, float] = field(default_factory=dict)
    description: str = ""
    source: Path | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "signals", MappingProxyType(dict(self.signals)))
        object.__setattr__(self, "defaults", MappingProxyType(dict(self.defaults)))

    @property
    def label(self) -> str:
        """How messages name the map: its file, or ``"channel map"``."""
        return str(self.source) if self.source is not None else "channel map"

    def spec(self, signal: str) -> ChannelSpec:
        """Source of canonical ``signal``: the mapped entry, or the canonical name itself.

        Parameters
        ----------
        signal : str
            Canonical signal name.

        Returns
        -------
        ChannelSpec
        """
        return self.signals.get(signal) or ChannelSpec(signal)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str | Path | None = None) -> ChannelMap:
        """Build a map from parsed TOML content.

        Parameters
        ----------
        data : mapping
            ``{"signals": {...}, "defaults": {...}, "description": "..."}``.
        source : path-like, optional
            File the content came from, for messages.

        Returns
        -------
        ChannelMap

        Raises
        ------
        DataError
            Listing every problem: unknown top-level keys, unknown canonical signals,
            entries without ``channel``, unknown entry fields, unknown or mismatched units,
            non-numeric ``scale`` / ``offset`` / ``group``, defaults for signals that cannot
            have one or outside the plausible range.
        """
        where = str(source) if source is not None else "channel map"
        problems: list[str] = []
        if not isinstance(data, Mapping):
            raise DataError(f"{where}: a channel map must be a table, got {type(data).__name__}")
        for key in data:
            if key not in _TOP_KEYS:
                problems.append(
                    f"{where}: unknown key {key!r}{_close(key, _TOP_KEYS)}; "
                    f"known: {', '.join(_TOP_KEYS)}"
                )
        description = data.get("description", "")
        if not isinstance(description, str):
            problems.append(f"{where}: 'description' must be a string")
            description = ""
        signals = _parse_signals(data.get("signals", {}), where, problems)
        defaults = _parse_defaults(data.get("defaults", {}), where, problems)
        if problems:
            raise DataError(f"{where}: invalid channel map", problems)
        return cls(signals, defaults, description, Path(source) if source is not None else None)


def _parse_signals(table: Any, where: str, problems: list[str]) -> dict[str, ChannelSpec]:
    if not isinstance(table, Mapping):
        problems.append(f"{where}: [signals] must be a table")
        return {}
    out: dict[str, ChannelSpec] = {}
    for name, entry in table.items():
        at = f"{where}: signals.{name}"
        before = len(problems)
        if name not in SIGNALS:
            problems.append(
                f"{at}: unknown canonical signal{_close(name, CANONICAL_ORDER)}; canonical "
                f"signals: {', '.join(CANONICAL_ORDER)}"
            )
            continue
        if isinstance(entry, str):
            entry = {"channel": entry}
        if not isinstance(entry, Mapping):
            problems.append(f"{at}: must be a channel name or a table, got {entry!r}")
            continue
        bad = [k for k in entry if k not in _ENTRY_FIELDS]
        for k in bad:
            problems.append(
                f"{at}: unknown field {k!r}{_close(k, _ENTRY_FIELDS)}; "
                f"fields: {', '.join(_ENTRY_FIELDS)}"
            )
        channel = entry.get("channel")
        if not isinstance(channel, str) or not channel:
            problems.append(f"{at}: 'channel' (source channel name) is required")
            continue
        unit = entry.get("unit")
        if unit is not None:
            try:
                parsed = parse_unit(unit)
                wanted = parse_unit(SIGNALS[name].unit).dimension
                if parsed.dimension != wanted:
                    problems.append(
                        f"{at}: unit {unit!r} is a {parsed.dimension} unit; {name} needs a "
                        f"{wanted} unit"
                    )
            except DataError as exc:
                problems.append(f"{at}: {exc}")
        scale, offset = entry.get("scale", 1.0), entry.get("offset", 0.0)
        for label, value in (("scale", scale), ("offset", offset)):
            if isinstance(value, bool) or not isinstance(value, int | float):
                problems.append(f"{at}: {label!r} must be a number, got {value!r}")
            elif not math.isfinite(value) or (label == "scale" and value == 0):
                problems.append(f"{at}: {label!r} must be finite and non-zero, got {value!r}")
        group = entry.get("group")
        if group is not None and (isinstance(group, bool) or not isinstance(group, int)):
            problems.append(f"{at}: 'group' must be an integer, got {group!r}")
        source = entry.get("source")
        if source is not None and (not isinstance(source, str) or not source.strip()):
            problems.append(f"{at}: 'source' must be a non-empty string, got {source!r}")
            source = None
        if len(problems) == before:
            out[name] = ChannelSpec(channel, unit, float(scale), float(offset), group, source)
    return out


def _parse_defaults(table: Any, where: str, problems: list[str]) -> dict[str, float]:
    if not isinstance(table, Mapping):
        problems.append(f"{where}: [defaults] must be a table")
        return {}
    out: dict[str, float] = {}
    for name, value in table.items():
        at = f"{where}: defaults.{name}"
        spec = SIGNALS.get(name)
        if spec is None:
            problems.append(f"{at}: unknown canonical signal{_close(name, CANONICAL_ORDER)}")
        elif name in _NO_DEFAULT:
            problems.append(f"{at}: {name} cannot have a constant default")
        elif isinstance(value, bool) or not isinstance(value, int | float):
            problems.append(f"{at}: must be a number in {spec.unit}, got {value!r}")
        elif not spec.plausible_min <= value <= spec.plausible_max:
            problems.append(
                f"{at}: {value!r} {spec.unit} is outside the plausible range "
                f"[{spec.plausible_min:g}, {spec.plausible_max:g}] {spec.unit}"
            )
        else:
            out[name] = float(value)
    return out


#: What functions accept as a channel map: a map, a TOML path, parsed TOML, or None.
ChannelMapLike = ChannelMap | str | Path | Mapping[str, Any] | None


def load_channel_map(source: str | Path | ChannelMap | Mapping[str, Any]) -> ChannelMap:
    """Read a channel map.

    Parameters
    ----------
    source : path-like, ChannelMap or mapping
        A TOML file, an existing map (returned unchanged) or parsed TOML content.

    Returns
    -------
    ChannelMap

    Raises
    ------
    DataError
        If the file is missing, is not valid TOML (line and column given) or describes an
        invalid map (see :meth:`ChannelMap.from_dict`).
    """
    if isinstance(source, ChannelMap):
        return source
    if isinstance(source, Mapping):
        return ChannelMap.from_dict(source)
    if not isinstance(source, str | os.PathLike):
        raise DataError(
            f"a channel map must be a TOML file, a mapping or a ChannelMap, got "
            f"{type(source).__name__} {source!r:.60}"
        )
    path = check_input_file(source, "channel map")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: channel map is not UTF-8 text ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: invalid TOML: {exc}") from None
    return ChannelMap.from_dict(data, source=path)
