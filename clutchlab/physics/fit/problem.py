"""The fit as a least-squares problem: residuals, continuity constraints and their Jacobians.

Decision vector ``z`` (all scaled): shared free parameters, per-experiment
parameters, then (multiple shooting) the initial state of every segment.
Parameters enter through ``θ = θ₀·exp(z)`` (log transform) or ``θ = θ₀ + s·z``
(linear); the chain rule ``dθ/dz`` is folded into the sensitivity seeds, so the
integrator returns derivatives with respect to ``z`` directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...data import Trace, dither_period_samples
from ...errors import FitError, SimulationError
from ..assembly import MODEL_INPUTS
from ..inputs import choose_drive, input_matrix
from ..model import CircuitModel
from ..parameters import Parameter, ParameterSet
from ..settings import SimulationSettings
from ..simulate import initial_state, simulate_inputs
from .sensitivity import SENSITIVITY_CHUNK, sensitivity_chunk, simulate_sensitivities
from .settings import FitSettings

__all__ = ["FitProblem"]

_K_FREQ = [s.name for s in MODEL_INPUTS].index("dither_freq_Hz")


def _period_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Centered ``n``-sample moving average (edges: shorter windows) — the same integer
    window as the residuals use, so target and prediction see one operator."""
    x = np.asarray(x, dtype=float)
    if n <= 1:
        return x.copy()
    a = n // 2
    cs = np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x, axis=0)])
    idx = np.arange(len(x))
    lo = np.clip(idx - a, 0, len(x))
    hi = np.clip(idx - a + n, 0, len(x))
    w = (hi - lo).reshape(-1, *([1] * (x.ndim - 1)))
    return (cs[hi] - cs[lo]) / w


@dataclass
class _Segment:
    exp: int
    start: int  # first sample (trace index)
    stop: int  # last sample (inclusive)
    rows: np.ndarray  # residual sample indices (trace index)
    row0: int  # first global residual row
    cols: np.ndarray  # global z column of each local direction
    state_cols: slice | None  # global columns of its initial state (multiple shooting)


@dataclass
class _Experiment:
    name: str
    t: np.ndarray
    u: np.ndarray
    drive: str
    target: np.ndarray  # period-mean (or raw) measured pressure, bar
    n_period: int
    x0: np.ndarray  # settled initial state at the start parameters
    settle_t: np.ndarray
    settle_u: np.ndarray
    keep: np.ndarray  # samples whose residual enters the objective


def snap_mask(target: np.ndarray, t: np.ndarray, rate_bar_s: float, guard_s: float) -> np.ndarray:
    """False within ``guard_s`` of samples where the measured (period-mean) pressure moves
    faster than ``rate_bar_s`` — the latch snaps — True elsewhere."""
    keep = np.ones(len(t), dtype=bool)
    if guard_s <= 0 or len(t) < 3:
        return keep
    fast = np.abs(np.gradient(target, t)) > rate_bar_s
    if fast.any():
        dt = float(np.median(np.diff(t)))
        w = max(round(guard_s / dt), 0)
        keep &= ~(np.convolve(fast.astype(float), np.ones(2 * w + 1), mode="same") > 0)
    return keep


class FitProblem:
    """Residuals ``r(z)``, constraints ``g(z) = 0`` and their sparse Jacobians.

    Parameters
    ----------
    model : CircuitModel
        The model to fit (any effects switched on).
    traces : list of Trace
        Training experiments.
    free : tuple of str
        Free parameter names.
    settings : FitSettings
        Method, segments, objective, decimation.
    start : ParameterSet
        Parameter values at ``z = 0`` for the free ones, and the fixed values.
    """

    def __init__(
        self,
        model: CircuitModel,
        traces: list[Trace],
        free: tuple[str, ...],
        settings: FitSettings,
        start: ParameterSet,
    ) -> None:
        self.model, self.settings, self.start = model, settings, start
        specs = {p.name: p for p in model.parameters}
        self.free = tuple(free)
        self.shared = tuple(n for n in free if n not in settings.per_experiment)
        self.per_exp = tuple(n for n in free if n in settings.per_experiment)
        self.specs: list[Parameter] = [specs[n] for n in free]
        self.names = [p.name for p in model.parameters]
        self.sim = SimulationSettings(
            substeps=settings.substeps, settle_s=settings.settle_s, drive=settings.drive
        )
        self.ms = settings.method == "multiple_shooting"
        self.experiments = [self._prepare(tr) for tr in traces]
        self.nx = model.functions(self.experiments[0].drive).nx
        self._layout()
        self._cache: dict[bytes, dict] = {}
        self.n_evals = 0
        self.n_jac_evals = 0
        self.on_jacobian = None  # progress hook: called with (cost) on each new Jacobian
        self._pool = None

    # ---- parameter transform --------------------------------------------------------
    def bounds_z(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the parameter part of ``z`` (per-experiment blocks repeated)."""
        lo, hi = [], []
        for name in self.shared + self.per_exp * len(self.experiments):
            p = self.specs[self.free.index(name)]
            lb, ub = self.settings.bounds.get(name, (p.lower, p.upper))
            th0 = self.start[name]
            if p.transform == "log":
                lo.append(math.log(lb / th0))
                hi.append(math.log(ub / th0))
            else:
                lo.append((lb - th0) / p.scale)
                hi.append((ub - th0) / p.scale)
        return np.array(lo), np.array(hi)

    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the segment-state part of ``z``: the latch opening in [0, 1]."""
        lo = np.full(self.n_z - self.n_par, -np.inf)
        hi = np.full(self.n_z - self.n_par, np.inf)
        names = [s.name for s in self.model.functions(self.experiments[0].drive).states]
        for s in self.segments:
            if s.state_cols is not None and "latch" in names:
                k = s.state_cols.start - self.n_par + names.index("latch")
                lo[k], hi[k] = -0.02, 1.02
        return lo, hi

    def _theta(self, name: str, z: float) -> tuple[float, float]:
        p = self.specs[self.free.index(name)]
        th0 = self.start[name]
        if p.transform == "log":
            th = th0 * math.exp(z)
            return min(max(th, p.lower), p.upper), th  # clip: exp(log(b)) may round past b
        return min(max(th0 + p.scale * z, p.lower), p.upper), p.scale

    def params_of(self, z: np.ndarray, exp: int) -> tuple[np.ndarray, dict[str, float]]:
        """Parameter vector (model order) of experiment ``exp`` and its free values."""
        values = {}
        for k, name in enumerate(self.shared):
            values[name] = self._theta(name, z[k])[0]
        base = len(self.shared) + exp * len(self.per_exp)
        for k, name in enumerate(self.per_exp):
            values[name] = self._theta(name, z[base + k])[0]
        vec = self.start.vector().copy()
        for name, v in values.items():
            vec[self.names.index(name)] = v
        return vec, values

    def parameter_set(self, z: np.ndarray, exp: int = 0) -> ParameterSet:
        """The fitted values as a ParameterSet (shared + this experiment's own)."""
        return self.start.replace(**self.params_of(z, exp)[1])

    # ---- data -----------------------------------------------------------------------
    def _prepare(self, trace: Trace) -> _Experiment:
        drive = choose_drive(trace, self.sim)
        u = input_matrix(trace, drive, self.sim)
        y = np.asarray(trace.get("clutch_pressure_bar"), dtype=float)
        period = round(dither_period_samples(trace))
        n = period if self.settings.objective == "period_mean" else 1
        dt = float(np.median(np.diff(trace.time_s)))
        ns = max(2, round(self.settings.settle_s / dt) + 1)
        su = np.repeat(u[:1], ns, axis=0)
        k_phase = [s.name for s in MODEL_INPUTS].index("dither_phase")
        su[:, k_phase] = u[0, k_phase] + u[0, _K_FREQ] * dt * (np.arange(ns) - (ns - 1))
        st = trace.time_s[0] + dt * (np.arange(ns) - (ns - 1))
        target = _period_mean(y, n)
        return _Experiment(
            trace.name,
            np.asarray(trace.time_s, float),
            u,
            drive,
            target,
            n,
            np.zeros(0),
            st,
            su,
            snap_mask(
                target, trace.time_s, self.settings.snap_rate_bar_s, self.settings.snap_guard_s
            ),
        )

    def _layout(self) -> None:
        n_par = len(self.shared) + len(self.per_exp) * len(self.experiments)
        col = n_par
        self.segments: list[_Segment] = []
        row = 0
        dec = self.settings.decimate
        for e, ex in enumerate(self.experiments):
            n = len(ex.t)
            if self.ms:
                bounds = _quiet_boundaries(ex.target, ex.t, self.settings.segment_s)
            else:
                bounds = [0, n - 1]
            a = ex.n_period // 2
            tail = ex.n_period - 1 - a
            for j in range(len(bounds) - 1):
                start, stop = bounds[j], bounds[j + 1]
                last = j == len(bounds) - 2
                lo = start + a
                hi = (stop if last else stop - 1) - tail
                rows = np.arange(lo - lo % dec + (dec if lo % dec else 0), hi + 1, dec)
                rows = rows[ex.keep[rows]]
                own = len(self.shared) + e * len(self.per_exp) + np.arange(len(self.per_exp))
                par_cols = np.concatenate([np.arange(len(self.shared)), own]).astype(int)
                if self.ms and j > 0:  # the first segment starts from the settled state
                    sc = slice(col, col + self.nx)
                    col += self.nx
                    cols = np.concatenate([np.arange(sc.start, sc.stop), par_cols])
                else:
                    sc, cols = None, par_cols
                self.segments.append(_Segment(e, start, stop, rows, row, cols, sc))
                row += len(rows)
        self.n_par, self.n_z, self.n_r = n_par, col, row
        self.continuity = [
            (a_, b_)
            for a_, b_ in zip(self.segments[:-1], self.segments[1:], strict=True)
            if a_.exp == b_.exp
        ]
        self.n_g = self.nx * len(self.continuity)
        self._sparsity()

    def _sparsity(self) -> None:
        rows, cols = [], []
        for s in self.segments:
            r = np.repeat(np.arange(s.row0, s.row0 + len(s.rows)), len(s.cols))
            rows.append(r)
            cols.append(np.tile(s.cols, len(s.rows)))
        self.j_rows = np.concatenate(rows) if rows else np.zeros(0, int)
        self.j_cols = np.concatenate(cols) if cols else np.zeros(0, int)
        grow, gcol = [], []
        for k, (a, b) in enumerate(self.continuity):
            base = k * self.nx
            grow.append(np.repeat(np.arange(base, base + self.nx), len(a.cols)))
            gcol.append(np.tile(a.cols, self.nx))
            grow.append(np.arange(base, base + self.nx))
            gcol.append(np.arange(b.state_cols.start, b.state_cols.stop))
        self.g_rows = np.concatenate(grow) if grow else np.zeros(0, int)
        self.g_cols = np.concatenate(gcol) if gcol else np.zeros(0, int)

    # ---- initial guess ----------------------------------------------------------------
    def initial_z(self, z_par: np.ndarray | None = None) -> np.ndarray:
        """Start vector: parameters ``z_par`` (0 = start values); segment states simulated."""
        z = np.zeros(self.n_z)
        if z_par is not None:
            z[: self.n_par] = z_par
        for e, ex in enumerate(self.experiments):
            p = self.params_of(z, e)[0]
            ps = ParameterSet.from_vector(self.model.parameters, p)
            fns = self.model.functions(ex.drive)
            try:
                x0, _ = simulate_inputs(
                    self.model,
                    ps,
                    ex.settle_t,
                    ex.settle_u,
                    ex.drive,
                    self.sim,
                    x0=initial_state(fns, ex.u[0]),
                )
                ex.x0 = x0[-1]
                if self.ms:
                    xs, _ = simulate_inputs(
                        self.model, ps, ex.t, ex.u, ex.drive, self.sim, x0=ex.x0
                    )
            except SimulationError as exc:
                raise FitError(
                    f"{ex.name}: the integrator diverges at the start parameters ({exc})"
                ) from exc
            if self.ms:
                for s in self.segments:
                    if s.exp == e and s.state_cols is not None:
                        z[s.state_cols] = xs[s.start]
        return z

    # ---- evaluation -------------------------------------------------------------------
    def _segment_x0_t_u(self, s: _Segment, z: np.ndarray):
        ex = self.experiments[s.exp]
        t, u = ex.t[s.start : s.stop + 1], ex.u[s.start : s.stop + 1]
        if s.state_cols is not None:
            return z[s.state_cols], t, u, 0
        fns = self.model.functions(ex.drive)
        t = np.concatenate([ex.settle_t[:-1] - ex.settle_t[-1] + t[0], t])
        u = np.concatenate([ex.settle_u[:-1], u])
        return initial_state(fns, ex.u[0]), t, u, len(ex.settle_t) - 1

    def segment_results(self, z: np.ndarray, jacobian: bool, ids) -> dict[int, tuple] | None:
        """Per segment id: (residuals, residual Jacobian block or None, end state, end
        sensitivities or None). None when the integrator diverges."""
        out = {}
        for si in ids:
            s = self.segments[si]
            ex = self.experiments[s.exp]
            p, _ = self.params_of(z, s.exp)
            x0, t, u, off = self._segment_x0_t_u(s, z)
            try:
                if jacobian:
                    nd = len(s.cols)
                    s0 = np.zeros((self.nx, nd))
                    e = np.zeros((len(p), nd))
                    first = self.nx if s.state_cols is not None else 0
                    if first:
                        s0[:, :first] = np.eye(first)
                    local_names = self.shared + self.per_exp
                    for k, c in enumerate(s.cols[first:]):
                        name = local_names[k]
                        e[self.names.index(name), first + k] = self._theta(name, z[c])[1]
                    run = simulate_sensitivities(
                        self.model, ex.drive, self.settings.substeps, t, u, p, x0, s0, e
                    )
                    y, dy, x_end, s_end = run.y[off:], run.dy[off:], run.x[-1], run.s_end
                else:
                    ps = ParameterSet.from_vector(self.model.parameters, p)
                    xs, ys = simulate_inputs(self.model, ps, t, u, ex.drive, self.sim, x0=x0)
                    y, dy, x_end, s_end = ys[off:, 0], None, xs[-1], None
            except SimulationError:
                return None
            loc = s.rows - s.start
            res = _window_mean(y, ex.n_period, loc) - ex.target[s.rows]
            block = _window_mean(dy, ex.n_period, loc) if jacobian else None
            out[si] = (res, block, x_end, s_end)
        return out

    def evaluate(self, z: np.ndarray, jacobian: bool) -> dict:
        """Residuals, constraints (and Jacobians) at ``z``; cached by ``z``."""
        z = np.asarray(z, dtype=float).ravel()
        key = z.tobytes()
        hit = self._cache.get(key)
        if hit is not None and (not jacobian or "J" in hit):
            return hit
        parts = self._run_segments(z, jacobian)
        ok = parts is not None
        r = np.full(self.n_r, np.nan)
        g = np.full(self.n_g, np.nan)
        jv, gv = [], []
        if ok:
            for si, s in enumerate(self.segments):
                res, block, _, _ = parts[si]
                r[s.row0 : s.row0 + len(res)] = res
                if jacobian:
                    jv.append(block.ravel())
            for k, (a, b) in enumerate(self.continuity):
                _, _, x_end, s_end = parts[self.segments.index(a)]
                g[k * self.nx : (k + 1) * self.nx] = z[b.state_cols] - x_end
                if jacobian:
                    gv.append((-s_end).ravel())
                    gv.append(np.ones(self.nx))
        out = {"r": r, "g": g, "ok": ok}
        if jacobian and ok:
            out["J"] = sp.csc_matrix(
                (np.concatenate(jv), (self.j_rows, self.j_cols)), shape=(self.n_r, self.n_z)
            )
            out["Jg"] = sp.csc_matrix(
                (np.concatenate(gv) if gv else np.zeros(0), (self.g_rows, self.g_cols)),
                shape=(self.n_g, self.n_z),
            )
            self.n_jac_evals += 1
            if self.on_jacobian is not None:
                self.on_jacobian(0.5 * float(np.dot(r, r)))
        elif jacobian:
            out["J"] = None
        self.n_evals += 1
        if len(self._cache) > 6:
            self._cache.pop(next(iter(self._cache)))
        self._cache[key] = out
        return out

    # ---- parallel evaluation ------------------------------------------------------------
    def _run_segments(self, z: np.ndarray, jacobian: bool) -> dict[int, tuple] | None:
        if self._pool is None:
            return self.segment_results(z, jacobian, range(len(self.segments)))
        futures = [self._pool.submit(_worker_results, z, jacobian, ids) for ids in self._shares]
        parts: dict[int, tuple] = {}
        for f in futures:
            res = f.result()
            if res is None:
                return None
            parts.update(res)
        return parts

    def _jacobian_code(self) -> list[tuple[str, int]]:
        """(drive, directions) of every sensitivity code the Jacobian evaluations call."""
        return sorted({(self.experiments[s.exp].drive, len(s.cols)) for s in self.segments})

    def compile_jacobian_code(self) -> None:
        """Compile (or load from the cache) the Jacobian's sensitivity code in this process.

        Called before :meth:`start_workers` forks: the workers then load one cached library
        instead of each compiling the same code at once on first use (a build started in
        the background is waited for).
        """
        for drive, nd in self._jacobian_code():
            sensitivity_chunk(self.model, drive, self.settings.substeps, nd, SENSITIVITY_CHUNK)

    def start_workers(self, traces: list[Trace], workers: int) -> None:
        """Evaluate segments in ``workers`` processes (experiments balanced by length)."""
        self._pool = None
        if workers <= 1 or len(self.experiments) < 2:
            return
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        # fork: no re-import of the caller's script (spawn would re-run an unguarded main).
        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        loads = [0] * workers
        shares: list[list[int]] = [[] for _ in range(workers)]
        for e in np.argsort([-len(ex.t) for ex in self.experiments]):
            w = int(np.argmin(loads))
            loads[w] += len(self.experiments[e].t)
            shares[w] += [i for i, s in enumerate(self.segments) if s.exp == e]
        self._shares = [sorted(s) for s in shares if s]
        # forked workers inherit this problem as it is (no rebuild of the model and the
        # experiments: ~0.5 s per worker on the default training set); spawned ones
        # rebuild it from a picklable description
        spec = (
            self
            if method == "fork"
            else (
                list(self.model.effect_names),
                [
                    (t.name, {k: np.asarray(v) for k, v in t.signals.items()}, dict(t.meta))
                    for t in traces
                ],
                self.free,
                self.settings,
                dict(self.start.values),
            )
        )
        self._pool = ProcessPoolExecutor(
            len(self._shares),
            mp_context=mp.get_context(method),
            initializer=_worker_init,
            initargs=(spec,),
        )

    def close(self) -> None:
        """Stop the worker processes."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def cost(self, z: np.ndarray) -> float:
        """½‖r‖² at ``z`` (inf where the model diverges)."""
        r = self.evaluate(z, False)["r"]
        return 0.5 * float(np.dot(r, r)) if np.all(np.isfinite(r)) else math.inf


def _quiet_boundaries(target: np.ndarray, t: np.ndarray, segment_s: float) -> list[int]:
    """Segment boundaries about ``segment_s`` apart, each placed where the measured
    (period-mean) pressure changes least within ±25 % of the nominal spacing — never
    inside a latch snap, where sensitivities to the segment state explode."""
    n = len(t)
    dt = float(t[1] - t[0])
    seg_n = max(round(segment_s / dt), 10)
    rate = np.abs(np.gradient(target))
    bounds = [0]
    nominal = seg_n
    while nominal < n - seg_n // 2:
        lo, hi = (
            max(bounds[-1] + seg_n // 2, nominal - seg_n // 4),
            min(n - 2, nominal + seg_n // 4),
        )
        k = lo + int(np.argmin(rate[lo : hi + 1])) if hi > lo else nominal
        bounds.append(k)
        nominal = k + seg_n
    bounds.append(n - 1)
    return bounds


def _window_mean(y: np.ndarray, n: int, loc: np.ndarray) -> np.ndarray:
    """Mean of ``y`` over the ``n``-sample window centred at each index of ``loc`` (axis 0)."""
    if n <= 1:
        return y[loc]
    a = n // 2
    cs = np.concatenate([np.zeros((1, *y.shape[1:])), np.cumsum(y, axis=0)])
    return (cs[loc - a + n] - cs[loc - a]) / n


_WORKER: FitProblem | None = None


def _worker_init(spec) -> None:
    """This worker's copy of the problem: the parent's own (fork), or rebuilt (spawn)."""
    global _WORKER
    if isinstance(spec, FitProblem):
        _WORKER = spec
        return
    effects, traces, free, settings, start = spec
    model = CircuitModel().with_effects(*effects)
    traces = [Trace(name, signals, meta=meta) for name, signals, meta in traces]
    _WORKER = FitProblem(model, traces, free, settings, model.params(**start))


def _worker_results(z, jacobian, ids):
    return _WORKER.segment_results(z, jacobian, ids)
