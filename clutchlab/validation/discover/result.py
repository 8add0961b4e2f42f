"""What a discovery found: per iteration the evidence, the effect added, errors before/after."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...data.output import write_file_atomic
from ...physics import CircuitModel
from ...physics.fit import FitResult
from ...physics.parameters import ParameterSet
from .diagnostics import Diagnostics
from .residuals import ResidualSet
from .scoring import CandidateScore
from .sparse import SparseFit

__all__ = ["DiscoveryResult", "IterationRecord", "ModelState"]


@dataclass
class ModelState:
    """A fitted model during discovery, with its residual and its errors.

    Attributes
    ----------
    fit : FitResult
        The fit (possibly not converged: ``fit.success`` False, best iterate).
    residual : ResidualSet
        Training residual at the fitted parameters.
    train, test : dict
        ``rmse_bar`` and ``fit_pct`` of the dither-period-mean pressure on the
        training and test experiments (NaN without test experiments).
    test_residual : dict
        Test experiment name -> ``(current_mA, residual_bar)`` arrays for figures.
    """

    fit: FitResult
    residual: ResidualSet
    train: dict[str, float]
    test: dict[str, float]
    test_residual: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @property
    def model(self) -> CircuitModel:
        """The model structure."""
        return self.fit.model()

    @property
    def params(self) -> ParameterSet:
        """The fitted parameters."""
        return self.fit.params()


def _parameters(fit: FitResult) -> list[dict[str, Any]]:
    return [
        {
            "name": n,
            "value": fit.values[n],
            "std_error": fit.std_errors.get(n, math.nan),
            "unit": fit.units.get(n, ""),
            # None: not known (the sensitivities diverged, see fit.uncertainty_note)
            "identifiable": None if fit.uncertainty_note else n not in fit.unidentifiable,
        }
        for n in fit.free
    ]


def _clean(x):
    """JSON-safe: NaN/inf -> None, numpy scalars -> Python."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


@dataclass
class IterationRecord:
    """One turn of the loop: residual → evidence → (effect added, refit) → errors.

    Attributes
    ----------
    index : int
        0-based.
    effect : str or None
        Effect added, or None when none was (see ``decision``).
    decision : str
        Why: ``"added"``, ``"no significant effect"``, ``"information criterion did
        not improve"``, ``"effect limit reached"``, ``"no candidates left"``.
    candidates : list of CandidateScore
        Evidence for every candidate, best statistic first.
    before, after : ModelState
        The model before and after (the same object when nothing was added).
    diagnostics : Diagnostics
        Of the residual before.
    sparse : SparseFit
        Sparse regression of the residual before.
    delta_bic : float or None
        Information criterion change of the added effect (negative: better).
    threshold_p : float
        Per-candidate significance level (α/m).
    wall_s : float
        Time of the iteration (s).
    reference : dict
        The residual sum of squares the refits were compared with, and how it was
        obtained (the current fit, or its continuation when it had not converged).
    refits : dict
        Effect name -> :class:`ModelState` of every confirmatory refit that ran.
    expansions : tuple of str
        Strengths the candidates' outputs were linearized at: ``("zero",)``, or
        ``("zero", "profile")`` when the second look (strengths profiled over multiples
        of their defaults) before leaving a structured residual unexplained ran.
    time_limited : bool
        The discovery's time budget (``DiscoverySettings.time_limit_s``) ended this
        iteration before it decided: no effect added, the evidence as far as it got.
    """

    index: int
    effect: str | None
    decision: str
    candidates: list[CandidateScore]
    before: ModelState
    after: ModelState
    diagnostics: Diagnostics
    sparse: SparseFit
    delta_bic: float | None = None
    threshold_p: float = 0.0
    wall_s: float = 0.0
    reference: dict = field(default_factory=dict)
    refits: dict[str, ModelState] = field(default_factory=dict)
    expansions: tuple[str, ...] = ("zero",)
    time_limited: bool = False

    def to_dict(self) -> dict:
        """JSON-ready dict (the issue's keys first)."""
        return {
            "effect": self.effect,
            "candidates": [c.to_dict() for c in self.candidates],
            "train_rmse_before_bar": self.before.train["rmse_bar"],
            "train_rmse_after_bar": self.after.train["rmse_bar"],
            "test_rmse_before_bar": self.before.test["rmse_bar"],
            "test_rmse_after_bar": self.after.test["rmse_bar"],
            "train_fit_pct_before": self.before.train["fit_pct"],
            "train_fit_pct_after": self.after.train["fit_pct"],
            "test_fit_pct_before": self.before.test["fit_pct"],
            "test_fit_pct_after": self.after.test["fit_pct"],
            "decision": self.decision,
            "time_limited": self.time_limited,
            "delta_bic": self.delta_bic,
            "threshold_p": self.threshold_p,
            "expansions": list(self.expansions),
            "reference": self.reference,
            "effects_before": list(self.before.fit.effects),
            "effects_after": list(self.after.fit.effects),
            "parameters_after": _parameters(self.after.fit),
            "fit_status_after": self.after.fit.status,
            "fit_converged_after": bool(self.after.fit.success),
            "residual_before": self.diagnostics.to_dict(),
            "residual_after_rms_bar": self.after.residual.rms_bar,
            "sparse_regression": self.sparse.to_dict(),
            "wall_s": self.wall_s,
        }


def _rmse(errors: dict, width: int) -> str:
    """``errors["rmse_bar"]`` in a column of ``width``; "–" where there is none (no test
    experiments: NaN)."""
    value = errors.get("rmse_bar")
    if value is None or not math.isfinite(value):
        return f"{'–':>{width}s}"
    return f"{value:{width}.4f}"


@dataclass
class DiscoveryResult:
    """The outcome of :func:`~clutchlab.validation.discover.discover`.

    Attributes
    ----------
    iterations : list of IterationRecord
        In order; the last one adds no effect unless the effect limit stopped the loop.
    baseline : ModelState
        The fitted starting model.
    final : ModelState
        The fitted model after the last effect added.
    unexplained : bool
        True when the final residual is still structured (not white), follows at least
        one examined signal, and no library effect explains a significant share of it
        (never when the discovery stopped at its time budget: it did not look far enough).
    signature : list of str
        Signals the unexplained residual follows (empty unless ``unexplained``).
    summary : str
        One paragraph for people.
    train, test : list of str
        Experiment names fitted on / only scored.
    wall_s : float
        Wall time of the discovery (s).
    settings : dict
        The discovery settings used.
    time_limited : bool
        Stopped at its time budget (``DiscoverySettings.time_limit_s``) before its last
        iteration decided; the effects added before stay (each was confirmed in full).
    """

    iterations: list[IterationRecord]
    baseline: ModelState
    final: ModelState
    unexplained: bool
    signature: list[str]
    summary: str
    train: list[str]
    test: list[str]
    wall_s: float
    settings: dict = field(default_factory=dict)
    time_limited: bool = False

    @property
    def added(self) -> list[str]:
        """Effects added, in order."""
        return [it.effect for it in self.iterations if it.effect]

    @property
    def best_model(self) -> CircuitModel:
        """The augmented model structure (base effects + the ones added)."""
        return self.final.model

    @property
    def params(self) -> ParameterSet:
        """Fitted parameters of :attr:`best_model`."""
        return self.final.params

    @property
    def fit_result(self) -> FitResult:
        """The final fit (values, standard errors, identifiability)."""
        return self.final.fit

    def to_dict(self) -> dict:
        """JSON-ready dict: ``{"iterations": [...], "unexplained": bool, ...}``."""
        return _clean(
            {
                "iterations": [it.to_dict() for it in self.iterations],
                "unexplained": self.unexplained,
                "added": self.added,
                "signature": self.signature,
                "summary": self.summary,
                # what a stopped discovery had done / what to do after "unexplained" ("" if
                # neither applies), as the terminal and the report say it
                "stop_note": self.stop_note(),
                "next_steps": self.next_steps(),
                "effects_initial": list(self.baseline.fit.effects),
                "effects_final": list(self.final.fit.effects),
                "train": self.train,
                "test": self.test,
                "baseline": {"train": self.baseline.train, "test": self.baseline.test},
                "final": {
                    "train": self.final.train,
                    "test": self.final.test,
                    "parameters": _parameters(self.final.fit),
                    "values": self.final.fit.values,
                },
                "wall_s": self.wall_s,
                "time_limited": self.time_limited,
                "settings": self.settings,
            }
        )

    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text (written to ``path`` when given, atomically)."""
        text = json.dumps(self.to_dict(), indent=2, ensure_ascii=False)
        if path is not None:
            write_file_atomic(path, (text + "\n").encode("utf-8"), overwrite=True)
        return text

    def next_steps(self) -> str:
        """What a reader can do with an "unexplained" verdict (``""`` otherwise).

        The verdict says that no library effect is claimed and which signals the residual
        follows; this names the commands that go on from there: flexible component laws
        chosen by BIC (``clutchlab select-structure``), a residual model on top of the
        physics (the ``hybrid`` variant of ``clutchlab evaluate``), and the library's
        residual signatures to compare with (``clutchlab effects``).
        """
        if not self.unexplained:
            return ""
        follows = ", ".join(self.signature) or "no single signal"
        return (
            f"What to do next: the residual no effect is claimed for follows {follows}. "
            "A flexible component law may describe it: `clutchlab select-structure DATASET "
            "--candidates plain,force,play,latch,vfs` fits the base circuit with each and "
            "chooses one by BIC on the training ramps; the `hybrid` variant of `clutchlab "
            "evaluate` learns what is left as a residual model on the physics; `clutchlab "
            "effects` lists each library effect's residual signature to compare with; runs "
            "that vary the signal it follows at the same current separate its cause."
        )

    def stop_note(self) -> str:
        """What a discovery stopped at its time budget had done, and how to let it finish.

        The summary says that it stopped; this says which candidates were significant,
        which refits ran (where, their ΔBIC, whether they were compared with a flexible
        law) and which options take it further. ``""`` unless :attr:`time_limited`.
        """
        if not self.time_limited or not self.iterations:
            return ""
        from .alternatives import alternative_note  # alternatives imports this module

        last = self.iterations[-1]
        added = self.added
        done = [
            f"{len(added)} effect(s) added and confirmed ({', '.join(added)})"
            if added
            else "no effect added"
        ]
        significant = [c for c in last.candidates if c.significant]
        if significant:
            done.append(
                f"in iteration {last.index}, {len(significant)} significant candidate(s): "
                + ", ".join(f"{c.effect} (share {c.share:.2f})" for c in significant)
            )
        elif last.candidates:
            done.append(f"in iteration {last.index}, no significant candidate so far")
        else:
            done.append(f"iteration {last.index} stopped before scoring its candidates")
        for c in last.candidates:
            refit = c.refit or {}
            if "delta_bic" not in refit:
                continue
            where = refit.get("subset") or "all training experiments"
            delta = refit["delta_bic"]
            text = f"{c.effect}'s refit on {where}: ΔBIC {delta:.1f}"
            if delta is None or not delta < 0:
                text += " (no better)"
            else:
                compared = alternative_note(refit)
                text += (
                    f", {compared}" if compared else ", not yet compared with a flexible law"
                ) + " (not claimed: its confirmation did not finish)"
            done.append(text)
        budget = self.settings.get("time_limit_s")
        larger = f"a --budget larger than {budget:g} s" if budget else "a larger --budget"
        return (
            "What it had done when it stopped: "
            + "; ".join(done)
            + f". To let it finish: run again with {larger} (this run took "
            f"{self.wall_s:.0f} s); a base fit passed with --physics-model FIT.json (from "
            "`clutchlab fit-physics` on the training ramps) is not fitted again, and "
            "--candidates limits the effects scored."
        )

    def table(self) -> str:
        """Per iteration: effect, the three best candidates' score statistic / share of the
        residual (``*``: significant, as the header says), RMSE before → after.

        An iteration that added no effect shows "—" in the effect column; why it added none
        (its decision, often a sentence) follows the table, one line per such iteration.
        """
        lines = [
            f"{'it':>2s}  {'effect':30s} {'train RMSE (bar)':>19s} {'test RMSE (bar)':>19s}  "
            "evidence: top 3 candidates, statistic/share (*: significant)"
        ]
        notes = []
        for it in self.iterations:
            if it.effect is None:
                notes.append(f"iteration {it.index}: no effect added: {it.decision}")
            top = ", ".join(
                f"{c.effect} {c.statistic:.1f}/{c.share:.2f}{'*' if c.significant else ''}"
                for c in it.candidates[:3]
            )
            lines.append(
                f"{it.index:2d}  {(it.effect or '—'):30s} "
                f"{_rmse(it.before.train, 9)} → {_rmse(it.after.train, 7)} "
                f"{_rmse(it.before.test, 9)} → {_rmse(it.after.test, 7)}  {top}"
            )
        return "\n".join(lines + notes)
