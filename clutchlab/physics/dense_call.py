"""Calls of a compiled CasADi function on NumPy arrays, without CasADi matrices in between.

A plain ``fn(a, b, …)`` from Python converts every NumPy argument to a ``DM`` and every
result back (through a Python list of floats), and builds a sparsity pattern for each. For
the simulation and sensitivity chunks (a result of ``nx × nd·500`` numbers per call) that
conversion took about half of a fit's Jacobian evaluation and more than half of its residual
evaluation (``benchmarks/bench_jacobian.py``). :class:`DenseCall` uses CasADi's
buffer interface instead: the arguments are handed over as memory, the results are
written into arrays allocated once.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import SimulationError

__all__ = ["DenseCall"]


class DenseCall:
    """Evaluate ``fn`` (dense inputs and outputs) on NumPy arrays through its buffer.

    Arguments are given by input name; an argument with fewer columns than its input is
    repeated horizontally, as CasADi does for a mapped function (a parameter vector for
    every sample of a chunk). Arguments that stay the same across calls are given once with
    :meth:`fix`.

    Parameters
    ----------
    fn : casadi.Function
        The function; every input and output must be dense.

    Notes
    -----
    The results are views of arrays that the next call overwrites: copy what you keep
    across calls. Arguments are copied in, so a result of one call may be passed as an
    argument of the next.
    """

    def __init__(self, fn: ca.Function) -> None:
        for i in range(fn.n_in()):
            if not fn.sparsity_in(i).is_dense():
                raise ValueError(f"{fn.name()}: input {fn.name_in(i)} is not dense")
        for i in range(fn.n_out()):
            if not fn.sparsity_out(i).is_dense():
                raise ValueError(f"{fn.name()}: output {fn.name_out(i)} is not dense")
        self.fn = fn
        self._buf, self._eval = fn.buffer()
        self._index = {fn.name_in(i): i for i in range(fn.n_in())}
        # column-major n × m memory is a C-ordered m × n array; callers see its transpose
        self._out = [np.empty(fn.size_out(i)[::-1]) for i in range(fn.n_out())]
        for i, arr in enumerate(self._out):
            self._buf.set_res(i, memoryview(arr))
        self._mem: dict[int, np.ndarray] = {}
        self._fixed: set[int] = set()

    def _set(self, name: str, value) -> int:
        i = self._index.get(name)
        if i is None:
            raise ValueError(
                f"{self.fn.name()} has no input {name!r} (inputs: {list(self._index)})"
            )
        n, m = self.fn.size_in(i)
        a = np.asarray(value, dtype=float)
        a = a.reshape(-1, 1) if a.ndim < 2 else a
        if a.shape[0] != n or a.shape[1] == 0 or m % a.shape[1]:
            raise ValueError(
                f"{self.fn.name()}: input {name} is {n}×{m}, got an array of shape "
                f"{np.shape(value)}"
            )
        mem = np.empty((m, n))  # column-major n × m
        mem.reshape(m // a.shape[1], a.shape[1], n)[:] = a.T
        self._mem[i] = mem
        self._buf.set_arg(i, memoryview(mem))
        return i

    def fix(self, **args) -> None:
        """Set inputs (by name) that the following calls leave as they are."""
        for name, value in args.items():
            self._fixed.add(self._set(name, value))

    def __call__(self, **args) -> list[np.ndarray]:
        """``fn`` on the named arguments (and the fixed ones); the results as
        ``(n_rows, n_cols)`` arrays.

        Raises
        ------
        ValueError
            If an input is missing, unknown, or of the wrong size.
        SimulationError
            If the function reports a failure.
        """
        given = {self._set(name, value) for name, value in args.items()}
        missing = [n for n, i in self._index.items() if i not in given | self._fixed]
        if missing:
            raise ValueError(f"{self.fn.name()}: no value for {missing}")
        self._eval()
        if self._buf.ret() != 0:
            raise SimulationError(f"{self.fn.name()} failed (status {self._buf.ret()})")
        return [arr.T for arr in self._out]
