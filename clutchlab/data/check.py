"""Check a dataset folder or a single log: one row per experiment, every problem listed."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import DataError
from .channel_map import ChannelMapLike, load_channel_map
from .io_dataset import scan_dataset
from .options import ReadOptions
from .reading import check_log
from .report import LoadReport

__all__ = ["CheckResult", "check_path"]


def _fmt_range(r: tuple[float, float] | None, digits: str) -> str:
    return "-" if r is None else f"{r[0]:{digits}} – {r[1]:{digits}}"


@dataclass(frozen=True)
class CheckResult:
    """Outcome of :func:`check_path`.

    Parameters
    ----------
    path : pathlib.Path
        What was checked.
    reports : tuple of LoadReport
        One per experiment that could be located, in manifest order.
    ramps : mapping of str to str
        Ramp label of each experiment (by name), where known.
    problems : tuple of str
        Problems of the dataset itself (manifest, missing files).
    """

    path: Path
    reports: tuple[LoadReport, ...] = ()
    ramps: Mapping[str, str] = field(default_factory=dict)
    problems: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """True if nothing is wrong."""
        return not self.problems and all(r.ok for r in self.reports)

    @property
    def n_problems(self) -> int:
        """Number of problems in total."""
        return len(self.problems) + sum(len(r.problems) for r in self.reports)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: ``{"path", "ok", "problems", "experiments": [...]}``."""
        rows = []
        for r in self.reports:
            row = r.to_dict()
            row["ramp"] = self.ramps.get(r.name)
            rows.append(row)
        return {
            "path": str(self.path),
            "ok": self.ok,
            "problems": list(self.problems),
            "experiments": rows,
        }

    def table(self) -> str:
        """Text table, one row per experiment, then every problem.

        Columns: file, ramp, samples, duration (s), rate (Hz), current range (mA), clutch
        pressure range (bar), number of problems.
        """
        head = ("file", "ramp", "samples", "dur s", "rate Hz", "current mA", "p_clutch bar", "!")
        rows = [head]
        for r in self.reports:
            current = r.ranges.get("current_mA") or r.ranges.get("current_cmd_mA")
            rows.append(
                (
                    r.file.name,
                    self.ramps.get(r.name) or "-",
                    "-" if r.samples is None else str(r.samples),
                    "-" if r.duration_s is None else f"{r.duration_s:.3f}",
                    "-" if r.rate_Hz is None else f"{r.rate_Hz:.6g}",
                    _fmt_range(current, ".1f"),
                    _fmt_range(r.ranges.get("clutch_pressure_bar"), ".2f"),
                    str(len(r.problems)),
                )
            )
        widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
        lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
        lines.insert(1, "  ".join("-" * w for w in widths))
        problems = list(self.problems) + [p for r in self.reports for p in r.problems]
        notes = [_named(r.file, n) for r in self.reports for n in (*r.filled, *r.notes)]
        notes += [
            f"{r.file}: resampled onto a uniform grid at {r.rate_Hz:.6g} Hz ({r.resampled});"
            f" jitter up to {r.jitter_max_s * 1e6:.3g} µs"
            for r in self.reports
            if r.resampled and r.rate_Hz
        ]
        if notes:
            lines += ["", "notes:", *(f"  - {n}" for n in notes)]
        status = "OK" if self.ok else f"{self.n_problems} problem(s)"
        lines += ["", f"{self.path}: {status}"]
        if problems:
            lines += [f"  - {p}" for p in problems]
        return "\n".join(lines)


def _named(file: Path, text: str) -> str:
    """``text`` led by the file's path as given (as the problems are), unless it already
    names the file."""
    if text.startswith(f"{file}: "):
        return text
    if text.startswith(f"{file.name}: "):
        text = text[len(file.name) + 2 :]
    return f"{file}: {text}"


def check_path(
    path: str | Path,
    channel_map: ChannelMapLike = None,
    *,
    options: ReadOptions | None = None,
) -> CheckResult:
    """Check a dataset folder (or its manifest) or a single log file, collecting every problem.

    Parameters
    ----------
    path : path-like
        Dataset folder, ``manifest.json``, or one ``.csv`` / ``.parquet`` / ``.mf4`` log.
    channel_map : ChannelMap, path-like or mapping, optional
        Map applied to every experiment (overrides the manifest's ``channel_map`` keys).
    options : ReadOptions, optional
        Gap interpolation, resampling, jitter tolerance.

    Returns
    -------
    CheckResult
        Never raises for problems of the data; they are in the result.

    Raises
    ------
    DataError
        If ``channel_map`` is unusable.
    """
    path = Path(path)
    cmap = load_channel_map(channel_map) if channel_map is not None else None
    if path.is_file() and path.name != "manifest.json":
        trace, report = check_log(path, channel_map=cmap, options=options)
        ramp = trace.ramp if trace is not None else None
        return CheckResult(path, (report,), {report.name: ramp} if ramp else {})
    try:
        scan = scan_dataset(path, cmap, options=options)
    except DataError as exc:
        return CheckResult(path, problems=tuple(exc.problems or [str(exc)]))
    ramps = {e.file.stem: e.meta.get("ramp") for e in scan.manifest.entries}
    return CheckResult(path, scan.reports, ramps, scan.problems)
