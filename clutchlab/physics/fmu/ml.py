"""FMU programs of learned models: GP mean and std, latch decision, causal dI/dt, hybrid.

The learned models live in :mod:`clutchlab.residual_ml`, a layer above this one, so they
reach the exporter as plain arrays: a :class:`GPSpec` per GP, a :class:`DecisionSpec` for the
latch classifier, a :class:`DidtSpec` for the dI/dt feature. :func:`ml_program` turns them
into an :class:`~clutchlab.physics.fmu.program.FmuProgram` — standalone, or on top of a
physics program (hybrid: physics pressure + residual GP).

Per step the FMU evaluates the features at the step's end, the decision (> 0: latched,
then only the latched GP is evaluated) and the GP: ``n·d`` kernel terms for the mean, an
``n × n`` product for the standard deviation (``with_std``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import ModelError
from .physics import FMU_INPUTS
from .program import FmuProgram, FmuVariable

__all__ = ["ML_FEATURES", "DecisionSpec", "DidtSpec", "GPSpec", "ml_program"]

#: Features an exported ML model may use, with their units.
ML_FEATURES: dict[str, str] = {
    "current_mA": "mA",
    "dither_amp_mA": "mA",
    "dither_freq_Hz": "Hz",
    "didt_mA_s": "mA/s",
    "physics_bar": "bar",
}


class _Constants:
    """The arrays of a program: small ones inline in the C code, large ones as inputs.

    Calling it with an array returns a CasADi matrix of the array's shape (1-D arrays as
    columns): a ``DM`` up to ``inline_limit`` elements, else an ``MX`` symbol that becomes
    a trailing input of every function (the same symbol for the same array).
    """

    def __init__(self, inline_limit: int = 4096) -> None:
        self.inline_limit = inline_limit
        self.arrays: list[np.ndarray] = []
        self.symbols: list[ca.MX] = []
        self._seen: dict[int, ca.MX] = {}

    def __call__(self, array) -> ca.DM | ca.MX:
        arr = np.asarray(array, dtype=float)
        arr = arr.reshape(-1, 1) if arr.ndim == 1 else arr
        if arr.size <= self.inline_limit:
            return ca.DM(arr)
        key = id(array)
        if key not in self._seen:
            sym = ca.MX.sym(f"c{len(self.symbols)}", *arr.shape)
            self.arrays.append(arr)
            self.symbols.append(sym)
            self._seen[key] = sym
        return self._seen[key]


_INLINE = _Constants(inline_limit=np.iinfo(np.int64).max)


@dataclass(frozen=True)
class GPSpec:
    """A fitted GP as arrays (the prediction of ``LocalGPRegressor``).

    ``mean(x) = y_mean + Σ_i weights_i · κ(r_i²)``, ``r_i² = Σ_j ((z_j − points_ij) /
    length_scales_j)²``, ``z = (x − x_mean) / x_scale``; ``κ(r²) = (1 + r²/2α)^(−α)``
    (``"rq"``) or ``exp(−r²/2)`` (``"rbf"``). Standard deviation (latent, noise excluded):
    ``y_scale · sqrt(max(s² − s²κᵀ K⁻¹ s²κ, 0))`` with ``s² = signal_var``.

    Attributes
    ----------
    kernel : {"rq", "rbf"}
    x_mean, x_scale : ndarray (d,)
        Standardization of the features (feature units).
    length_scales : ndarray (d,)
        Length scales in standardized units.
    alpha : float
        Scale mixture α of the RQ kernel (ignored for RBF).
    points : ndarray (n, d)
        Training (bin) points, standardized.
    weights : ndarray (n,)
        ``K⁻¹y · s² · y_scale``: mean weights in target units (bar).
    y_mean : float
        Target offset (bar).
    signal_var : float
        s² in normalized target units (for the std).
    y_scale : float
        Target scale (bar).
    k_inv : ndarray (n, n) or None
        ``K⁻¹`` in normalized units (noise included); None: no std output.
    """

    kernel: str
    x_mean: np.ndarray
    x_scale: np.ndarray
    length_scales: np.ndarray
    alpha: float
    points: np.ndarray
    weights: np.ndarray
    y_mean: float
    signal_var: float = 1.0
    y_scale: float = 1.0
    k_inv: np.ndarray | None = None

    def __post_init__(self) -> None:
        n, d = np.shape(self.points)
        problems = []
        if self.kernel not in ("rq", "rbf"):
            problems.append(f"kernel {self.kernel!r} is not 'rq' or 'rbf'")
        for name in ("x_mean", "x_scale", "length_scales"):
            if np.shape(getattr(self, name)) != (d,):
                problems.append(f"{name} must have shape ({d},)")
        if np.shape(self.weights) != (n,):
            problems.append(f"weights must have shape ({n},)")
        if self.k_inv is not None and np.shape(self.k_inv) != (n, n):
            problems.append(f"k_inv must have shape ({n}, {n})")
        if problems:
            raise ModelError("invalid GPSpec: " + "; ".join(problems))

    @property
    def n_features(self) -> int:
        """Number of input features d."""
        return int(np.shape(self.points)[1])

    def _profile(self, x: ca.MX, const: _Constants) -> ca.MX:
        """Kernel profile κ(r_i²) of every point (1 × n), a serial map (a loop in C)."""
        d = self.n_features
        z = ((x - const(self.x_mean).T) / const(self.x_scale).T).T
        zs, pt = ca.SX.sym("z", d), ca.SX.sym("pt", d)
        r2 = ca.sumsqr((zs - pt) / ca.DM(self.length_scales))
        if self.kernel == "rbf":
            prof = ca.exp(-0.5 * r2)
        else:
            prof = ca.exp(-self.alpha * ca.log1p(r2 / (2.0 * self.alpha)))
        kern = ca.Function("kernel", [zs, pt], [prof])
        n = self.points.shape[0]
        return kern.map(n, "serial")(z, const(np.ascontiguousarray(self.points.T)))

    def mean(self, x: ca.MX, const: _Constants = _INLINE) -> ca.MX:
        """Predictive mean (bar) at the row vector of features ``x`` (1 × d)."""
        return self.y_mean + ca.mtimes(self._profile(x, const), const(self.weights))

    def std(self, x: ca.MX, const: _Constants = _INLINE) -> ca.MX:
        """Predictive standard deviation (bar) at ``x``; requires ``k_inv``."""
        if self.k_inv is None:
            raise ModelError("this GPSpec has no k_inv: no standard deviation")
        ks = self.signal_var * self._profile(x, const).T
        var = self.signal_var - ca.dot(ks, ca.mtimes(const(self.k_inv), ks))
        return self.y_scale * ca.sqrt(ca.fmax(var, 0.0))


@dataclass(frozen=True)
class DecisionSpec:
    """A latch classifier's decision function (> 0: latched) on standardized features.

    ``kind="rbf"``: ``Σ_i coef_i exp(−γ |z − support_i|²) + intercept``; ``kind="linear"``:
    ``weights · z + intercept``; ``z = (x[columns] − mean) / scale`` (``columns``: the
    features the classifier uses, all when None).
    """

    kind: str
    mean: np.ndarray
    scale: np.ndarray
    intercept: float
    support: np.ndarray | None = None
    coef: np.ndarray | None = None
    gamma: float = 1.0
    weights: np.ndarray | None = None
    columns: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        ok = (self.kind == "rbf" and self.support is not None and self.coef is not None) or (
            self.kind == "linear" and self.weights is not None
        )
        if not ok:
            raise ModelError(
                "invalid DecisionSpec: kind 'rbf' needs support and coef, 'linear' needs weights"
            )

    def __call__(self, x: ca.MX, const: _Constants = _INLINE) -> ca.MX:
        """Decision value at the row vector ``x`` (1 × d)."""
        if self.columns is not None:
            x = ca.horzcat(*(x[:, c] for c in self.columns))
        z = (x - const(self.mean).T) / const(self.scale).T
        if self.kind == "linear":
            return ca.dot(z.T, const(self.weights)) + self.intercept
        d = z.shape[1]
        zs, sv = ca.SX.sym("z", d), ca.SX.sym("sv", d)
        kern = ca.Function("rbf", [zs, sv], [ca.exp(-self.gamma * ca.sumsqr(zs - sv))])
        n = self.support.shape[0]
        k = kern.map(n, "serial")(z.T, const(np.ascontiguousarray(self.support.T)))
        return ca.mtimes(k, const(self.coef)) + self.intercept


@dataclass(frozen=True)
class DidtSpec:
    """Causal dI/dt of the nominal current: least-squares slope over the last N samples.

    ``N`` = ``periods`` dither periods (rounded up to odd, as ``clutchlab.data.didt``), at
    most ``max_samples``. Unlike the offline (centred) Savitzky–Golay slope it lags by
    ``(N − 1)/2`` samples: a model must be trained on the same causal feature for the FMU
    to reproduce it.
    """

    periods: float = 5.0
    max_samples: int = 255
    sample_s: float = 1e-3

    def slope(self, buffer: ca.MX, freq: ca.MX) -> ca.MX:
        """Slope (mA/s) from ``buffer`` (newest first, mA) at dither frequency ``freq`` (Hz)."""
        m = self.max_samples
        n = ca.ceil(self.periods / (ca.fmax(freq, 1e-9) * self.sample_s))
        n = ca.fmin(ca.fmax(n + 1 - ca.fmod(n, 2), 3), m)
        j = ca.DM(np.arange(m, dtype=float))
        t = -j * self.sample_s
        t_bar = -(n - 1) * self.sample_s / 2
        s = self.sample_s**2 * n * (n * n - 1) / 12
        w = ca.if_else(j < n, (t - t_bar) / s, 0)
        return ca.dot(w, buffer)


def _inputs(physics: FmuProgram | None) -> tuple[FmuVariable, ...]:
    if physics is not None:
        return physics.inputs
    spec = FMU_INPUTS["command"] + (
        ("line_pressure_bar", "bar", "line pressure (not used by this model)", 17.7),
        ("prime_pressure_bar", "bar", "prime pressure (not used by this model)", 0.5),
        ("oil_temp_C", "°C", "oil temperature (not used by this model)", 40.0),
    )
    return tuple(FmuVariable(n, u, d, s) for n, u, d, s in spec)


def ml_program(
    gps: GPSpec | dict[int, GPSpec],
    features: tuple[str, ...],
    decision: DecisionSpec | None = None,
    didt: DidtSpec | None = None,
    physics: FmuProgram | None = None,
    with_std: bool = True,
    name: str = "clutch_gp",
    description: str = "",
) -> FmuProgram:
    """The FMU program of a GP model (one GP, or one per latch state with a decision).

    Parameters
    ----------
    gps : GPSpec or dict of int to GPSpec
        One GP, or ``{0: unlatched, 1: latched}`` selected by ``decision``.
    features : tuple of str
        Feature names of :data:`ML_FEATURES`, in the GPs' column order.
    decision : DecisionSpec, optional
        Latch classifier (required for two GPs); its output is ``latch_state``.
    didt : DidtSpec, optional
        Causal dI/dt (required when ``didt_mA_s`` is a feature).
    physics : FmuProgram, optional
        Physics program (command drive) under a residual GP: hybrid. The output
        ``clutch_pressure_bar`` is then physics + residual; the physics outputs remain.
    with_std : bool
        Output ``clutch_pressure_std_bar`` (the GPs need ``k_inv``).
    name, description : str
        Model identifier and description.

    Returns
    -------
    FmuProgram
    """
    gps = gps if isinstance(gps, dict) else {0: gps}
    unknown = [f for f in features if f not in ML_FEATURES]
    problems = [f"unknown feature(s) {unknown}; known: {list(ML_FEATURES)}"] if unknown else []
    if len(gps) > 1 and decision is None:
        problems.append("two GPs need a decision function")
    if "didt_mA_s" in features and didt is None:
        problems.append("feature didt_mA_s needs a DidtSpec")
    if "physics_bar" in features and physics is None:
        problems.append("feature physics_bar needs a physics program")
    if physics is not None and physics.inputs[0].name != "current_cmd_mA":
        problems.append("a hybrid needs the command-drive physics program")
    if any(g.n_features != len(features) for g in gps.values()):
        problems.append(f"every GP must take the {len(features)} features {features}")
    if with_std and any(g.k_inv is None for g in gps.values()):
        problems.append("with_std needs k_inv in every GPSpec")
    if problems:
        raise ModelError("cannot build the ML program:\n  - " + "\n  - ".join(problems))

    inputs = _inputs(physics)
    nv = len(inputs)
    nb = didt.max_samples if didt is not None else 1
    npx = physics.nx if physics is not None else 0
    pars = physics.parameters if physics is not None else ()
    if physics is None:
        step_s = didt.sample_s if didt is not None else 1e-3
        pars = (FmuVariable("max_step_s", "s", "longest internal step", step_s),)
    npar = len(pars)
    const = _Constants()
    x = ca.MX.sym("x", npx + nb)
    v, dv, h, p = ca.MX.sym("v", nv), ca.MX.sym("dv", nv), ca.MX.sym("h"), ca.MX.sym("p", npar)
    xp, buf = x[:npx], x[npx:]

    def residual(vv: ca.MX, buffer: ca.MX, phys_bar: ca.MX | None):
        cols = {
            "current_mA": vv[0],
            "dither_amp_mA": vv[1],
            "dither_freq_Hz": vv[2],
            "didt_mA_s": didt.slope(buffer, vv[2]) if didt is not None else ca.MX(0),
            "physics_bar": phys_bar if phys_bar is not None else ca.MX(0),
        }
        feat = ca.horzcat(*(cols[f] for f in features))
        if decision is None:
            g = next(iter(gps.values()))
            mean = g.mean(feat, const)
            std = g.std(feat, const) if with_std else None
            return mean, std, None, feat
        dec = decision(feat, const)
        latched = dec > 0
        g0, g1 = gps.get(0, gps.get(1)), gps.get(1, gps.get(0))
        mean = ca.if_else(latched, g1.mean(feat, const), g0.mean(feat, const), True)
        std = (
            ca.if_else(latched, g1.std(feat, const), g0.std(feat, const), True)
            if with_std
            else None
        )
        return mean, std, latched, feat

    def outputs(y_phys: ca.MX | None, vv: ca.MX, buffer: ca.MX) -> ca.MX:
        phys_bar = y_phys[0] if y_phys is not None else None
        mean, std, latched, _ = residual(vv, buffer, phys_bar)
        out = []
        if y_phys is not None:
            out.append(y_phys[0] + mean)
        else:
            out.append(mean)
        if std is not None:
            out.append(std)
        if latched is not None:
            out.append(latched)
        if y_phys is not None:
            out += [mean, y_phys[0], *(y_phys[k] for k in range(1, y_phys.shape[0]))]
        return ca.vertcat(*out)

    v1 = v + h * dv
    buf1 = ca.vertcat(v1[0], buf[: nb - 1]) if didt is not None else buf
    if physics is not None:
        xp1, yp1 = physics.step(xp, v, dv, h, p)
        x1 = ca.vertcat(xp1, buf1)
    else:
        yp1, x1 = None, buf1
    y_step = outputs(yp1, v1, buf1)
    yp0 = physics.output(xp, v, p) if physics is not None else None
    y_out = outputs(yp0, v, buf)
    t_pre = ca.MX.sym("t_pre")
    start_buf = ca.repmat(v[0], nb, 1)
    cs = const.symbols
    step = ca.Function("step", [x, v, dv, h, p, *cs], [x1, y_step])
    output = ca.Function("output", [x, v, p, *cs], [y_out])
    if physics is not None:
        x_start = ca.vertcat(physics.start(v, dv, p, t_pre), start_buf)
        start = ca.Function("start", [v, dv, p, t_pre, *cs], [x_start])
        x_settle = ca.vertcat(physics.settle(xp, v, dv, h, p), buf)
        settle = ca.Function("settle", [x, v, dv, h, p, *cs], [x_settle])
    else:
        start = ca.Function("start", [v, dv, p, t_pre, *cs], [start_buf])
        settle = None

    kind = "hybrid" if physics is not None else "ml"
    outs = [
        FmuVariable(
            "clutch_pressure_bar",
            "bar",
            "clutch pressure: physics + residual GP mean"
            if physics is not None
            else "clutch pressure, GP mean",
        )
    ]
    if with_std:
        outs.append(
            FmuVariable("clutch_pressure_std_bar", "bar", "predictive std of the GP (latent)")
        )
    if decision is not None:
        outs.append(FmuVariable("latch_state", "-", "latch classifier: 1 latched, 0 not"))
    if physics is not None:
        outs.append(FmuVariable("residual_bar", "bar", "residual GP mean added to the physics"))
        outs.append(FmuVariable("physics_pressure_bar", "bar", "physics model clutch pressure"))
        renamed = {"latch_state": "physics_latch_state"} if decision is not None else {}
        outs += [
            FmuVariable(renamed.get(o.name, o.name), o.unit, o.description)
            for o in physics.outputs[1:]
        ]
    return FmuProgram(
        name=name,
        description=description
        or (
            f"clutchlab {kind} model: {len(gps)} GP(s) on {', '.join(features)}"
            + (", latch classifier" if decision is not None else "")
        ),
        kind=kind,
        inputs=inputs,
        outputs=tuple(outs),
        parameters=pars,
        nx=npx + nb,
        start=start,
        settle=settle,
        step=step,
        output=output,
        step_s=physics.step_s if physics is not None else 1e-3,
        stop_time_s=physics.stop_time_s if physics is not None else 23.0,
        annotations={
            **(physics.annotations if physics is not None else {}),
            "kind": kind,
            "features": ",".join(features),
            "gps": str(len(gps)),
            "didt": "causal" if didt is not None else "none",
        },
        constants=tuple(const.arrays),
    )
