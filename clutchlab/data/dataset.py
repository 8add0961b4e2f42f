"""An ordered collection of experiments (traces), split by ramp label."""

from __future__ import annotations

import copy
import operator
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, overload

from ..errors import DataError
from .trace import Trace

if TYPE_CHECKING:
    from .report import LoadReport

__all__ = ["Dataset"]


def _unknown_check(wanted, known: list[str], what: str, problems: list[str]) -> set:
    """The wanted labels as a set; records a problem listing the known ones for unknown labels."""
    wanted = {wanted} if isinstance(wanted, str) else set(wanted)
    unknown = sorted(map(str, wanted - set(known)))
    if unknown:
        problems.append(
            f"unknown {what} {', '.join(map(repr, unknown))}; known: "
            f"{', '.join(map(repr, known)) or '(none)'}"
        )
    return wanted


class Dataset:
    """Ordered collection of experiments, as described by a dataset manifest.

    Parameters
    ----------
    experiments : iterable of Trace
        Experiments, in manifest order. Names must be unique.
    root : path-like, optional
        Folder the dataset was loaded from, or None for an in-memory dataset.
    manifest_extra : dict, optional
        Top-level manifest keys other than ``"experiments"`` (free metadata). Copied.
    reports : mapping of str to LoadReport, optional
        How each experiment was read (sources, unit conversions, jitter, filled gaps), by
        experiment name; set by :func:`~clutchlab.data.io_dataset.load_dataset`.

    Raises
    ------
    DataError
        If experiment names repeat or ``manifest_extra`` has an ``"experiments"`` key.
    TypeError
        If an experiment is not a :class:`~clutchlab.data.trace.Trace`.
    """

    def __init__(
        self,
        experiments: Iterable[Trace],
        root: str | Path | None = None,
        manifest_extra: Mapping[str, Any] | None = None,
        reports: Mapping[str, LoadReport] | None = None,
    ) -> None:
        traces = tuple(experiments)
        for i, trace in enumerate(traces):
            if not isinstance(trace, Trace):
                raise TypeError(f"experiment {i} is a {type(trace).__name__}, not a Trace")
        problems: list[str] = []
        index: dict[str, int] = {}
        for i, trace in enumerate(traces):
            if trace.name in index:
                problems.append(
                    f"experiment {i}: name {trace.name!r} already used by experiment "
                    f"{index[trace.name]}"
                )
            else:
                index[trace.name] = i
        extra = dict(manifest_extra or {})
        if "experiments" in extra:
            problems.append("manifest_extra must not contain the key 'experiments'")
        if problems:
            raise DataError("invalid dataset", problems)
        self._experiments: tuple[Trace, ...] = traces
        self._index = index
        self.root: Path | None = Path(root) if root is not None else None
        self.manifest_extra: dict[str, Any] = extra
        self._reports = {k: v for k, v in (reports or {}).items() if k in index}

    # -- container protocol ----------------------------------------------------------------

    def __iter__(self) -> Iterator[Trace]:
        return iter(self._experiments)

    def __len__(self) -> int:
        return len(self._experiments)

    @overload
    def __getitem__(self, key: int | str) -> Trace: ...

    @overload
    def __getitem__(self, key: slice) -> Dataset: ...

    def __getitem__(self, key: int | str | slice) -> Trace | Dataset:
        """Experiment by position or by name; a slice gives a new Dataset.

        Raises
        ------
        KeyError
            If no experiment has the name ``key``.
        IndexError
            If the position is out of range (the message gives the number of experiments).
        TypeError
            If ``key`` is neither a name, an integer position nor a slice.
        """
        if isinstance(key, str):
            try:
                return self._experiments[self._index[key]]
            except KeyError:
                raise KeyError(
                    f"no experiment named {key!r}; experiments: {', '.join(self._index)}"
                ) from None
        if isinstance(key, slice):
            return self._derive(self._experiments[key])
        try:
            if isinstance(key, bool):
                raise TypeError
            position = operator.index(key)
        except TypeError:
            raise TypeError(
                "an experiment is looked up by its name, an integer position or a slice, "
                f"not {type(key).__name__} {key!r}"
            ) from None
        n = len(self._experiments)
        if not -n <= position < n:
            names = ", ".join(list(self._index)[:5]) + (" …" if n > 5 else "")
            held = f"{n} experiment(s) (positions 0 … {n - 1}; names {names})" if n else "none"
            raise IndexError(
                f"experiment position {position} is out of range: the dataset has {held}"
            )
        return self._experiments[position]

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __repr__(self) -> str:
        return (
            f"Dataset({len(self)} experiments, ramps={self.ramps!r}, "
            f"root={str(self.root) if self.root else None!r})"
        )

    def _derive(self, traces: Iterable[Trace]) -> Dataset:
        return Dataset(
            traces, root=self.root, manifest_extra=self.manifest_extra, reports=self._reports
        )

    # -- views -----------------------------------------------------------------------------

    @property
    def experiments(self) -> tuple[Trace, ...]:
        """The experiments, in order."""
        return self._experiments

    @property
    def reports(self) -> Mapping[str, LoadReport]:
        """How each experiment was read, by name (empty for an in-memory dataset)."""
        return MappingProxyType(self._reports)

    @property
    def channel_maps(self) -> list[str]:
        """The channel map files the experiments were read through (a manifest's or one
        given on loading), sorted; empty when every log had canonical channel names."""
        return sorted({str(r.channel_map) for r in self._reports.values() if r.channel_map})

    @property
    def names(self) -> list[str]:
        """Experiment names, in order."""
        return [t.name for t in self._experiments]

    @property
    def ramps(self) -> list[str]:
        """Sorted unique ramp labels (experiments without a ramp label are not counted)."""
        return sorted({t.ramp for t in self._experiments if t.ramp is not None})

    def select(
        self,
        ramps: str | Iterable[str] | None = None,
        names: str | Iterable[str] | None = None,
    ) -> Dataset:
        """Experiments matching every given criterion, in dataset order.

        Parameters
        ----------
        ramps : str or iterable of str, optional
            Keep experiments with one of these ramp labels (e.g. ``["fast", "slow"]``).
        names : str or iterable of str, optional
            Keep experiments with one of these names.

        Returns
        -------
        Dataset
            Sharing the (immutable) traces, ``root`` and ``manifest_extra``.

        Raises
        ------
        DataError
            If a ramp label or a name is unknown; the message lists the known ones.
        """
        keep = list(self._experiments)
        problems: list[str] = []
        if ramps is not None:
            wanted = _unknown_check(ramps, self.ramps, "ramp label(s)", problems)
            keep = [t for t in keep if t.ramp in wanted]
        if names is not None:
            wanted = _unknown_check(names, list(self._index), "experiment name(s)", problems)
            keep = [t for t in keep if t.name in wanted]
        if problems:
            raise DataError("cannot select experiments", problems)
        return self._derive(keep)

    def by_ramp(self, label: str) -> Dataset:
        """Experiments with ramp label ``label`` (see :meth:`select`).

        Parameters
        ----------
        label : str
            Ramp label, e.g. ``"medium"``.

        Returns
        -------
        Dataset
        """
        return self.select(ramps=[label])

    def manifest(self, suffix: str = ".csv") -> dict[str, Any]:
        """Manifest describing the dataset (the content of ``manifest.json``).

        Parameters
        ----------
        suffix : str, optional
            File extension of the experiment files, e.g. ``".csv"``.

        Returns
        -------
        dict
            ``{"experiments": [{"file": "<name><suffix>", "ramp": ..., **meta}, ...],
            **manifest_extra}``.

        Raises
        ------
        DataError
            Listing every experiment without a ramp label (the manifest requires one).
        """
        entries = []
        problems = []
        for i, trace in enumerate(self._experiments):
            if trace.ramp is None:
                problems.append(f"experiment {i} ({trace.name!r}): no ramp label in meta")
            meta = {k: v for k, v in trace.meta.items() if k not in ("file", "ramp")}
            entries.append(
                {"file": f"{trace.name}{suffix}", "ramp": trace.ramp, **copy.deepcopy(meta)}
            )
        if problems:
            raise DataError("cannot write the dataset manifest", problems)
        return {"experiments": entries, **copy.deepcopy(self.manifest_extra)}
