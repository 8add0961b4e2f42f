"""The paper's classifier comparison (Table 1, Fig. 2) by leave-one-experiment-out.

For each of the six classifiers (:data:`~clutchlab.residual_ml.classifiers.CLASSIFIERS`) and
each training experiment, the classifier is fitted on the latched / unlatched samples of all
other training experiments and scored on that experiment's samples (latch-event samples
excluded, see :mod:`~clutchlab.residual_ml.labels`). The accuracy of a classifier is the
fraction of correctly classified held-out samples, pooled over all experiments.
"""

from __future__ import annotations

import csv
import io
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from ..data import Trace, write_file_atomic
from ..errors import DataError, ModelError
from ..forkmap import default_workers, fork_imap
from .classifiers import CLASSIFIERS, make_classifier
from .features import DIDT_FEATURES, FeatureBuilder
from .labels import LatchLabelRule, latch_labels

__all__ = ["ClassifierComparison", "compare_classifiers"]


@dataclass
class ClassifierComparison:
    """Result of :func:`compare_classifiers`.

    Attributes
    ----------
    rows : list of dict
        One per classifier: ``name``, ``label``, ``accuracy`` (pooled LOEO), ``min_accuracy``
        (worst held-out experiment), ``fit_s`` (median fit time of one fold, s),
        ``n_train_points`` (bins the last fold's classifier saw).
    per_experiment : dict
        Classifier name → experiment name → held-out accuracy.
    feature_names : list of str
        Classifier inputs.
    experiments : list of str
        Training experiments (each held out once).
    """

    rows: list[dict]
    per_experiment: dict[str, dict[str, float]]
    feature_names: list[str]
    experiments: list[str]
    _final: dict = field(default_factory=dict, repr=False)
    _data: tuple | None = field(default=None, repr=False)

    def table(self) -> str:
        """Plain-text table, one line per classifier."""
        lines = [f"{'classifier':36s} {'LOEO accuracy':>14s} {'worst exp.':>11s} {'fit (s)':>8s}"]
        for r in self.rows:
            lines.append(
                f"{r['label']:36s} {r['accuracy']:14.4f} {r['min_accuracy']:11.4f} "
                f"{r['fit_s']:8.2f}"
            )
        return "\n".join(lines)

    def csv_text(self) -> str:
        """The table as CSV (name, label, accuracy, min_accuracy, fit_s, n_train_points)."""
        keys = ["name", "label", "accuracy", "min_accuracy", "fit_s", "n_train_points"]
        buf = io.StringIO(newline="")
        w = csv.DictWriter(buf, fieldnames=keys)
        w.writeheader()
        for r in self.rows:
            w.writerow({k: r[k] for k in keys})
        return buf.getvalue()

    def to_csv(self, path: str | Path) -> None:
        """Write :meth:`csv_text` to ``path`` (atomically, replacing an earlier file)."""
        write_file_atomic(path, self.csv_text().encode("utf-8"), overwrite=True)

    def to_dict(self) -> dict:
        """JSON-ready result."""
        return {
            "classifiers": {
                r["name"]: {k: v for k, v in r.items() if k != "name"} for r in self.rows
            },
            "per_experiment": self.per_experiment,
            "features": self.feature_names,
            "experiments": self.experiments,
        }

    def figure(self, max_points: int = 4000, seed: int = 0):
        """Paper Fig. 2 style: latched (green) / unlatched (magenta) points and decision regions.

        Each panel shows one classifier (fitted on all training experiments) in the plane of
        nominal current (mA) and dI/dt (mA/s); the other inputs are set per current to the
        median over the training samples at that current (dither frequency: the median
        frequency). The number in each panel is the classifier's LOEO accuracy.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from matplotlib.colors import ListedColormap
        from matplotlib.figure import Figure

        X, y = self._data
        names = self.feature_names
        ii, jd = names.index("current_mA"), names.index("didt_mA_s")
        gi = np.linspace(X[:, ii].min(), X[:, ii].max(), 220)
        gd = np.linspace(X[:, jd].min() * 1.1, X[:, jd].max() * 1.1, 160)
        GI, GD = np.meshgrid(gi, gd)
        grid = np.empty((GI.size, X.shape[1]))
        grid[:, ii], grid[:, jd] = GI.ravel(), GD.ravel()
        edges = np.linspace(gi[0], gi[-1], 45)
        cell = np.clip(np.digitize(X[:, ii], edges) - 1, 0, edges.size - 2)
        gcell = np.clip(np.digitize(grid[:, ii], edges) - 1, 0, edges.size - 2)
        for j, name in enumerate(names):
            if j in (ii, jd):
                continue
            if name == "direction":
                grid[:, j] = np.where(grid[:, jd] > 0, 1.0, -1.0)
                continue
            med = np.array(
                [np.median(X[cell == c, j]) if (cell == c).any() else np.nan for c in range(45)]
            )
            med = np.where(np.isnan(med), np.nanmedian(X[:, j]), med)
            grid[:, j] = med[gcell] if name != "dither_freq_Hz" else np.median(X[:, j])
        rng = np.random.default_rng(seed)
        pick = rng.choice(X.shape[0], min(max_points, X.shape[0]), replace=False)
        n = len(self.rows)
        ncol = min(3, n)  # one classifier: one panel, not a row of three with two empty
        nrow = int(np.ceil(n / ncol))
        fig = Figure(figsize=(4.2 * ncol, 3.4 * nrow), layout="constrained")
        cmap = ListedColormap(["#f3c6f0", "#c8ecc8"])
        for k, r in enumerate(self.rows):
            ax = fig.add_subplot(nrow, ncol, k + 1)
            clf = self._final[r["name"]]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                Z = clf.predict(grid).reshape(GI.shape)
            ax.contourf(GI, GD, Z, levels=[-0.5, 0.5, 1.5], cmap=cmap)
            for lab, color in ((0, "m"), (1, "g")):
                sel = pick[y[pick] == lab]
                ax.scatter(X[sel, ii], X[sel, jd], s=3, c=color, lw=0)
            ax.set_title(r["label"], fontsize=9)
            ax.text(
                0.97,
                0.04,
                f"{r['accuracy']:.3f}",
                transform=ax.transAxes,
                ha="right",
                fontsize=11,
                weight="bold",
                # readable over the points it sits on
                bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "0.6", "alpha": 0.85},
            )
            ax.set_xlabel("nominal current (mA)")
            ax.set_ylabel("dI/dt (mA/s)")
        fig.suptitle("Latched (green) vs unlatched (magenta); LOEO accuracy in each panel")
        return fig


def compare_classifiers(
    traces: list[Trace],
    names: list[str] | None = None,
    features: tuple[str, ...] = DIDT_FEATURES,
    rule: LatchLabelRule | None = None,
    random_state: int = 0,
    progress: bool = False,
    workers: int | None = None,
) -> ClassifierComparison:
    """Leave-one-experiment-out accuracy of the latch classifiers on training experiments.

    Parameters
    ----------
    traces : list of Trace
        Training experiments (at least 2; e.g. the fast and slow ramps).
    names : list of str, optional
        Classifiers (default all six of :data:`CLASSIFIERS`, in the paper's order); a name
        given twice is compared once.
    features : tuple of str
        Classifier inputs (default I, A_d, f_d, dI/dt, direction).
    rule : LatchLabelRule, optional
        Latch-label rule (default parameters).
    random_state : int
        Seed of subsets and boosting.
    progress : bool
        Show a progress bar.
    workers : int, optional
        Worker processes of the fits (:func:`clutchlab.forkmap.default_workers` by default;
        1 fits in this process). The result does not depend on it.

    Returns
    -------
    ClassifierComparison

    Raises
    ------
    DataError
        If fewer than two experiments are given, the labels hold one latch state only, or
        a latch state occurs in one experiment only (a fold would train without it).
    ModelError
        Naming every classifier that is not one of :data:`CLASSIFIERS`.
    """
    traces = list(traces)
    if len(traces) < 2:
        raise DataError(
            f"leave-one-experiment-out needs at least 2 training experiments, got {len(traces)}"
        )
    names = list(dict.fromkeys(names or CLASSIFIERS))  # each once: a repeat is one row
    unknown = [n for n in names if n not in CLASSIFIERS]
    if unknown:
        raise ModelError(f"unknown classifier(s) {unknown}; known: {', '.join(CLASSIFIERS)}")
    builder = FeatureBuilder(tuple(features))
    Xs, ys = [], []
    for t in traces:
        F = builder.build(t)
        lab = latch_labels(t, rule)
        keep = lab >= 0
        Xs.append(F[keep])
        ys.append(lab[keep].astype(int))
    X, y = np.concatenate(Xs), np.concatenate(ys)
    if np.unique(y).size < 2:
        raise DataError("the training experiments hold only one latch state; nothing to classify")
    n = len(traces)
    # every fold trains without one experiment: it needs both states in the others
    state_names = {0: "unlatched", 1: "latched"}
    alone = []
    for state, label in state_names.items():
        holders = [k for k in range(n) if np.any(ys[k] == state)]
        if len(holders) == 1:
            alone.append(f"only experiment {traces[holders[0]].name!r} has {label} samples")
    if alone:
        raise DataError(
            "leave-one-experiment-out needs each latch state in at least 2 training "
            "experiments (a fold trains without one of them)",
            alone,
        )
    jobs = [(name, k) for name in names for k in [*range(n), None]]  # None: the final fit

    def run(j: int) -> tuple[int, float, object]:
        """Job ``j``: held-out correct count and fit time, or the final classifier."""
        name, k = jobs[j]
        clf = make_classifier(name, random_state=random_state, feature_names=builder.names)
        Xtr = X if k is None else np.concatenate([Xs[i] for i in range(n) if i != k])
        ytr = y if k is None else np.concatenate([ys[i] for i in range(n) if i != k])
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # discretizer bins collapsing on constant inputs
            clf.fit(Xtr, ytr)
        fit_s = time.perf_counter() - t0
        if k is None:
            return 0, fit_s, clf
        return (int((clf.predict(Xs[k]) == ys[k]).sum()) if ys[k].size else 0), fit_s, None

    # The fits are independent: they run on worker processes (same results in any order).
    done = {}
    with tqdm(total=len(jobs), desc="classifiers", disable=not progress) as bar:
        for j, r in fork_imap(run, len(jobs), workers or default_workers()):
            done[jobs[j]] = r
            bar.update()
    rows, per, final = [], {}, {}
    for name in names:
        final[name] = clf = done[(name, None)][2]
        correct = sum(done[(name, k)][0] for k in range(n))
        total = sum(ys[k].size for k in range(n))
        accs = {
            traces[k].name: done[(name, k)][0] / ys[k].size if ys[k].size else float("nan")
            for k in range(n)
        }
        per[name] = accs
        rows.append(
            {
                "name": name,
                "label": CLASSIFIERS[name].label,
                "accuracy": correct / total,
                "min_accuracy": float(np.nanmin(list(accs.values()))),
                "fit_s": float(np.median([done[(name, k)][1] for k in range(n)])),
                "n_train_points": int(clf.n_train_points_),
            }
        )
    return ClassifierComparison(
        rows, per, list(builder.names), [t.name for t in traces], final, (X, y)
    )
