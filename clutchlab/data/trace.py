"""One experiment: canonical signals sampled on a common time base, plus its metadata."""

from __future__ import annotations

import copy
import difflib
from collections.abc import Callable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DataError
from .signals import CANONICAL_ORDER, CURRENT_SIGNALS, SIGNALS

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Trace"]

#: At most this many offending rows are listed per problem.
_MAX_ROWS_LISTED = 5


def _default_row_label(i: int) -> str:
    return f"row {i + 1}"


def _list_rows(idx: np.ndarray, row_label: Callable[[int], str]) -> str:
    shown = ", ".join(row_label(int(i)) for i in idx[:_MAX_ROWS_LISTED])
    if idx.size > _MAX_ROWS_LISTED:
        shown += f" … ({idx.size} rows in total)"
    return shown


def _unknown_names_problem(unknown: list[str], where: str) -> str:
    hints = []
    for name in unknown:
        close = difflib.get_close_matches(str(name), CANONICAL_ORDER, n=1)
        hints.append(f"{name!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return (
        f"{where}: non-canonical column(s) {', '.join(hints)}; canonical signals are "
        f"{', '.join(CANONICAL_ORDER)}"
    )


def _check_signals(
    signals: Mapping[str, Any],
    where: str,
    row_label: Callable[[int], str] = _default_row_label,
) -> tuple[dict[str, np.ndarray], list[str]]:
    """Convert and validate signals; return read-only float64 copies and every problem found.

    Parameters
    ----------
    signals : mapping of str to array_like
        Signal name to values (in the unit of the canonical signal).
    where : str
        Prefix naming the trace / file in each problem.
    row_label : callable, optional
        Maps a 0-based sample index to the text naming that row (``"row 5"``, ``"line 6"``).

    Returns
    -------
    arrays : dict of str to numpy.ndarray
        Canonical names, in canonical order, to read-only float64 copies.
    problems : list of str
        Every problem found; empty if the signals satisfy the data contract.
    """
    problems: list[str] = []
    if not isinstance(signals, Mapping):
        return {}, [f"{where}: signals must be a mapping of name to array, got {type(signals)!r}"]

    unknown = [k for k in signals if k not in SIGNALS]
    if unknown:
        problems.append(_unknown_names_problem(unknown, where))

    converted: dict[str, np.ndarray] = {}
    for name in CANONICAL_ORDER:
        if name not in signals:
            continue
        try:
            arr = np.array(signals[name], dtype=np.float64, copy=True)
        except (TypeError, ValueError) as exc:
            problems.append(f"{where}: column {name!r}: cannot convert to float64 ({exc})")
            continue
        if arr.ndim != 1:
            problems.append(f"{where}: column {name!r}: must be 1-D, got shape {arr.shape}")
            continue
        arr.flags.writeable = False
        converted[name] = arr

    if "time_s" not in signals:
        problems.append(f"{where}: required column 'time_s' is missing")
    if not any(c in signals for c in CURRENT_SIGNALS):
        problems.append(
            f"{where}: one of the columns {' / '.join(map(repr, CURRENT_SIGNALS))} is required; "
            "neither is present"
        )
    if "clutch_pressure_bar" not in signals:
        problems.append(f"{where}: required column 'clutch_pressure_bar' is missing")

    lengths = {name: arr.size for name, arr in converted.items()}
    if "time_s" in converted:
        n = lengths["time_s"]
        ref = "time_s"
    elif lengths:
        ref, n = next(iter(lengths.items()))
    else:
        ref, n = None, 0
    for name, size in lengths.items():
        if size != n:
            problems.append(f"{where}: column {name!r} has {size} samples but {ref!r} has {n}")

    t = converted.get("time_s")
    if t is not None:
        if t.size == 0:
            problems.append(f"{where}: no samples (column 'time_s' is empty)")
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            problems.append(
                f"{where}: column 'time_s': non-finite value at {_list_rows(bad, row_label)}"
            )
        finite_pair = np.isfinite(t[1:]) & np.isfinite(t[:-1])
        back = np.flatnonzero(finite_pair & (t[1:] <= t[:-1])) + 1
        if back.size:
            i = int(back[0])
            problems.append(
                f"{where}: column 'time_s': not strictly increasing at "
                f"{_list_rows(back, row_label)} (first: {t[i]:.9g} s after {t[i - 1]:.9g} s)"
            )
    return converted, problems


class Trace:
    """One experiment: canonical signals on a common time base, with metadata.

    Parameters
    ----------
    name : str
        Experiment name (the file stem in a dataset folder).
    signals : mapping of str to array_like
        Canonical signal name to 1-D values of equal length, in the signal's unit
        (``time_s`` in s, currents in mA, pressures in bar, temperature in °C; see
        :data:`~clutchlab.data.signals.SIGNALS`). Required: ``time_s`` (strictly increasing),
        ``clutch_pressure_bar`` and one of ``current_mA`` / ``current_cmd_mA``.
        The arrays are copied to float64 and made read-only.
    meta : dict, optional
        Experiment metadata from the manifest: ``ramp`` (split label), ``dither_freq_Hz`` (Hz),
        ``dither_shape`` and any other key. Copied.
    source : path-like, optional
        File the trace was read from, used in error messages.

    Raises
    ------
    DataError
        Listing every problem found (non-canonical or missing columns, arrays that are not
        1-D or differ in length, non-finite or non-increasing time with the offending rows).
    """

    def __init__(
        self,
        name: str,
        signals: Mapping[str, Any],
        meta: Mapping[str, Any] | None = None,
        source: str | Path | None = None,
    ) -> None:
        source_path = Path(source) if source is not None else None
        where = f"trace {name!r}" + (f" ({source_path})" if source_path is not None else "")
        problems: list[str] = []
        if not isinstance(name, str) or not name:
            problems.append(f"{where}: name must be a non-empty string")
        if meta is not None and not isinstance(meta, Mapping):
            problems.append(f"{where}: meta must be a mapping, got {type(meta)!r}")
            meta = None
        meta_dict = dict(meta or {})
        ramp = meta_dict.get("ramp")
        if ramp is not None and (not isinstance(ramp, str) or not ramp):
            problems.append(f"{where}: meta['ramp'] must be a non-empty string, got {ramp!r}")
        arrays, signal_problems = _check_signals(signals, where)
        problems += signal_problems
        if problems:
            raise DataError(f"invalid {where}", problems)
        self._name: str = name
        self._signals: dict[str, np.ndarray] = arrays
        self.meta: dict[str, Any] = meta_dict
        self._source: Path | None = source_path

    # -- basic attributes ------------------------------------------------------------------

    @property
    def name(self) -> str:
        """Experiment name."""
        return self._name

    @property
    def signals(self) -> Mapping[str, np.ndarray]:
        """Read-only mapping of canonical name to read-only float64 array, canonical order."""
        return MappingProxyType(self._signals)

    @property
    def source(self) -> Path | None:
        """File the trace was read from, or None."""
        return self._source

    @property
    def time_s(self) -> np.ndarray:
        """Sample time, s (read-only, strictly increasing)."""
        return self._signals["time_s"]

    @property
    def ramp(self) -> str | None:
        """Ramp label (split key: ``"fast"``, ``"medium"``, ``"slow"``, …) or None."""
        return self.meta.get("ramp")

    def __len__(self) -> int:
        return int(self._signals["time_s"].size)

    def __repr__(self) -> str:
        return (
            f"Trace(name={self._name!r}, n={len(self)}, ramp={self.ramp!r}, "
            f"signals=[{', '.join(self._signals)}])"
        )

    # -- signal access ---------------------------------------------------------------------

    def has(self, name: str) -> bool:
        """Whether the signal ``name`` is present (a DESIGN default does not count).

        Parameters
        ----------
        name : str
            Canonical signal name.

        Returns
        -------
        bool
        """
        return name in self._signals

    def get(self, name: str, default: float | None = None) -> np.ndarray:
        """Signal values, or a constant array when absent.

        Parameters
        ----------
        name : str
            Canonical signal name.
        default : float, optional
            Constant value, in the signal's unit, used when the signal is absent. If None,
            the DESIGN default is used (``line_pressure_bar`` 17.7 bar,
            ``prime_pressure_bar`` 0.5 bar).

        Returns
        -------
        numpy.ndarray
            Read-only float64 array of ``len(self)`` samples, in the signal's unit.

        Raises
        ------
        DataError
            If ``name`` is not canonical, or the signal is absent and has no default.
        """
        if name in self._signals:
            return self._signals[name]
        spec = SIGNALS.get(name)
        if spec is None:
            raise DataError(
                f"trace {self._name!r}: unknown signal {name!r}; canonical signals: "
                f"{', '.join(CANONICAL_ORDER)}"
            )
        value = default if default is not None else spec.default
        if value is None:
            raise DataError(
                f"trace {self._name!r}"
                + (f" ({self._source})" if self._source is not None else "")
                + f": signal {name!r} is absent and has no default; present: "
                f"{', '.join(self._signals)}"
            )
        out = np.full(len(self), float(value))
        out.flags.writeable = False
        return out

    @property
    def units(self) -> dict[str, str]:
        """Unit of every signal present, by name (e.g. ``{"time_s": "s", ...}``)."""
        return {name: SIGNALS[name].unit for name in self._signals}

    # -- derived quantities ----------------------------------------------------------------

    @property
    def duration_s(self) -> float:
        """Last minus first sample time, s."""
        t = self.time_s
        return float(t[-1] - t[0])

    @property
    def sample_rate_Hz(self) -> float:
        """Median sample rate, Hz (median of ``1 / diff(time_s)``).

        Raises
        ------
        DataError
            If the trace has fewer than two samples.
        """
        t = self.time_s
        if t.size < 2:
            raise DataError(
                f"trace {self._name!r}: sample rate needs at least 2 samples, has {t.size}"
            )
        return float(np.median(1.0 / np.diff(t)))

    # -- conversion ------------------------------------------------------------------------

    def to_pandas(self) -> pd.DataFrame:
        """Signals as a DataFrame.

        Returns
        -------
        pandas.DataFrame
            One float64 column per signal present, in canonical order, in the signal's unit.
            ``df.attrs["units"]`` maps column to unit, ``df.attrs["meta"]`` holds a copy of
            :attr:`meta` and ``df.attrs["name"]`` the trace name.
        """
        import pandas as pd

        df = pd.DataFrame({name: arr.copy() for name, arr in self._signals.items()})
        df.attrs["name"] = self._name
        df.attrs["units"] = self.units
        df.attrs["meta"] = copy.deepcopy(self.meta)
        return df

    @classmethod
    def from_pandas(
        cls,
        df: pd.DataFrame,
        name: str,
        meta: Mapping[str, Any] | None = None,
        source: str | Path | None = None,
    ) -> Trace:
        """Build a trace from a DataFrame with canonical column names.

        Parameters
        ----------
        df : pandas.DataFrame
            One numeric column per canonical signal, in the signal's unit (the index is
            ignored). If ``df.attrs["units"]`` is present, it must agree with the canonical
            units.
        name : str
            Experiment name.
        meta : dict, optional
            Metadata; defaults to ``df.attrs["meta"]`` if present.
        source : path-like, optional
            File the data came from, for error messages.

        Returns
        -------
        Trace

        Raises
        ------
        DataError
            Listing every problem: non-canonical or duplicate columns, non-numeric columns,
            units that disagree with the canonical ones, and every :class:`Trace` check.
        """
        where = f"DataFrame for trace {name!r}" + (f" ({source})" if source is not None else "")
        problems: list[str] = []
        columns = list(df.columns)
        dupes = sorted({str(c) for c in columns if columns.count(c) > 1})
        if dupes:
            problems.append(f"{where}: duplicate column(s) {', '.join(map(repr, dupes))}")
        unknown = [c for c in dict.fromkeys(columns) if c not in SIGNALS]
        if unknown:
            problems.append(_unknown_names_problem(unknown, where))
        units = df.attrs.get("units") or {}
        signals: dict[str, np.ndarray] = {}
        for col in CANONICAL_ORDER:
            if col not in columns or col in dupes:
                continue
            unit = units.get(col) if isinstance(units, Mapping) else None
            if unit is not None and unit != SIGNALS[col].unit:
                problems.append(
                    f"{where}: column {col!r} is in {unit!r} but the canonical unit is "
                    f"{SIGNALS[col].unit!r}"
                )
            try:
                signals[col] = df[col].to_numpy(dtype=np.float64)
            except (TypeError, ValueError) as exc:
                problems.append(f"{where}: column {col!r}: not numeric ({exc})")
        if problems:
            raise DataError(f"cannot build trace {name!r} from DataFrame", problems)
        if meta is None:
            attrs_meta = df.attrs.get("meta")
            meta = copy.deepcopy(attrs_meta) if isinstance(attrs_meta, Mapping) else None
        return cls(name, signals, meta=meta, source=source)

    # -- derived traces --------------------------------------------------------------------

    def with_signals(self, **arrays: Any) -> Trace:
        """New trace with some signals replaced or added.

        Parameters
        ----------
        **arrays : array_like
            Canonical signal name to 1-D values of ``len(self)`` samples, in the signal's unit.

        Returns
        -------
        Trace
            Same name, metadata and source.

        Raises
        ------
        DataError
            If the result breaks the data contract (see :class:`Trace`).
        """
        return Trace(self._name, {**self._signals, **arrays}, meta=self.meta, source=self._source)

    def resample(self, rate_Hz: float) -> Trace:
        """New trace on a uniform grid at ``rate_Hz`` from the first sample on, every signal
        linearly interpolated (as ``clutchlab data convert --rate``).

        Parameters
        ----------
        rate_Hz : float
            Grid rate, Hz.

        Returns
        -------
        Trace
            Same name, metadata and source.

        Raises
        ------
        DataError
            If ``rate_Hz`` is not a positive finite number, or the grid holds fewer than two
            samples.
        """
        rate = float(rate_Hz)
        if not (np.isfinite(rate) and rate > 0):
            raise DataError(f"trace {self._name!r}: resampling rate must be > 0 Hz, not {rate_Hz}")
        t = self.time_s
        n = int(np.floor((t[-1] - t[0]) * rate + 1e-9)) + 1
        if n < 2:
            raise DataError(
                f"trace {self._name!r}: {self.duration_s:.6g} s hold fewer than two samples at "
                f"{rate:g} Hz"
            )
        grid = t[0] + np.arange(n) / rate
        signals = {k: np.interp(grid, t, v) for k, v in self._signals.items()}
        signals["time_s"] = grid
        return Trace(self._name, signals, meta=self.meta, source=self._source)

    def slice_time(self, t0: float | None = None, t1: float | None = None) -> Trace:
        """New trace with the samples whose time lies in ``[t0, t1]``.

        Parameters
        ----------
        t0, t1 : float, optional
            Window start and end (inclusive), s. None means the first / last sample.

        Returns
        -------
        Trace
            Same name, metadata and source.

        Raises
        ------
        DataError
            If ``t1 < t0``, a bound is NaN, or the window contains no sample.
        """
        t = self.time_s
        lo = -np.inf if t0 is None else float(t0)
        hi = np.inf if t1 is None else float(t1)
        if np.isnan(lo) or np.isnan(hi) or hi < lo:
            raise DataError(f"trace {self._name!r}: invalid time window [{t0}, {t1}] s")
        i0 = int(np.searchsorted(t, lo, side="left"))
        i1 = int(np.searchsorted(t, hi, side="right"))
        if i1 <= i0:
            raise DataError(
                f"trace {self._name!r}: no sample in [{t0}, {t1}] s; the trace spans "
                f"[{t[0]:.9g}, {t[-1]:.9g}] s"
            )
        return Trace(
            self._name,
            {name: arr[i0:i1] for name, arr in self._signals.items()},
            meta=self.meta,
            source=self._source,
        )
