"""``clutchlab demo``: the whole story on the embedded synthetic stand, written as a report.

stand data (cached in ``OUT/stand_data``) → every available variant fitted on the fast and
slow ramps (physics fit, then the ML variants) → scored on the unseen medium ramp → the
report (``report.html``, ``report.md``, ``metrics.json``, ``metrics.csv``, ``figures/``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..budgets import DEMO_BUDGET_S, FIT_BUDGET_S
from ..data import Dataset, load_dataset
from ..data.output import check_report_out
from ..report_files import REPORT_FILES
from .evaluate import Evaluation, evaluate
from .report import REPORT_FOLDER, ReportFiles, write_report
from .variants import available_variants

__all__ = [
    "DEMO_BUDGET_S",
    "DEMO_FIT_TIME_LIMIT_S",
    "DEMO_RESERVE_S",
    "DemoResult",
    "run_demo",
    "stand_data",
]

#: Wall-clock limit of the demo's physics fit (s): the fit budget of ``fit-physics`` and
#: ``evaluate``, which keeps the demo within its 10-minute budget on 2 cores; a fit stopped
#: by it keeps its best iterate and the report says so.
DEMO_FIT_TIME_LIMIT_S = FIT_BUDGET_S

# DEMO_BUDGET_S (from clutchlab.budgets, 600 s; ``clutchlab demo --budget``): the demo's
# wall-time budget. The closing-the-loop discovery behind ``augmented_hybrid`` must end by
# ``DEMO_BUDGET_S - DEMO_RESERVE_S`` after the demo started (its
# ``DiscoverySettings.time_limit_s`` is what is left when it starts); stopped there, it
# keeps the model it had, claims nothing it did not confirm in full, and the report and
# the terminal say so.

#: Time kept for what follows the discovery (s): the later variants, the hysteresis bands,
#: the classifier comparison and the report; 80 s in all on the slowest 2-core machine
#: measured (session 40, 601 s demo).
DEMO_RESERVE_S = 120.0


def stand_data(
    folder: str | Path, progress: bool = True, config: Any = None
) -> tuple[Dataset, bool]:
    """The demo's stand dataset: loaded from ``folder`` if it holds one, else generated there.

    Parameters
    ----------
    folder : path
        Dataset folder (``manifest.json`` + experiments).
    progress : bool
        Progress bar while the stand runs.
    config : StandConfig, optional
        Stand configuration when generating; the full default stand by default.

    Returns
    -------
    dataset : Dataset
    cached : bool
        Whether it was loaded rather than generated.
    """
    from ..physics.stand import StandConfig, write_stand

    folder = Path(folder)
    if (folder / "manifest.json").exists():
        return load_dataset(folder), True
    write_stand(folder, config or StandConfig(), progress=progress, overwrite=True)
    return load_dataset(folder), False


@dataclass(frozen=True)
class DemoResult:
    """What :func:`run_demo` produced.

    Attributes
    ----------
    files : ReportFiles
        The written report.
    evaluation : Evaluation
        Scores, fitted models and figure data.
    cached : bool
        Whether the stand data were re-used.
    """

    files: ReportFiles
    evaluation: Evaluation
    cached: bool

    @property
    def report(self) -> Path:
        """Path of ``report.html``."""
        return self.files.html

    @property
    def failed(self) -> dict[str, str]:
        """Variants that failed, with the error."""
        return dict(self.evaluation.failed)


def _say(progress: bool, text: str) -> None:
    if progress:
        print(f"clutchlab demo: {text}", file=sys.stderr, flush=True)


def run_demo(
    out: str | Path = "clutchlab-demo",
    progress: bool = True,
    command: str = "clutchlab demo",
    *,
    variants: Sequence[str] | None = None,
    physics_settings: Any = None,
    stand_config: Any = None,
    time_budget_s: float | None = DEMO_BUDGET_S,
) -> DemoResult:
    """Stand data → physics fit → ML variants → report.

    Parameters
    ----------
    out : path
        Output folder; the stand data are cached in ``out/stand_data``.
    progress : bool
        Progress bars and stage messages (stderr).
    command : str
        Command line recorded in the report.
    variants : sequence of str, optional
        Variants to compare; every available one by default, ``augmented_hybrid`` (closing
        the loop: a discovery starting from ``physics_fitted``'s fit) included.
    physics_settings : FitSettings, optional
        Physics fit settings; default settings with a time limit of
        :data:`DEMO_FIT_TIME_LIMIT_S`.
    stand_config : StandConfig, optional
        Stand configuration when the data are generated (the full default stand).
    time_budget_s : float or None
        Wall-time budget of the demo (s): the discovery behind ``augmented_hybrid`` ends by
        ``time_budget_s - DEMO_RESERVE_S`` after the start (see :data:`DEMO_BUDGET_S`);
        None: no budget.

    Returns
    -------
    DemoResult
        The report files (``result.report`` is ``out/report.html``), the evaluation, and
        whether the stand data were re-used.
    """
    from ..physics.fit import FitSettings

    out = Path(out)
    # refused now, not after ten minutes of fitting: the folder is written by swapping it
    check_report_out(out, REPORT_FILES, kind=REPORT_FOLDER, what="demo output folder")
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    _say(progress, f"[1/3] stand data in {out / 'stand_data'}")
    dataset, cached = stand_data(out / "stand_data", progress, stand_config)
    stand_s = time.perf_counter() - t_start
    _say(progress, f"      {len(dataset)} experiments ({'cached' if cached else 'generated'})")
    _say(progress, "[2/3] fit on fast + slow, score on the unseen medium ramp")
    settings = physics_settings or FitSettings(
        progress=progress, time_limit_s=DEMO_FIT_TIME_LIMIT_S
    )
    if variants is None:
        variants = available_variants()
    options = {}
    if time_budget_s is not None and "augmented_hybrid" in variants:
        deadline = t_start + time_budget_s - DEMO_RESERVE_S
        options["augmented_hybrid"] = {"discovery_deadline": deadline}
    ev = evaluate(
        dataset,
        variants,
        physics_settings=settings,
        options=options,
        on_error="report",
        progress=progress,
        command=command,
    )
    ev.timings = {"stand_data_s": stand_s, **ev.timings}
    ev.extra["stand_data_cached"] = cached
    _say(progress, "[3/3] report")
    t0 = time.perf_counter()
    ev.timings["total_s"] = time.perf_counter() - t_start  # without the report rendering
    files = write_report(ev, out)
    _say(progress, f"      report written in {time.perf_counter() - t0:.1f} s")
    return DemoResult(files, ev, cached)
