"""From decoded source channels to a validated trace: map, convert, check, fill, align.

This is the one path every format goes through (DESIGN §3): it applies the channel map and
the unit conversion, collects every problem (each with file, column and row), fills gaps if
allowed, aligns multi-rate or irregular time bases on one uniform grid and builds the
:class:`~clutchlab.data.trace.Trace`, together with a :class:`~clutchlab.data.report.LoadReport`.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DataError
from .channel_map import ChannelMap, ChannelSpec
from .demodulate import dither_in_current, no_dither_amplitude_note, no_dither_frequency_note
from .derived import FOUND_DITHER_KEY
from .options import ReadOptions
from .rawlog import RawChannel, RawLog, TimeBase
from .report import LoadReport
from .signals import CANONICAL_ORDER, CURRENT_SIGNALS, SIGNALS
from .timebase import Timing, align, analyse_timing, uniform_grid
from .trace import Trace
from .units import parse_unit
from .validate import (
    check_dither_rate,
    check_time,
    check_values,
    clutch_pressure_scale_note,
    describe_runs,
    fill_runs,
    nonfinite_runs,
)

__all__ = ["assemble"]

#: Most samples a requested resampling rate may produce (memory guard).
_MAX_GRID = 100_000_000


@dataclass
class _Signal:
    """One canonical signal taken from a source channel, in canonical units."""

    name: str
    channel: RawChannel
    values: np.ndarray
    where: str  # "<file>: column 'P_CL' (clutch_pressure_bar)"
    base: int


#: Sample rates (Hz) outside which a note asks whether the time column is in seconds.
RATE_PLAUSIBLE_HZ = (10.0, 1e6)


#: Where ``interpolate_gaps`` is given: the commands that fit read the data as they are.
_FILL_HOW = (
    ": ReadOptions(interpolate_gaps={n}), or `clutchlab data convert --interpolate-gaps {n}` "
    "for a filled copy to fit on"
)


def _fastest_base(bases: list[TimeBase], used: list[int]) -> int:
    """The time base (index) of ``used`` with the shortest median sample interval: the one
    whose rate a failed multi-rate log is reported at, so its samples and duration match."""

    def step(b: int) -> float:
        d = np.diff(bases[b].time_s)
        d = d[np.isfinite(d) & (d > 0)]
        return float(np.median(d)) if d.size else np.inf

    return min(used, key=step)


def _hint_names(names: list[str]) -> str:
    hints = []
    for name in names:
        close = difflib.get_close_matches(str(name), CANONICAL_ORDER, n=1)
        hints.append(f"{name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return ", ".join(hints)


def _claimed(raw: RawLog, cmap: ChannelMap | None) -> dict[int, str]:
    """Source channels a channel map assigns to a signal: ``id(channel)`` → signal.

    A claimed channel is not also taken, under its own name, for another canonical signal
    the map does not mention.
    """
    if cmap is None:
        return {}
    claimed: dict[int, str] = {}
    for signal, spec in cmap.signals.items():
        if signal == "time_s" and not raw.tabular:
            continue  # MF4 time comes from the master channels; the mapping is ignored
        for channel in raw.find(spec.channel, spec.group, spec.source):
            claimed.setdefault(id(channel), signal)
    return claimed


def _converted_twice(channel: RawChannel, map_unit: str, where: str) -> str:
    """The problem of a map unit on a channel the decoder already converted (timestamps)."""
    unit = "seconds" if channel.unit == "s" else repr(channel.unit)
    return (
        f"{where}: is {channel.converted}, already in {unit}; the map's unit {map_unit!r} does "
        f"not apply (remove it from the channel map)"
    )


def _resolve_unit(
    spec: ChannelSpec, channel: RawChannel, signal: str, mapped: bool, where: str
) -> tuple[str | None, list[str], list[str]]:
    """Unit of the source values, problems and notes."""
    canonical = SIGNALS[signal].unit
    file_unit = None
    notes: list[str] = []
    if channel.converted is not None and spec.unit is not None:
        if parse_unit(spec.unit) != parse_unit(channel.unit):
            return None, [_converted_twice(channel, spec.unit, where)], notes
    if channel.unit is not None:
        try:
            file_unit = parse_unit(channel.unit)
        except DataError:
            if spec.unit is None:
                return (
                    None,
                    [
                        f"{where}: unknown unit {channel.unit!r} in the file; declare the unit in "
                        f"a channel map"
                    ],
                    notes,
                )
            notes.append(f"{where}: unit {channel.unit!r} in the file ignored (map: {spec.unit})")
    if spec.unit is not None:
        if file_unit is not None and file_unit != parse_unit(spec.unit):
            return (
                None,
                [
                    f"{where}: the channel map says unit {spec.unit!r} but the file says "
                    f"{channel.unit!r}"
                ],
                notes,
            )
        return spec.unit, [], notes
    if file_unit is not None:
        if file_unit.dimension != parse_unit(canonical).dimension:
            return (
                None,
                [
                    f"{where}: unit {channel.unit!r} is a {file_unit.dimension} unit; "
                    f"{signal} needs {canonical}"
                ],
                notes,
            )
        if file_unit != parse_unit(canonical) and not mapped:
            return (
                None,
                [
                    f"{where}: is in {channel.unit!r} but the canonical unit is {canonical!r}; "
                    f"declare unit = {channel.unit!r} in a channel map to convert it"
                ],
                notes,
            )
        return channel.unit, [], notes
    return canonical, [], notes


def _source_text(channel: RawChannel, unit: str, signal: str, spec: ChannelSpec) -> str:
    text = channel.where
    canonical = SIGNALS[signal].unit
    if parse_unit(unit) != parse_unit(canonical):
        text += f" [{unit} → {canonical}]"
    if spec.scale != 1.0:
        text += f" × {spec.scale:g}"
    if spec.offset != 0.0:
        text += f" {spec.offset:+g} {canonical}"
    return text


def _convert(values: np.ndarray, unit: str, signal: str, spec: ChannelSpec) -> np.ndarray:
    src, dst = parse_unit(unit), parse_unit(SIGNALS[signal].unit)
    with np.errstate(over="ignore", invalid="ignore"):
        out = values
        if src != dst:
            out = ((values * src.scale + src.offset) - dst.offset) / dst.scale
        if spec.scale != 1.0:
            out = out * spec.scale
        if spec.offset != 0.0:
            out = out + spec.offset
    return np.asarray(out, dtype=np.float64)


def _ranges(signals: Mapping[str, np.ndarray]) -> dict[str, tuple[float, float]]:
    out = {}
    for name, values in signals.items():
        finite = values[np.isfinite(values)]
        if finite.size:
            out[name] = (float(finite.min()), float(finite.max()))
    return out


def assemble(
    raw: RawLog,
    *,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
    channel_map: ChannelMap | None = None,
    options: ReadOptions | None = None,
) -> tuple[Trace | None, LoadReport]:
    """Build a trace from decoded source channels, collecting every problem.

    Parameters
    ----------
    raw : RawLog
        Decoded log.
    name : str, optional
        Experiment name; default the name embedded in the file, else the file stem.
    meta : dict, optional
        Metadata (from the manifest); default the metadata embedded in the file.
    channel_map : ChannelMap, optional
        Source channel → canonical signal; without it, channel names must be canonical.
    options : ReadOptions, optional
        Gap interpolation, resampling, jitter tolerance.

    Returns
    -------
    trace : Trace or None
        None if any problem was found.
    report : LoadReport
        Everything done and found, including the problems.
    """
    options = options or ReadOptions()
    file = str(raw.path)
    embedded = raw.meta or {}
    if name is None:
        emb_name = embedded.get("name")
        name = emb_name if isinstance(emb_name, str) and emb_name else raw.path.stem
    if meta is None:
        meta = embedded.get("meta") if isinstance(embedded.get("meta"), dict) else {}
    problems: list[str] = list(raw.problems)
    notes: list[str] = list(raw.notes)
    filled: list[str] = []
    sources: dict[str, str] = {}
    cmap = channel_map

    # -- 1. which source channel is which canonical signal -----------------------------------
    if cmap is None:
        unknown = [c.name for c in raw.channels if c.name not in SIGNALS]
        if unknown:
            problems.append(
                f"{file}: non-canonical column(s) {_hint_names(unknown)}; canonical signals "
                f"are {', '.join(CANONICAL_ORDER)} (or pass a channel map to rename them)"
            )
    else:
        used = {cmap.spec(s).channel for s in CANONICAL_ORDER}
        ignored = sorted({c.name for c in raw.channels if c.name not in used})
        if ignored:
            shown = ", ".join(map(repr, ignored[:10])) + (" …" if len(ignored) > 10 else "")
            notes.append(f"{len(ignored)} channel(s) not in the channel map ignored: {shown}")

    picked: dict[str, _Signal] = {}
    missing_mapped: dict[str, str] = {}
    rejected: set[str] = set()  # found, but unusable (its problem is reported)
    claimed = _claimed(raw, cmap)
    for signal in CANONICAL_ORDER:
        spec = cmap.spec(signal) if cmap is not None else ChannelSpec(signal)
        mapped = cmap is not None and signal in cmap.signals
        if signal == "time_s" and not raw.tabular:
            if mapped:
                notes.append(
                    "time_s mapping ignored: MF4 channels carry their own time (the master "
                    "channel of their group)"
                )
            continue
        candidates = raw.find(spec.channel, spec.group, spec.source)
        if not mapped and claimed:
            taken = [c for c in candidates if id(c) in claimed]
            candidates = [c for c in candidates if id(c) not in claimed]
            for c in taken:
                notes.append(
                    f"{file}: {c.where} is mapped to {claimed[id(c)]} by {cmap.label}, so it "
                    f"is not also read as {signal}"
                )
        if not candidates and spec.source is not None:
            known = sorted({x for c in raw.find(spec.channel, spec.group) for x in c.sources})
            problems.append(
                f"{file}: channel {spec.channel!r} ({signal}) is not logged from source "
                f"{spec.source!r}; its sources: {', '.join(map(repr, known)) or 'none written'}"
            )
            rejected.add(signal)
            continue
        if not candidates:
            if mapped and signal not in cmap.defaults:
                missing_mapped[signal] = spec.channel
            continue
        if len(candidates) > 1:
            problems.append(
                f"{file}: channel {spec.channel!r} ({signal}) is ambiguous, it occurs as "
                + "; ".join(
                    c.where + (f" from {', '.join(map(repr, c.sources))}" if c.sources else "")
                    for c in candidates
                )
                + "; set 'source' (or 'group') in the channel map"
            )
            rejected.add(signal)
            continue
        channel = candidates[0]
        where = f"{file}: {channel.where}" + (f" ({signal})" if channel.name != signal else "")
        if channel.values is None:
            problems.append(f"{where}: {channel.problem}")
            rejected.add(signal)
            continue
        unit, unit_problems, unit_notes = _resolve_unit(spec, channel, signal, mapped, where)
        problems += unit_problems
        notes += unit_notes
        if unit is None:
            rejected.add(signal)
            continue
        values = _convert(channel.values, unit, signal, spec)
        sources[signal] = _source_text(channel, unit, signal, spec)
        picked[signal] = _Signal(signal, channel, values, where, channel.base or 0)

    for signal, channel_name in missing_mapped.items():
        label = cmap.label if cmap is not None else ""
        group = cmap.spec(signal).group if cmap is not None else None
        elsewhere = sorted({c.base for c in raw.find(channel_name)} - {None})
        if group is not None and elsewhere:
            problems.append(
                f"{file}: channel {channel_name!r}, mapped to {signal} by {label}, is not in "
                f"group {group}; it is in group {', '.join(map(str, elsewhere))} (fix 'group' "
                "in the channel map, or leave it out when the name is unique)"
            )
            continue
        available = ", ".join(repr(c.name) for c in raw.channels[:20])
        problems.append(
            f"{file}: channel {channel_name!r}, mapped to {signal} by {label}, not found; "
            f"channels: {available}" + (" …" if len(raw.channels) > 20 else "")
        )

    # -- 2. time bases ---------------------------------------------------------------------
    bases: list[TimeBase]
    if raw.tabular:
        time_sig = picked.pop("time_s", None)
        if time_sig is None:
            if "time_s" not in missing_mapped and "time_s" not in rejected:
                problems.append(f"{file}: required column 'time_s' is missing")
            bases = []
        else:
            bases = [TimeBase(time_sig.values, time_sig.channel.where, raw.row_label)]
        base_where = [time_sig.where] if time_sig is not None else []
    else:
        bases = raw.bases
        base_where = [f"{file}: time of {b.label} (master channel)" for b in bases]
    used_bases = sorted({s.base for s in picked.values()}) if bases else []
    time_ok: dict[int, bool] = {}
    for b in used_bases:
        t = bases[b].time_s
        known = time_sig.channel.reported if raw.tabular and time_sig is not None else None
        tp = check_time(t, base_where[b], bases[b].row_label, known)
        if t.size < 2:
            tp.append(f"{base_where[b]}: too few samples ({t.size}); at least 2 are needed")
        problems += tp
        time_ok[b] = not tp and bool(np.isfinite(t).all())  # unparseable cells: reported

    # -- 3. values: missing runs, units, ranges ----------------------------------------------
    for sig in picked.values():
        base = bases[sig.base] if bases else None
        row_label = base.row_label if base is not None else raw.row_label
        runs = nonfinite_runs(sig.values)
        if runs and sig.channel.reported is not None:
            known = sig.channel.reported
            runs = [(a, b) for a, b in runs if not known[a:b].all()]
        if runs:
            text, longest = describe_runs(runs, sig.values, row_label)
            if time_ok.get(sig.base) and longest <= options.interpolate_gaps:
                sig.values = fill_runs(base.time_s, sig.values, runs)
                filled.append(f"{sig.where}: interpolated {text}")
            else:
                hint = (
                    f"longer than interpolate_gaps = {options.interpolate_gaps}"
                    if options.interpolate_gaps
                    else f"pass interpolate_gaps={longest} to fill runs up to {longest} samples"
                    f"{_FILL_HOW.format(n=longest)}"
                )
                problems.append(f"{sig.where}: missing values (NaN/inf) at {text} ({hint})")
        problems += check_values(sig.name, sig.values, sig.where, row_label)

    # -- 4. required signals ---------------------------------------------------------------
    accounted = picked.keys() | missing_mapped.keys() | rejected  # absent, or said why
    if "clutch_pressure_bar" not in accounted:
        problems.append(f"{file}: required column 'clutch_pressure_bar' is missing")
    if not any(c in accounted for c in CURRENT_SIGNALS):
        problems.append(
            f"{file}: one of the columns {' / '.join(map(repr, CURRENT_SIGNALS))} is required; "
            "neither is present"
        )

    # -- 5. timing, gaps, alignment -----------------------------------------------------------
    timings: dict[int, Timing] = {}
    for b in used_bases:
        if time_ok[b]:
            timings[b] = analyse_timing(bases[b].time_s, bases[b].label)
    reasons: list[str] = []
    for b, tm in timings.items():
        if not tm.gaps:
            continue
        worst = max(m for _, m in tm.gaps)
        shown = ", ".join(f"{bases[b].row_label(i)} ({m} missing)" for i, m in tm.gaps[:5]) + (
            f" … ({len(tm.gaps)} gaps in total)" if len(tm.gaps) > 5 else ""
        )
        if worst <= options.interpolate_gaps:
            filled.append(f"{base_where[b]}: interpolated time gap(s) before {shown}")
            reasons.append("gaps in the time stamps")
        else:
            hint = (
                f"longer than interpolate_gaps = {options.interpolate_gaps}"
                if options.interpolate_gaps
                else f"pass interpolate_gaps={worst} to interpolate them{_FILL_HOW.format(n=worst)}"
            )
            problems.append(
                f"{base_where[b]}: time gap(s) of missing samples before {shown} "
                f"(interval {tm.interval_s:.6g} s; {hint})"
            )
    for b, tm in timings.items():
        # An MF4 master channel is in seconds by the standard, and a slow channel group
        # (oil temperature at 1 Hz) is normal there; a column of a table may be in ms.
        if raw.tabular and not RATE_PLAUSIBLE_HZ[0] <= tm.rate_Hz <= RATE_PLAUSIBLE_HZ[1]:
            notes.append(
                f"{base_where[b]}: sample rate {tm.rate_Hz:.6g} Hz: is the time in seconds? A "
                "time logged in ms, µs or ns needs its unit in the channel map (unit = 'ms')"
            )
    if options.rate_Hz is not None:
        reasons.append(f"rate_Hz = {options.rate_Hz:g} requested")
    if len(timings) > 1:
        ts = [bases[b].time_s for b in timings]
        if not all(t.size == ts[0].size and np.array_equal(t, ts[0]) for t in ts[1:]):
            rates = ", ".join(f"{tm.label} {tm.rate_Hz:.6g} Hz" for tm in timings.values())
            reasons.append(f"{len(timings)} time bases ({rates})")
    for tm in timings.values():
        if tm.jitter_fraction > options.max_jitter:
            reasons.append(
                f"{tm.label}: time-stamp jitter up to {tm.jitter_fraction:.1%} of the sample "
                f"interval (> max_jitter {options.max_jitter:.1%})"
            )

    grid: np.ndarray | None = None
    if not problems and timings:
        if reasons:
            longest = max(tm.samples for tm in timings.values())
            limit = _MAX_GRID if options.rate_Hz else 4 * longest + 16
            try:
                grid = uniform_grid(list(timings.values()), options.rate_Hz, limit)
            except DataError as exc:
                problems.append(f"{file}: {exc}")
                grid = np.empty(0)
            if problems:
                grid = None
            elif grid.size < 2:
                problems.append(f"{file}: the time bases do not overlap (no common time span)")
                grid = None
            else:
                first = min(tm.start_s for tm in timings.values())
                last = max(tm.end_s for tm in timings.values())
                dropped = (grid[0] - first) + (last - grid[-1])
                if dropped > 1.5 / (options.rate_Hz or max(tm.rate_Hz for tm in timings.values())):
                    notes.append(
                        f"aligned on [{grid[0]:.6g}, {grid[-1]:.6g}] s, the span every channel "
                        f"covers ({dropped:.6g} s of the log outside it dropped)"
                    )
        else:
            grid = bases[used_bases[0]].time_s

    # -- 6. dither resolvable at this rate? ------------------------------------------------------
    rate = None
    found_dither_Hz: float | None = None  # demodulated when no frequency is given
    if grid is not None:
        rate = float(1.0 / np.median(np.diff(grid)))
    elif used_bases:  # the rate the trace would have: checked even when other problems exist
        steps = [np.diff(bases[b].time_s) for b in used_bases]
        steps = [d[np.isfinite(d) & (d > 0)] for d in steps]
        fastest = min((float(np.median(d)) for d in steps if d.size), default=None)
        rate = options.rate_Hz or (1.0 / fastest if fastest else None)
    if rate is not None:
        fsig = picked.get("dither_freq_Hz")
        if fsig is not None:
            problems += check_dither_rate(rate, fsig.values, fsig.where, bases[fsig.base].row_label)
        elif cmap is not None and "dither_freq_Hz" in cmap.defaults:
            problems += check_dither_rate(
                rate, cmap.defaults["dither_freq_Hz"], f"{file}: {cmap.label} defaults"
            )
        elif isinstance(meta.get("dither_freq_Hz"), int | float) and not isinstance(
            meta.get("dither_freq_Hz"), bool
        ):
            problems += check_dither_rate(
                rate, float(meta["dither_freq_Hz"]), f"{file}: manifest 'dither_freq_Hz'"
            )
        elif (csig := picked.get("current_mA")) is not None and time_ok.get(csig.base):
            # No frequency given: the dither of the measured current at its own rate (a
            # log resampled below 10 × that dither would alias it), and a note below.
            t_c = bases[csig.base].time_s
            found_dither_Hz = dither_in_current(csig.values, 1.0 / float(np.median(np.diff(t_c))))
            if found_dither_Hz is not None:
                problems += check_dither_rate(
                    rate,
                    found_dither_Hz,
                    f"{csig.where}: its dither (demodulated, no dither_freq_Hz given)",
                )

    # -- 7. the trace ------------------------------------------------------------------------
    signals: dict[str, np.ndarray] = {}
    defaults: dict[str, float] = {}
    trace = None
    if grid is not None and not problems:
        signals["time_s"] = grid
        for sig in picked.values():
            signals[sig.name] = align(grid, bases[sig.base].time_s, sig.values)
        if cmap is not None:
            for signal, value in cmap.defaults.items():
                if signal not in signals:
                    signals[signal] = np.full(grid.size, value)
                    defaults[signal] = value
                    sources[signal] = f"default {value:g} {SIGNALS[signal].unit} ({cmap.label})"
        if found_dither_Hz is not None:  # the period of the means downstream (DESIGN §3)
            meta = {**meta, FOUND_DITHER_KEY: found_dither_Hz}
        try:
            trace = Trace(name, signals, meta=meta, source=raw.path)
        except DataError as exc:
            problems += exc.problems or [str(exc)]
        if trace is not None and not problems and found_dither_Hz is not None:
            notes.append(no_dither_frequency_note(found_dither_Hz))
        if trace is not None and not problems and (note := no_dither_amplitude_note(trace)):
            notes.append(note)
        if trace is not None and not problems and (note := clutch_pressure_scale_note(trace)):
            notes.append(note)
    if trace is None:  # describe the log as read, for `clutchlab data check`
        if bases and used_bases:
            t0 = bases[_fastest_base(bases, used_bases)].time_s
            signals = {"time_s": t0, **{s.name: s.values for s in picked.values()}}
        else:
            signals = {s.name: s.values for s in picked.values()}
    t = signals.get("time_s")
    finite_t = t[np.isfinite(t)] if t is not None else np.empty(0)
    report = LoadReport(
        file=raw.path,
        format=raw.format,
        name=name,
        channel_map=cmap.label if cmap is not None else None,
        sources=sources,
        defaults=defaults,
        timing=tuple(timings.values()),
        resampled="; ".join(reasons) if reasons and trace is not None else None,
        rate_Hz=rate,
        filled=tuple(filled),
        notes=tuple(notes),
        problems=tuple(problems),
        samples=int(t.size) if t is not None else None,
        duration_s=float(finite_t[-1] - finite_t[0]) if finite_t.size else None,
        ranges=_ranges({k: v for k, v in signals.items() if k != "time_s"}),
    )
    return (trace if not problems else None), report
