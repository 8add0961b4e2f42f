"""Benchmark: one residual and one Jacobian evaluation of the physics fit, in one process.

What every fit, refit and discovery step pays per iteration: the forward simulation of the
training experiments (residuals) and their forward sensitivities (Jacobian), on the default
stand's training set (fast + slow ramps), the fit's default free parameters, at the start
values. Anchor: the same evaluations with the compiled chunks called the plain CasADi way
(``fn(*args)``: DM conversion of every argument and result), measured in the same run —
the path :class:`clutchlab.physics.dense_call.DenseCall` replaced. Also checks that both
paths give bitwise the same residuals and Jacobian, and prints the time per sample and
direction and the ratio to the data's duration (real time).

Usage: ``python benchmarks/bench_jacobian.py [--data STAND] [--runs 3]``
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import statistics
import time
from contextlib import contextmanager

import numpy as np

from clutchlab.data import load_dataset
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import DEFAULT_FREE, FitSettings
from clutchlab.physics.fit.problem import FitProblem
from clutchlab.physics.stand import StandConfig, run_stand

# the modules themselves (the package re-exports a function named ``simulate``)
sensitivity_module = importlib.import_module("clutchlab.physics.fit.sensitivity")
simulate_module = importlib.import_module("clutchlab.physics.simulate")


class _PlainCall:
    """The call before DenseCall: ``fn(*args)`` with CasADi's conversions."""

    def __init__(self, fn) -> None:
        self.fn, self.fixed = fn, {}

    def fix(self, **args) -> None:
        self.fixed.update(args)

    def __call__(self, **args):
        given = {**self.fixed, **args}
        ordered = [given[self.fn.name_in(i)] for i in range(self.fn.n_in())]
        return [np.asarray(v) for v in self.fn(*ordered)]


@contextmanager
def _plain_calls():
    saved = sensitivity_module.DenseCall, simulate_module.DenseCall
    sensitivity_module.DenseCall = simulate_module.DenseCall = _PlainCall
    try:
        yield
    finally:
        sensitivity_module.DenseCall, simulate_module.DenseCall = saved


def _timed(problem: FitProblem, z: np.ndarray, jacobian: bool) -> tuple[float, dict]:
    problem._cache.clear()  # time the evaluation, not the cache
    t0 = time.perf_counter()
    out = problem.evaluate(z, jacobian)
    return time.perf_counter() - t0, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", help="stand dataset (default: the default stand, generated)")
    ap.add_argument("--runs", type=int, default=3, help="evaluations of each kind and path")
    args = ap.parse_args()
    data = (
        load_dataset(args.data) if args.data else run_stand(StandConfig(), progress=False).dataset
    )
    train = list(data.select(ramps=["fast", "slow"]))
    model = CircuitModel()
    problem = FitProblem(model, train, tuple(DEFAULT_FREE), FitSettings(), model.default_params())
    problem.compile_jacobian_code()
    z = problem.initial_z()
    samples = sum(len(t) for t in train)
    duration = sum(t.duration_s for t in train)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}"
    )
    print(
        f"data: {len(train)} training experiments, {samples} samples ({duration:.0f} s), "
        f"{problem.n_r} residuals, {len(DEFAULT_FREE)} free parameters; one process"
    )
    times: dict[tuple[str, bool], list[float]] = {}
    outs: dict[tuple[str, bool], dict] = {}
    for _ in range(args.runs):
        for path in ("buffer", "plain"):
            for jac in (False, True):
                if path == "plain":
                    with _plain_calls():
                        dt, out = _timed(problem, z, jac)
                else:
                    dt, out = _timed(problem, z, jac)
                times.setdefault((path, jac), []).append(dt)
                outs[(path, jac)] = out
    same = all(
        np.array_equal(outs[("buffer", jac)]["r"], outs[("plain", jac)]["r"])
        for jac in (False, True)
    ) and np.array_equal(
        outs[("buffer", True)]["J"].toarray(), outs[("plain", True)]["J"].toarray()
    )
    print(
        f"{'evaluation':<12} {'plain call (s)':>15} {'buffer (s)':>11} {'ratio':>6} "
        f"{'µs/sample/dir':>14} {'× real time':>12}"
    )
    for jac, label in ((False, "residuals"), (True, "Jacobian")):
        plain = statistics.median(times[("plain", jac)])
        buf = statistics.median(times[("buffer", jac)])
        per = buf / samples / (len(DEFAULT_FREE) if jac else 1) * 1e6
        print(
            f"{label:<12} {plain:>15.2f} {buf:>11.2f} {plain / buf:>6.2f} {per:>14.3f} "
            f"{buf / duration:>12.4f}"
        )
    print(
        f"(medians of {args.runs}; µs per sample per direction; residuals and Jacobian of the "
        f"two paths bitwise equal: {same})"
    )
    if not same:
        raise SystemExit("the buffer path differs from the plain call")


if __name__ == "__main__":
    main()
