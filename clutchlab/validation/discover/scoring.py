"""Attribution: how much of the residual each library effect's output sensitivity explains.

A score (Lagrange-multiplier) test per candidate effect, evaluated at the fitted model
with the candidate switched on at zero strength, where the model output equals the
fitted model's:

1. ``X = ∂ŷ/∂s`` — the output sensitivities to the effect's strength parameters ``s``
   (CasADi forward sensitivities through the compiled integrator, the same residual
   operator as the fit: dither-period mean, decimated).
2. Project out what the fit can already do: with ``Q`` an orthonormal basis of the free
   parameters' sensitivities ``J``, ``X⊥ = (I − QQᵀ) X`` and ``r⊥ = (I − QQᵀ) r``. The
   *novelty* ``‖X⊥‖ / ‖X‖`` says how much of the effect's signature is new (0: the free
   parameters mimic it exactly, e.g. a latch threshold shift against the latch preload).
3. Bounded linear least squares ``min ‖r⊥ + X⊥ b‖`` with ``b`` inside the strength bounds
   (effects act one way: friction, leakage, lag ≥ 0), the one-step estimate of the
   strength. ``share = 1 − RSS₁/RSS₀`` is the fraction of the residual it explains.
4. Statistic ``T = n_eff · ln(RSS₀/RSS₁)`` (the linearized likelihood ratio) with
   ``n_eff`` the effective number of independent residuals of the alternative
   (:func:`~.residuals.effective_size`), referred to χ² with ``k`` = number of strength
   parameters (conservative for one-sided bounds). Significant when ``p < α / m``.

Where the sensitivity is identically zero at zero strength (a strength entering
quadratically, e.g. the supply restriction's area ratio), it is taken at a small probe
strength instead; the residual is still the fitted model's. An effect's fitted
parameters that are not strengths (a lag's time constant) have no sensitivity at zero
strength but shape the strength's; they are scored on a grid, refined once around its
best point, and the largest statistic kept (a sup-score test: the significance level is
divided by the number of values scored).

The linearization at zero strength misses an effect whose output is far from linear in
its strength over the range that matters (a viscosity ``exp(−b ΔT)`` over 30 K; a magnetic
hysteresis whose small play only shifts the spool's friction stick-slip, so that 0.3 N
makes the fit worse and 2.5 N explains nine tenths of the residual). Before a structured
residual is left unexplained, :func:`~.loop.discover` therefore takes a second look, the
*profile* (``expansion="profile"``): the effect's strengths are set along their defaults at
:data:`PROFILE_MULTIPLIERS` × the default (clipped to the bounds), the projected residual
sum of squares is computed there by simulation (the free parameters enter to first order,
through the projection), and from the best of these points one Gauss–Newton step is taken
(linearized there, inside the bounds). It is a likelihood-ratio statistic profiled over a
grid of strengths: each candidate keeps the larger statistic of the two looks, and the
significance level is divided by all the points scored.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import lsq_linear
from scipy.stats import chi2
from tqdm.auto import tqdm

from ...data import Trace
from ...errors import ClutchlabError
from ...physics import CircuitModel
from ...physics.effects import EFFECTS
from ...physics.fit import FitSettings
from ...physics.parameters import ParameterSet
from .residuals import ResidualSet, effective_size, point_sums_of_squares, residual_problem
from .warm import warm_sensitivities

__all__ = ["CandidateScore", "Projector", "profile_points", "score_candidates", "score_effect"]

#: Relative singular-value cut-off of the free parameters' sensitivity basis.
RANK_TOL = 1e-8
#: Below this novelty an effect is reported as confounded with the free parameters.
MIN_NOVELTY = 0.02
#: Multiples of the default at which an effect's fitted non-strength parameters (a lag's
#: time constant) are scored, see :func:`nuisance_grid`.
NUISANCE_FACTORS = (0.3, 1.0, 3.0, 10.0)
#: Factor around the best nuisance grid value scored once more (see
#: :func:`nuisance_refinements`): the geometric mid-point of the grid's spacing.
REFINE_FACTOR = 3.0**0.5
#: Multiples of the default strength the profile look simulates at (clipped to the
#: bounds, duplicates dropped): beyond the default, where the linearization at zero does
#: not reach; 10 × reaches the upper bound of most library strengths.
PROFILE_MULTIPLIERS = (3.0, 10.0)


@dataclass
class CandidateScore:
    """Evidence for one candidate effect in one iteration.

    Attributes
    ----------
    effect : str
        Library name.
    k : int
        Number of strength parameters tested.
    share : float
        Fraction of the (projected) residual sum of squares its sensitivity explains.
    statistic : float
        ``n_eff · ln(RSS₀/RSS₁)``.
    p_value : float
        χ²ₖ tail probability of ``statistic``.
    n_eff : float
        Effective number of independent residuals used.
    novelty : float
        ``‖X⊥‖/‖X‖``: part of the sensitivity the free parameters cannot mimic.
    strength : dict
        One-step (linearized) estimate of each strength parameter (its unit).
    nuisance : dict
        Values of the fitted non-strength parameters at which the score was largest.
    n_tests : int
        Number of nuisance values scored (the significance level is divided by it).
    probe : str
        Where the output was linearized: ``"zero"`` (zero strength), ``"probe"`` (a small
        strength), ``"default"`` (the default strength) or ``"profile"`` (the best point of
        the profile over :data:`PROFILE_MULTIPLIERS` × the default).
    significant : bool
        ``p_value < α/(m·n_tests)`` and ``share ≥ min_share``.
    status : str
        ``"scored"``, ``"confounded"`` (novelty below :data:`MIN_NOVELTY`) or
        ``"failed: <reason>"``.
    signature : str
        The effect's documented residual signature.
    refit : dict
        Filled when the candidate was refitted to confirm: ``status``, ``rss_bar2``,
        ``delta_bic``, ``wall_s``.
    diverged : list of dict
        Points of the profile look (strengths, and the nuisance values scored with them;
        engineering units) where the model with the effect could not be simulated: its
        integration diverged (see :data:`~.residuals.DIVERGED_SPANS`). The effect was not
        evaluated there; more integration substeps (``FitSettings.substeps``) may reach it.
    wall_s : float
        Time to score it (s).
    """

    effect: str
    k: int
    share: float = 0.0
    statistic: float = 0.0
    p_value: float = 1.0
    n_eff: float = 0.0
    novelty: float = 0.0
    strength: dict[str, float] = field(default_factory=dict)
    nuisance: dict[str, float] = field(default_factory=dict)
    n_tests: int = 1
    probe: str = "zero"
    significant: bool = False
    status: str = "scored"
    signature: str = ""
    refit: dict = field(default_factory=dict)
    diverged: list[dict[str, float]] = field(default_factory=list)
    wall_s: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return asdict(self)


class Projector:
    """Orthogonal projection away from the free parameters' output sensitivities.

    Parameters
    ----------
    jacobian : numpy.ndarray
        Residuals × scaled free parameters (bar per unit z).
    """

    def __init__(self, jacobian: np.ndarray | None) -> None:
        if jacobian is None or jacobian.size == 0:
            self.q = None
            return
        norms = np.linalg.norm(jacobian, axis=0)
        j = jacobian[:, norms > 0] / norms[norms > 0]
        if j.shape[1] == 0:
            self.q = None
            return
        u, s, _ = np.linalg.svd(j, full_matrices=False)
        self.q = u[:, s > RANK_TOL * s[0]]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """``(I − QQᵀ) x``."""
        if self.q is None:
            return np.array(x, dtype=float, copy=True)
        return x - self.q @ (self.q.T @ x)


def _sensitivity(
    model: CircuitModel,
    values: dict[str, float],
    strength: tuple[str, ...],
    probe: dict[str, float],
    traces: list[Trace],
    fit: FitSettings,
    keep: np.ndarray,
):
    params = model.params(**values, **probe)
    problem = residual_problem(model, params, strength, traces, fit)
    warm_sensitivities(model, traces, fit, len(strength))
    problem.start_workers(traces, fit.workers)
    try:
        ev = problem.evaluate(np.zeros(problem.n_z), True)
    finally:
        problem.close()
    if not ev["ok"] or ev.get("J") is None:
        raise ClutchlabError("the model with the effect diverges at its probe strength")
    x = ev["J"].toarray()[keep]
    if not np.all(np.isfinite(x)):
        raise ClutchlabError("non-finite output sensitivity")
    return x, problem.bounds_z(), np.asarray(ev["r"], dtype=float)[keep]


def score_effect(
    name: str,
    model: CircuitModel,
    values: dict[str, float],
    traces: list[Trace],
    base: ResidualSet,
    projector: Projector,
    fit: FitSettings,
    probe_fraction: float = 0.1,
    expansion: str = "zero",
    nuisance: dict[str, float] | None = None,
) -> CandidateScore:
    """Score test of one library effect ``name`` against the fitted ``model``.

    Parameters
    ----------
    name : str
        Effect not yet in ``model``.
    model : CircuitModel
        The fitted model structure.
    values : dict
        Its fitted parameter values (engineering units).
    traces : list of Trace
        Training experiments (the ones ``base`` was computed on, same order).
    base : ResidualSet
        Residual of the fitted model.
    projector : Projector
        Projection away from the free parameters' sensitivities.
    fit : FitSettings
        Residual operator (substeps, decimation, settle time, workers).
    probe_fraction : float
        Fraction of the default strength used when the zero-strength sensitivity vanishes.
    expansion : {"zero", "default", "profile"}
        Where the effect's output is linearized (see :func:`_score_at`).
    nuisance : dict, optional
        Fixed values of the effect's fitted non-strength parameters (a lag's time
        constant, engineering units), scored at instead of the nuisance grid; the profile
        look takes those of the first look.

    Returns
    -------
    CandidateScore
        Never raises for a failing candidate: its ``status`` says why.
    """
    t0 = time.perf_counter()
    cls = EFFECTS[name]
    strength = tuple(cls.STRENGTH)
    out = CandidateScore(effect=name, k=len(strength), signature=cls.signature)
    try:
        cand = model.with_effects(name)
        grid = [dict(nuisance)] if nuisance is not None else nuisance_grid(cand, name)
        rp = projector(base.r[base.keep])
        rss0 = float(np.dot(rp, rp))
        best = None
        tried: list[dict[str, float]] = []
        diverged: list[dict[str, float]] = []

        def trial_at(point: dict[str, float]) -> None:
            nonlocal best
            tried.append(point)
            trial = _score_at(
                cand,
                name,
                values | point,
                traces,
                base,
                projector,
                fit,
                rp,
                probe_fraction,
                expansion,
            )
            trial.nuisance = point
            diverged[:] = _merged(diverged, trial.diverged)
            if best is None or trial.statistic > best.statistic:
                best = trial

        for point in grid:
            trial_at(point)
        if nuisance is None:
            for point in nuisance_refinements(cand, best.nuisance):
                if point not in tried:
                    trial_at(point)
        per_point = len(profile_points(cand, name)) if expansion == "profile" else 1
        out.n_tests = len(tried) * per_point
        for key in ("share", "statistic", "p_value", "n_eff", "novelty", "strength", "probe"):
            setattr(out, key, getattr(best, key))
        out.nuisance, out.status = best.nuisance, best.status
        out.diverged = diverged
        if rss0 <= 0:
            out.status = "confounded"
    except ClutchlabError as exc:
        out.status = f"failed: {exc}"
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        out.status = f"failed: {type(exc).__name__}: {exc}"
    out.wall_s = time.perf_counter() - t0
    return out


def nuisance_grid(cand: CircuitModel, name: str) -> list[dict[str, float]]:
    """Values of the effect's fitted non-strength parameters to score at.

    Such a parameter (a lag's time constant) has no output sensitivity at zero
    strength, yet shapes the strength's sensitivity; the score is taken at each of
    :data:`NUISANCE_FACTORS` × its default (clipped to the bounds) and the largest is
    kept — a sup-score test, whose significance level is divided by the grid size.
    """
    specs = {p.name: p for p in cand.parameters}
    grid: list[dict[str, float]] = [{}]
    for n in _nuisance_names(name):
        spec = specs[n]
        values = sorted(
            {min(max(spec.default * f, spec.lower), spec.upper) for f in NUISANCE_FACTORS}
        )
        grid = [g | {n: v} for g in grid for v in values]
    return grid


def _merged(points: list[dict[str, float]], more: list[dict[str, float]]) -> list[dict[str, float]]:
    """``points`` followed by the points of ``more`` not already in it (order kept)."""
    return points + [p for p in more if p not in points]


def _nuisance_names(name: str) -> list[str]:
    """The effect's fitted parameters that are not strengths (a lag's time constant)."""
    cls = EFFECTS[name]
    return [n for n in cls.fit_parameters() if n not in cls.STRENGTH]


def nuisance_refinements(cand: CircuitModel, best: dict[str, float]) -> list[dict[str, float]]:
    """Values around the best grid point: each nuisance parameter ×/÷ :data:`REFINE_FACTOR`.

    The grid of :func:`nuisance_grid` is a factor 3–3.3 apart; a lag between two grid
    values has a sensitivity neither grid value matches well (a 4.7 ms eddy-current lag
    against 3 and 9 ms), so the best grid point is refined once, within the bounds.
    """
    specs = {p.name: p for p in cand.parameters}
    out = []
    for n, v in best.items():
        for f in (1.0 / REFINE_FACTOR, REFINE_FACTOR):
            x = min(max(v * f, specs[n].lower), specs[n].upper)
            if x != v:
                out.append(best | {n: x})
    return out


def _score_at(
    cand: CircuitModel,
    name: str,
    values: dict[str, float],
    traces: list[Trace],
    base: ResidualSet,
    projector: Projector,
    fit: FitSettings,
    rp: np.ndarray,
    probe_fraction: float = 0.1,
    expansion: str = "zero",
) -> CandidateScore:
    """The score of effect ``name`` at fixed non-strength parameter ``values``.

    ``expansion="zero"``: linearized at zero strength, where the model is the fitted one
    (the score test). ``"default"``: linearized at the effect's default strength, from
    the residual there — a one-step (Gauss–Newton) look at an effect whose output is
    far from linear in its strength over the range that matters. ``"profile"``: the same
    from the best point of :func:`profile_points` (see :func:`_profile_best`).
    """
    cls = EFFECTS[name]
    strength = tuple(cls.STRENGTH)
    out = CandidateScore(effect=name, k=len(strength))
    specs = {p.name: p for p in cand.parameters}

    def clipped(fraction: float) -> dict[str, float]:
        return _along_defaults(specs, strength, fraction)

    rss0 = float(np.dot(rp, rp))
    if expansion in ("default", "profile"):
        # linearized at a non-zero strength: the residual there, not the fitted model's
        if expansion == "default":
            probe = clipped(1.0)
        else:
            probe, rss_at, diverged = _profile_best(
                cand, name, values, traces, base.keep, projector, fit
            )
            nuisance = {k: v for k, v in values.items() if k in _nuisance_names(name)}
            out.diverged = [nuisance | p for p in diverged]
            if rss_at >= rss0:
                # no profile point explains any of the residual: no step from a point
                # that is worse than the fitted model (and no sensitivity to pay for)
                out.probe, out.strength = expansion, dict(probe)
                return out
        x, (lo, hi), r_at = _sensitivity(cand, values, strength, probe, traces, fit, base.keep)
        start = projector(r_at)
        out.probe = expansion
    else:
        probe = {s: 0.0 for s in strength}
        x, (lo, hi), _ = _sensitivity(cand, values, strength, probe, traces, fit, base.keep)
        start = rp
        if not np.any(x):
            probe = clipped(probe_fraction)
            x, (lo, hi), _ = _sensitivity(cand, values, strength, probe, traces, fit, base.keep)
            out.probe = "probe"
    xp = projector(x)
    out.novelty = float(np.linalg.norm(xp) / max(np.linalg.norm(x), 1e-300))
    if out.novelty < MIN_NOVELTY or rss0 <= 0:
        out.status = "confounded"
        return out
    sol = lsq_linear(xp, -start, bounds=(lo, hi), method="bvls")
    e1 = start + xp @ sol.x
    rss1 = float(np.dot(e1, e1))
    out.share = float(max(1.0 - rss1 / rss0, 0.0))
    n_eff, _ = effective_size(e1, base.kept_slices)
    out.n_eff = n_eff
    # linearized away from zero strength, the best step can still predict more than the
    # fitted model's residual (the linear model of a far point): no evidence, not negative
    out.statistic = float(max(n_eff * np.log(rss0 / max(rss1, 1e-300)), 0.0))
    out.p_value = float(chi2.sf(out.statistic, len(strength)))
    steps = zip(strength, sol.x, strict=True)
    out.strength = {s: float(probe[s] + specs[s].scale * b) for s, b in steps}
    return out


def profile_points(cand: CircuitModel, name: str) -> list[dict[str, float]]:
    """Strengths of the profile look: :data:`PROFILE_MULTIPLIERS` × the defaults.

    Every strength parameter of the effect is scaled together along its default (its
    scale where the default is 0), clipped to its bounds; repeated points are dropped
    (a lag strength κ defaults to its upper bound 1 and gives one point).
    """
    specs = {p.name: p for p in cand.parameters}
    points: list[dict[str, float]] = []
    for m in PROFILE_MULTIPLIERS:
        point = _along_defaults(specs, EFFECTS[name].STRENGTH, m)
        if point not in points:
            points.append(point)
    return points


def _along_defaults(specs: dict, strength, fraction: float) -> dict[str, float]:
    """``fraction`` × each strength's default (its scale where the default is 0), clipped
    to its bounds (engineering units)."""
    out = {}
    for s in strength:
        spec = specs[s]
        out[s] = min(max(fraction * (spec.default or spec.scale), spec.lower), spec.upper)
    return out


def _profile_best(
    cand: CircuitModel,
    name: str,
    values: dict[str, float],
    traces: list[Trace],
    keep: np.ndarray,
    projector: Projector,
    fit: FitSettings,
) -> tuple[dict[str, float], float, list[dict[str, float]]]:
    """The point of :func:`profile_points` with the smallest projected residual sum of squares.

    One simulation per point (no sensitivities), all in one residual problem whose
    experiments are shared among ``fit.workers`` processes; the free parameters enter
    through the projection, i.e. to first order. Returns the point, its projected sum of
    squares (bar²; ``inf`` when the model diverges at every point) and the points where it
    diverged.
    """
    points = profile_points(cand, name)
    rss = point_sums_of_squares(cand, values, points, traces, fit, keep, projector)
    diverged = [p for p, r in zip(points, rss, strict=True) if not np.isfinite(r)]
    k = int(np.argmin(rss))
    return points[k], float(rss[k]), diverged


def _compile_ahead(model: CircuitModel, name: str, traces: list[Trace], fit: FitSettings) -> None:
    """Start compiling the sensitivity code the score of ``name`` will need (see
    :func:`~.warm.warm_sensitivities`); a model that cannot be built is left to its score."""
    try:
        cand = model.with_effects(name)
    except (ClutchlabError, ValueError):
        return
    warm_sensitivities(cand, traces, fit, len(EFFECTS[name].STRENGTH), background=True)


def score_candidates(
    candidates: list[str],
    model: CircuitModel,
    params: ParameterSet,
    traces: list[Trace],
    base: ResidualSet,
    fit: FitSettings,
    *,
    alpha: float = 0.01,
    min_share: float = 0.1,
    probe_fraction: float = 0.1,
    progress: bool = False,
    expansion: str = "zero",
    previous: list[CandidateScore] | None = None,
    keep: frozenset[str] = frozenset(),
) -> list[CandidateScore]:
    """Score every candidate; flag the significant ones; best statistic first.

    Parameters
    ----------
    candidates : list of str
        Library effects not in ``model``.
    model, params : CircuitModel, ParameterSet
        The fitted model and its parameters.
    traces : list of Trace
        Training experiments.
    base : ResidualSet
        Residual with the Jacobian of the free parameters (``jacobian`` set).
    fit : FitSettings
        Residual operator.
    alpha : float
        Family-wise level; Bonferroni: each test at ``alpha / len(candidates)``.
    min_share : float
        Smallest explained share that counts.
    probe_fraction : float
        See :func:`score_effect`.
    progress : bool
        Progress bar.
    expansion : {"zero", "default", "profile"}
        Where each effect is linearized (see :func:`score_effect`).
    previous : list of CandidateScore, optional
        Scores of the same candidates at another expansion point: each candidate keeps
        the larger statistic of the two, and its number of tests is the sum (the
        significance level is divided by it — a sup-score over the expansion points).
        The profile look scores at their nuisance values (a lag's time constant).
    keep : frozenset of str
        Candidates whose ``previous`` score is kept as it is, not scored again (those
        already refitted in the iteration: a larger statistic would not refit them again).

    Returns
    -------
    list of CandidateScore
    """
    projector = Projector(None if base.jacobian is None else base.jacobian[base.keep])
    values = dict(params.values)
    before = {c.effect: c for c in previous or []}
    scores = []
    desc = {"zero": "score effects", "profile": "profile effect strengths"}.get(
        expansion, f"score effects at {expansion} strength"
    )
    fresh = [n for n in candidates if not (n in before and n in keep)]
    for name in tqdm(candidates, desc=desc, unit="effect", disable=not progress):
        old = before.get(name)
        if old is not None and name in keep:
            scores.append(old)
            continue
        if expansion == "zero" and name in fresh[:-1]:  # the next one compiles meanwhile
            _compile_ahead(model, fresh[fresh.index(name) + 1], traces, fit)
        hint = old.nuisance if old is not None and expansion == "profile" else None
        new = score_effect(
            name, model, values, traces, base, projector, fit, probe_fraction, expansion, hint
        )
        if old is not None:
            n_tests = old.n_tests + new.n_tests
            keep_new = new.status == "scored" and (
                old.status != "scored" or new.statistic > old.statistic
            )
            diverged = _merged(old.diverged, new.diverged)
            new = new if keep_new else old
            new.n_tests, new.diverged = n_tests, diverged
        scores.append(new)
    level = alpha / max(len(candidates), 1)
    for s in scores:
        s.significant = (
            s.status == "scored" and s.p_value < level / s.n_tests and s.share >= min_share
        )
    scores.sort(key=lambda s: (-s.statistic, s.effect))
    return scores
