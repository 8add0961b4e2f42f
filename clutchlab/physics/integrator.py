"""Fixed-step ROS2 integration of a model over a sampled input, compiled to C.

One *sample step* advances the state over one sample interval ``[t_k, t_{k+1}]``
with the inputs linearly interpolated between the samples, in ``substeps`` ROS2
steps. A *chunk* maps the sample step over ``chunk`` samples (``mapaccum``) so that
a whole trace runs inside generated C code with no Python per sample. The same
sample step is what a fitter differentiates and what an FMU calls each
communication step.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import casadi as ca

from ..errors import SimulationError
from .model import CircuitModel, ModelFunctions
from .smooth import smooth_max0
from .source_key import code_source_key

__all__ = [
    "CSE",
    "GAMMA_ROS2",
    "cache_dir",
    "cached_by_source",
    "chunk_function",
    "compile_function",
    "compile_in_background",
    "load_or_compile",
    "lu_factor",
    "lu_solve",
    "recorded_library",
    "sample_step_function",
    "stabilized_jacobian",
]

#: ROS2 parameter γ = 1 + 1/√2 (L-stable).
GAMMA_ROS2 = 1.0 + 1.0 / 2.0**0.5

#: Options of the generated functions: common subexpressions computed once. The numbers
#: are bitwise the same; the sensitivity code of the base model is half the size, compiles
#: in 6 s instead of 17 s and runs a Jacobian evaluation ~24 % faster (measured, 8
#: directions; BENCHMARKS.md).
CSE = {"cse": True}


def cache_dir() -> Path:
    """Folder of compiled model code: ``$CLUTCHLAB_CACHE`` or ``~/.cache/clutchlab``."""
    root = os.environ.get("CLUTCHLAB_CACHE") or Path.home() / ".cache" / "clutchlab"
    path = Path(root)
    path.mkdir(parents=True, exist_ok=True)
    return path


def lu_factor(a: ca.SX) -> tuple[list[list], int]:
    """Symbolic LU factorization (Doolittle) without pivoting, skipping structural zeros.

    No pivoting is deliberate: with the states ordered base model first, effect
    states last, an effect at zero strength contributes exact zeros to the base
    rows, and elimination in this order leaves the base rows bit-for-bit as in the
    model without the effect (a QR or a pivoted LU would mix them). The diagonal of
    ``W = I − γhJ`` is ≥ 1 after :func:`stabilized_jacobian`.
    """
    n = a.shape[0]
    m = [[a[i, j] for j in range(n)] for i in range(n)]
    for k in range(n):
        for i in range(k + 1, n):
            if m[i][k].is_zero():
                continue
            m[i][k] = m[i][k] / m[k][k]
            for j in range(k + 1, n):
                if not m[k][j].is_zero():
                    m[i][j] = m[i][j] - m[i][k] * m[k][j]
    return m, n


def lu_solve(lu: tuple[list[list], int], b: ca.SX) -> ca.SX:
    """Solve with the factors of :func:`lu_factor` (forward, then back substitution)."""
    m, n = lu
    y = [b[i] for i in range(n)]
    for i in range(n):
        for j in range(i):
            if not m[i][j].is_zero():
                y[i] = y[i] - m[i][j] * y[j]
    x = [None] * n
    for i in range(n - 1, -1, -1):
        acc = y[i]
        for j in range(i + 1, n):
            if not m[i][j].is_zero():
                acc = acc - m[i][j] * x[j]
        x[i] = acc / m[i][i]
    return ca.vertcat(*x)


def stabilized_jacobian(jac: ca.SX) -> ca.SX:
    """The Jacobian with positive diagonal entries smoothly clamped to zero.

    ROS2 is a W-method: it keeps order 2 with any matrix in place of the exact
    Jacobian. Locally *unstable* modes (negative Stribeck damping, the latch's
    snap, positive feedback) have positive eigenvalues λ; with the exact Jacobian
    ``I − γhJ`` becomes singular where ``γhλ = 1`` and the step explodes. Treating
    those diagonal terms explicitly removes the singularity; stiff *stable* modes
    (negative diagonal) keep their implicit treatment.
    """
    out = ca.SX(jac)
    for i in range(jac.shape[0]):
        d = jac[i, i]
        if not d.is_zero():
            out[i, i] = d - smooth_max0(d, 1.0)
    return out


def sample_step_function(fns: ModelFunctions, substeps: int) -> ca.Function:
    """``step(x, u0, u1, dt, p) -> (x1, y1)``: one sample interval in ``substeps`` ROS2 steps.

    ``u0``/``u1`` are the inputs at the interval's ends (linearly interpolated in
    between); ``dt`` the interval (s); ``y1`` the outputs at its end.
    """
    nx, nu = fns.nx, fns.u_sym.shape[0]
    x, u, p = fns.x_sym, fns.u_sym, fns.p_sym
    jac = stabilized_jacobian(ca.jacobian(fns.dx_expr, x))
    h = ca.SX.sym("h")
    ua, ub = ca.SX.sym("ua", nu), ca.SX.sym("ub", nu)
    f_a = ca.substitute(fns.dx_expr, u, ua)
    j_a = ca.substitute(jac, u, ua)
    w = ca.SX.eye(nx) - GAMMA_ROS2 * h * j_a
    lu = lu_factor(w)
    k1 = lu_solve(lu, f_a)
    f_b = ca.substitute(ca.substitute(fns.dx_expr, u, ub), x, x + h * k1)
    k2 = lu_solve(lu, f_b - 2.0 * k1)
    x_next = x + 1.5 * h * k1 + 0.5 * h * k2
    ros2 = ca.Function("ros2", [x, ua, ub, h, p], [x_next], CSE)

    x0, u0, u1, dt = ca.SX.sym("x0", nx), ca.SX.sym("u0", nu), ca.SX.sym("u1", nu), ca.SX.sym("dt")
    xk = x0
    for j in range(substeps):
        a, b = j / substeps, (j + 1) / substeps
        xk = ros2(xk, u0 + a * (u1 - u0), u0 + b * (u1 - u0), dt / substeps, p)
    y1 = fns.out(xk, u1, p)
    return ca.Function(
        "sample_step",
        [x0, u0, u1, dt, p],
        [xk, y1],
        ["x0", "u0", "u1", "dt", "p"],
        ["x1", "y1"],
        CSE,
    )


def compile_function(fn: ca.Function, tag: str, opt: str = "-O2") -> ca.Function | None:
    """Public alias of the code-generation cache (see :func:`_compile`)."""
    return _compile(fn, tag, opt)


def _alias(tag: str, key: str) -> Path:
    return cache_dir() / f"{tag}_{key}.src"


def recorded_library(tag: str, key: str) -> Path | None:
    """The library recorded under source key ``key`` (:mod:`~clutchlab.physics.source_key`)
    for cache tag ``tag``; None when nothing is recorded or the library is gone."""
    try:
        lib = cache_dir() / _alias(tag, key).read_text(encoding="utf-8").strip()
    except OSError:
        return None
    return lib if lib.suffix == ".so" and lib.is_file() else None


def cached_by_source(name: str, tag: str, key: str) -> ca.Function | None:
    """Function ``name`` from the library recorded under source key ``key``, loaded without
    building or generating its code.

    Parameters
    ----------
    name : str
        Name of the compiled function.
    tag : str
        The cache tag the library was compiled under.
    key : str
        Its source key (:func:`~clutchlab.physics.source_key.code_source_key`).

    Returns
    -------
    casadi.Function or None
        None when nothing is recorded under the key, the library is gone or does not load:
        the caller then builds the code and finds (or compiles) it by code hash as before.
    """
    lib = recorded_library(tag, key)
    if lib is None:
        return None
    try:
        return ca.external(name, str(lib))
    except RuntimeError:
        return None


def load_or_compile(
    model: CircuitModel, name: str, tag: str, opt: str, build: Callable[[], ca.Function]
) -> tuple[ca.Function, bool]:
    """Function ``name`` of ``model``: loaded by its source key when its library is recorded,
    else built by ``build()`` and compiled (then recorded under the key).

    Returns
    -------
    (casadi.Function, bool)
        The function and whether it is compiled (False: no working compiler, so the built,
        interpreted function).
    """
    key = code_source_key(model, name, tag, opt)
    cached = cached_by_source(name, tag, key)
    if cached is not None:
        return cached, True
    fn = build()
    compiled = _compile(fn, tag, opt, key)
    return (fn, False) if compiled is None else (compiled, True)


def _record_alias(tag: str, key: str, lib: Path) -> None:
    """Record ``lib`` under ``key``; atomic (a reader sees the old record or the new one)."""
    alias = _alias(tag, key)
    part = alias.with_suffix(f".{os.getpid()}.tmp")
    part.write_text(lib.name + "\n", encoding="utf-8")
    part.replace(alias)


def _compiler() -> str | None:
    return shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")


def _cc_command(cc: str, opt: str, src: Path, out: Path) -> list[str]:
    """The one compiler call of the cache: ``src`` (C) to the shared library ``out``."""
    return [cc, opt, "-shared", "-fPIC", "-o", str(out), str(src), "-lm"]


def _generate(fn: ca.Function, tag: str, opt: str) -> tuple[bytes, Path]:
    """The C source of ``fn`` and the cached library it compiles to (by code hash)."""
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        os.chdir(tmp)
        try:
            src = Path(tmp) / fn.generate(f"{fn.name()}.c", {"with_header": False})
        finally:
            os.chdir(cwd)
        code = src.read_bytes()
    digest = hashlib.sha1(code + ca.__version__.encode() + opt.encode()).hexdigest()[:16]
    return code, cache_dir() / f"{tag}_{digest}.so"


#: Libraries this process is compiling in the background: path -> the compiler process.
_BUILDS: dict[Path, subprocess.Popen] = {}


def compile_in_background(fn: ca.Function, tag: str, opt: str = "-O2") -> None:
    """Start compiling ``fn`` into the cache and return at once.

    A later :func:`compile_function` of the same code in this process waits for it
    instead of compiling again; a failed build leaves nothing behind, and that call then
    compiles as usual (with its error message). Does nothing when the library is cached
    already, is being built here, or there is no compiler or POSIX shell.
    """
    cc, sh = _compiler(), shutil.which("sh")
    if cc is None or sh is None:
        return
    for done in [lib for lib, build in _BUILDS.items() if build.poll() is not None]:
        del _BUILDS[done]  # finished builds nobody asked for (yet): reaped
    code, lib = _generate(fn, tag, opt)
    if lib.exists() or lib in _BUILDS:
        return
    stem = lib.with_suffix(f".{os.getpid()}.bg")
    src, part = stem.with_suffix(".bg.c"), stem.with_suffix(".bg.tmp")
    src.write_bytes(code)
    # the rename is atomic and done by the shell: the library appears whole or not at all
    script = 's=$1 p=$2 l=$3; shift 3; "$@" && mv -f "$p" "$l"; rm -f "$s" "$p"'
    _BUILDS[lib] = subprocess.Popen(
        [sh, "-c", script, "sh", str(src), str(part), str(lib), *_cc_command(cc, opt, src, part)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def _await_build(lib: Path) -> None:
    build = _BUILDS.pop(lib, None)
    if build is not None:
        build.wait()


@atexit.register
def _reap_builds() -> None:  # pragma: no cover - interpreter exit
    for build in _BUILDS.values():
        try:
            build.wait(timeout=120)
        except subprocess.TimeoutExpired:
            build.kill()


def _compile(
    fn: ca.Function, tag: str, opt: str = "-O2", key: str | None = None
) -> ca.Function | None:
    """Generate C for ``fn``, compile it (cached by code hash) and load it; None if impossible.

    With a source ``key`` the library is also recorded under it, for
    :func:`cached_by_source`.
    """
    cc = _compiler()
    if cc is None:
        return None
    code, lib = _generate(fn, tag, opt)
    if not lib.exists():
        _await_build(lib)
    if not lib.exists():
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / f"{fn.name()}.c"
            src.write_bytes(code)
            part = lib.with_suffix(f".{os.getpid()}.tmp")
            res = subprocess.run(_cc_command(cc, opt, src, part), capture_output=True, text=True)
            if res.returncode != 0:
                warnings.warn(
                    f"C compilation failed, interpreting instead:\n{res.stderr[-2000:]}",
                    RuntimeWarning,
                    stacklevel=3,
                )
                return None
            part.replace(lib)
    loaded = ca.external(fn.name(), str(lib))
    if key is not None:
        _record_alias(tag, key, lib)
    return loaded


@lru_cache(maxsize=32)
def chunk_function(
    model: CircuitModel, drive: str, substeps: int, chunk: int, compile_mode: str
) -> ca.Function:
    """``chunk(x0, U0, U1, DT, p) -> (X, Y)`` over ``chunk`` samples, compiled if possible.

    ``U0``/``U1`` (nu × chunk) are the inputs at the start/end of each interval,
    ``DT`` (1 × chunk) the intervals; ``X`` (nx × chunk) and ``Y`` (ny × chunk)
    the states and outputs at the interval ends.
    """
    name, tag = f"chunk_{chunk}", f"clutchlab_{model.key}_{drive}_{substeps}"

    def build() -> ca.Function:
        step = sample_step_function(model.functions(drive), substeps)
        return step.mapaccum(name, chunk, ["x0"], ["x1"])

    if compile_mode == "never":
        return build()
    fn, compiled = load_or_compile(model, name, tag, "-O3", build)
    if not compiled and compile_mode == "always":
        raise SimulationError("compile='always' but no working C compiler was found")
    return fn
