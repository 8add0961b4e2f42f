"""IPOPT on the fit problem with a Gauss–Newton Hessian.

``min ½‖r(z)‖²  s.t.  g(z) = 0, z_lo ≤ z ≤ z_hi``. Residuals and constraints come
from :class:`FitProblem` through CasADi callbacks; the Hessian of the Lagrangian
is replaced by ``σ JᵀJ`` (generalized Gauss–Newton; the constraint curvature is
dropped, as in constrained Gauss–Newton for multiple shooting).
"""

from __future__ import annotations

import math
import signal
import threading
import time

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .problem import FitProblem

__all__ = [
    "BREAKDOWN_STATUSES",
    "COST_PLATEAU",
    "ITERATION_LIMIT",
    "WALL_TIME_LIMIT",
    "BestIterate",
    "CostPlateau",
    "IterationDeadline",
    "SigintLatch",
    "solve_ipopt",
]

#: IPOPT's return status at its iteration limit, and at its wall-time limit (also what a
#: stop by this module's deadline, or a stage not started for time, reports).
ITERATION_LIMIT = "Maximum_Iterations_Exceeded"
WALL_TIME_LIMIT = "Maximum_WallTime_Exceeded"

#: The status of a solve stopped by :class:`CostPlateau`: its cost had stopped moving.
COST_PLATEAU = "Cost_Plateau"

#: IPOPT return statuses of a solver that broke down, as against one that converged or
#: stopped at one of its limits (iterations, time, a step too small to matter).
BREAKDOWN_STATUSES: tuple[str, ...] = (
    "Error_In_Step_Computation",
    "Restoration_Failed",
    "Invalid_Number_Detected",
    "Diverging_Iterates",
    "Unrecoverable_Exception",
    "NonIpopt_Exception_Thrown",
    "Internal_Error",
    "Insufficient_Memory",
)

#: IPOPT's status when :class:`IterationDeadline` stopped it; reported as the wall-time limit.
_USER_STOP = "User_Requested_Stop"


def _sparsity(m: sp.csc_matrix) -> ca.Sparsity:
    m = sp.csc_matrix(m)
    return ca.Sparsity(m.shape[0], m.shape[1], m.indptr.tolist(), m.indices.tolist())


def _dm(m: sp.csc_matrix, pattern: sp.csc_matrix) -> ca.DM:
    """``m`` as a CasADi matrix on ``pattern``'s sparsity (both built from the same COO)."""
    m = sp.csc_matrix(m)
    if m.nnz != pattern.nnz or not np.array_equal(m.indices, pattern.indices):
        m = (m + 0 * pattern).tocsc()  # align to the pattern (explicit zeros where absent)
        m.sort_indices()
    return ca.DM(_sparsity(pattern), m.data)


class _Vec(ca.Callback):
    """``z -> r(z)`` or ``z -> g(z)`` with a Jacobian callback."""

    def __init__(self, name, problem: FitProblem, which: str, n_out: int, pattern):
        ca.Callback.__init__(self)
        self.problem, self.which, self.n_out, self.pattern = problem, which, n_out, pattern
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 1

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.problem.n_z, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(self.n_out, 1)

    def eval(self, arg):
        out = self.problem.evaluate(np.asarray(arg[0]).ravel(), False)
        return [ca.DM(out[self.which])]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _Jac(name, self.problem, self.which, self.n_out, self.pattern, opts)
        return self._jac


class _Jac(ca.Callback):
    def __init__(self, name, problem, which, n_out, pattern, opts):
        ca.Callback.__init__(self)
        self.problem, self.which, self.n_out, self.pattern = problem, which, n_out, pattern
        self.key = "J" if which == "r" else "Jg"
        self.construct(name, opts)

    def get_n_in(self):
        return 2

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        n = self.problem.n_z if i == 0 else self.n_out
        return ca.Sparsity.dense(n, 1)

    def get_sparsity_out(self, i):
        return _sparsity(self.pattern)

    def eval(self, arg):
        out = self.problem.evaluate(np.asarray(arg[0]).ravel(), True)
        m = out.get(self.key)
        if m is None:  # diverged: NaN Jacobian, IPOPT backtracks
            return [ca.DM(_sparsity(self.pattern), np.full(self.pattern.nnz, np.nan))]
        return [_dm(m, self.pattern)]


class IterationDeadline:
    """Stop the solver before an iteration it cannot finish by ``deadline``.

    Called at the end of every iteration (the first call ends the initialization): the
    next iteration is predicted to take as long as the last one, and the solver stops
    when it would end after ``deadline`` (a :func:`time.perf_counter` time, s).
    """

    def __init__(self, deadline: float, clock=time.perf_counter):
        self.deadline, self.clock = deadline, clock
        self.last = clock()
        self.stopped = False

    def should_stop(self) -> bool:
        """True when the next iteration, as long as the last, would end after the deadline."""
        now = self.clock()
        step, self.last = now - self.last, now
        self.stopped = now + step > self.deadline
        return self.stopped


class BestIterate:
    """The accepted iterate of lowest objective seen so far (IPOPT's iteration 0 = the start).

    IPOPT returns its last iterate, which after a breakdown (``Error_In_Step_Computation``)
    or at a limit can be far above an earlier one: a regulator-lag refit of a discovery
    returned 34 574 bar² from a start at 3 757 (session 32). Only meaningful without
    equality constraints (single shooting), where every iterate is a feasible model.
    """

    def __init__(self):
        self.f, self.x, self.k, self.count = math.inf, None, -1, 0

    def offer(self, f: float, x: np.ndarray) -> None:
        """Record iterate number ``self.count`` with objective ``f`` at ``x``."""
        if math.isfinite(f) and f < self.f:
            self.f, self.x, self.k = f, np.array(x, dtype=float), self.count
        self.count += 1

    def choose(
        self, z_last: np.ndarray, f_last: float, z0: np.ndarray
    ) -> tuple[np.ndarray, int | None]:
        """The iterate to return and its number (None: the solver's last one, which is
        at least as good as every other); iteration 0 is IPOPT's start pushed off its
        bounds, for which the start ``z0`` itself is returned."""
        if self.x is None or self.f >= f_last:  # also False for a NaN last objective
            return z_last, None
        return (np.array(z0, dtype=float) if self.k == 0 else self.x), self.k


class CostPlateau:
    """Stop a solver whose cost has stopped moving: its last ``n_iter + 1`` accepted costs
    all lie within ``rtol`` (relative) of each other.

    IPOPT's own early stop (its acceptable level) also asks for a small optimality error,
    which a cost with kinks (friction, metering edges, latch snaps) never reaches: its
    Gauss–Newton steps are cut back over and over while the cost moves in its sixth digit,
    until a time or iteration limit (a zoo pre-fit, session 37: 1367.49 → 1367.42 bar² over
    26 iterations, 8 backtracks each, dual infeasibility 5–30). The test is on the current
    cost, not the best: a solver that went uphill and is falling back (977 → 1844 → … →
    1074) is not on a plateau although its best has not moved.

    Parameters
    ----------
    n_iter : int
        Iterations over which the cost must stay flat (≥ 1).
    rtol : float
        Relative spread of those costs below which the solver stops.
    """

    def __init__(self, n_iter: int, rtol: float):
        self.n_iter, self.rtol = int(n_iter), float(rtol)
        self.costs: list[float] = []
        self.stopped = False

    def should_stop(self, f: float) -> bool:
        """Record the cost of one more accepted iterate; True on a plateau."""
        self.costs.append(f)
        last = self.costs[-1 - self.n_iter :]
        if len(last) <= self.n_iter or not all(math.isfinite(c) for c in last):
            return False
        self.stopped = max(last) - min(last) <= self.rtol * abs(min(last))
        return self.stopped


class SigintLatch:
    """Ctrl-C during a solve as a flag: the solver stops at its next iteration, then the
    caller raises :class:`KeyboardInterrupt`.

    IPOPT calls back into Python; a ``KeyboardInterrupt`` raised inside a callback is caught
    by CasADi and reported as ``NonIpopt_Exception_Thrown``, which a fit would take for a
    stop at a limit and hand back as its result. A second Ctrl-C interrupts at once. Only
    the main thread can hold signal handlers; elsewhere this does nothing. Nor does it
    where SIGINT is ignored (a job started with ``nohup`` or in the background of a
    script): what the caller chose stays in force.
    """

    def __init__(self):
        self.hit = False
        self._previous = None

    def _on_sigint(self, signum, frame):
        if self.hit:
            raise KeyboardInterrupt
        self.hit = True

    def __enter__(self) -> SigintLatch:
        if threading.current_thread() is threading.main_thread():
            if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
                self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc) -> bool:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False


class _StopCallback(ca.Callback):
    """IPOPT's iteration callback around an :class:`IterationDeadline` and an optional
    :class:`CostPlateau` (1 = stop); it also hands every iterate to a
    :class:`BestIterate`."""

    def __init__(
        self,
        n_x: int,
        n_g: int,
        deadline: IterationDeadline,
        best: BestIterate,
        plateau: CostPlateau | None = None,
        latch: SigintLatch | None = None,
    ):
        ca.Callback.__init__(self)
        self.n_x, self.n_g, self.deadline, self.best = n_x, n_g, deadline, best
        self.plateau, self.latch = plateau, latch
        self.construct("iteration_deadline", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = {"f": 1, "x": self.n_x, "lam_x": self.n_x, "g": self.n_g, "lam_g": self.n_g}
        k = n.get(ca.nlpsol_out(i))
        return ca.Sparsity.dense(k) if k is not None else ca.Sparsity(0, 0)

    def eval(self, arg):
        names = [ca.nlpsol_out(i) for i in range(ca.nlpsol_n_out())]
        f = float(arg[names.index("f")])
        self.best.offer(f, np.asarray(arg[names.index("x")]).ravel())
        late = self.deadline.should_stop()
        flat = self.plateau is not None and self.plateau.should_stop(f)
        interrupted = self.latch is not None and self.latch.hit
        return [1 if late or flat or interrupted else 0]


def solve_ipopt(
    problem: FitProblem,
    z0: np.ndarray,
    lbz: np.ndarray,
    ubz: np.ndarray,
    max_iter: int,
    tol: float,
    time_limit_s: float,
    extra: dict | None = None,
    reg: float = 1e-6,
    plateau: tuple[int, float] | None = None,
):
    """Solve; return ``(z, stats)`` where stats has IPOPT's return status and iterations.

    Without continuity constraints ``z`` is the accepted iterate of lowest objective
    (:class:`BestIterate`; ``stats["best_iter"]`` its number, 0 = the start ``z0`` itself),
    not IPOPT's last one; with them (multiple shooting) it is IPOPT's last iterate, whose
    constraints the solver has balanced against the objective.

    ``time_limit_s`` is IPOPT's wall limit, and no iteration is started that would end
    after it (:class:`IterationDeadline`; reported as ``Maximum_WallTime_Exceeded``).

    ``plateau = (n_iter, rtol)`` also stops the solver when its last ``n_iter + 1`` costs
    lie within ``rtol`` (relative) of each other (:class:`CostPlateau`;
    reported as ``Cost_Plateau``). Single shooting only: a multiple-shooting iterate is
    not a model, so its cost alone says nothing about convergence.

    Ctrl-C stops the solver at its next iteration and raises :class:`KeyboardInterrupt`
    (:class:`SigintLatch`), instead of ending as a solve stopped at a limit.

    ``reg`` (bar² per unit of z²) is a small Levenberg damping added to the Gauss–Newton
    Hessian so that directions the residuals do not see (the fast states of a
    segment's initial state) cannot take huge steps.
    """
    j_pattern = sp.csc_matrix(
        (np.ones(len(problem.j_rows)), (problem.j_rows, problem.j_cols)),
        shape=(problem.n_r, problem.n_z),
    )
    g_pattern = sp.csc_matrix(
        (np.ones(len(problem.g_rows)), (problem.g_rows, problem.g_cols)),
        shape=(problem.n_g, problem.n_z),
    )
    keep = []
    z = ca.MX.sym("z", problem.n_z)
    r_fn = _Vec("residuals", problem, "r", problem.n_r, j_pattern)
    keep.append(r_fn)
    r = r_fn(z)
    nlp = {"x": z, "f": 0.5 * ca.sumsqr(r)}
    if problem.n_g:
        g_fn = _Vec("continuity", problem, "g", problem.n_g, g_pattern)
        keep.append(g_fn)
        nlp["g"] = g_fn(z)
    jr = ca.jacobian(r, z)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", problem.n_g)
    hess = ca.Function(
        "gauss_newton_hessian",
        [z, ca.MX.sym("p", 0), lam_f, lam_g],
        [ca.triu(lam_f * (jr.T @ jr + reg * ca.MX.eye(problem.n_z)))],
        ["x", "p", "lam_f", "lam_g"],
        ["triu_hess_gamma_x_x"],
    )
    deadline = IterationDeadline(time.perf_counter() + time_limit_s)
    best = BestIterate()
    flat = CostPlateau(*plateau) if plateau is not None and not problem.n_g else None
    latch = SigintLatch()
    stop = _StopCallback(problem.n_z, problem.n_g, deadline, best, flat, latch)
    keep.append(stop)
    opts = {
        "hess_lag": hess,
        "iteration_callback": stop,
        "print_time": False,
        "ipopt": {
            "max_iter": max_iter,
            "tol": tol,
            "acceptable_tol": 1e-2,
            "acceptable_obj_change_tol": 1e-4,
            "acceptable_iter": 3,
            "max_wall_time": time_limit_s,
            "print_level": 0,
            "sb": "yes",
            "mu_strategy": "adaptive",
            **(extra or {}),
        },
    }
    solver = ca.nlpsol("physics_fit", "ipopt", nlp, opts)
    args = {"x0": z0, "lbx": lbz, "ubx": ubz}
    if problem.n_g:
        args |= {"lbg": 0.0, "ubg": 0.0}
    with latch:
        sol = solver(**args)
    if latch.hit:
        raise KeyboardInterrupt("the fit was interrupted (Ctrl-C)")
    stats = solver.stats()
    status = stats.get("return_status", "?")
    if status == _USER_STOP and deadline.stopped:
        status = WALL_TIME_LIMIT
    elif status == _USER_STOP and flat is not None and flat.stopped:
        status = COST_PLATEAU
    z, best_iter = np.asarray(sol["x"]).ravel(), None
    if not problem.n_g:
        z, best_iter = best.choose(z, float(sol["f"]), z0)
    return z, {
        "return_status": status,
        "iter_count": int(stats.get("iter_count", -1)),
        "success": bool(stats.get("success", False)),
        "best_iter": best_iter,
    }
