"""Local GP regression that scales to ~10⁶ redundant ramp samples.

:class:`LocalGPRegressor` is an exact GP (rational-quadratic or RBF kernel, per-input length
scales, hyperparameters by maximum marginal likelihood, predictive standard deviation) fitted
to *bin means* instead of raw samples:

1. Inputs are standardized; targets are centred and scaled (weighted by the sample weights).
2. **Binning** (:func:`~clutchlab.residual_ml.binning.grid_bins`): samples in one cell of a
   grid of ``bin_width`` standard deviations are replaced by their weighted mean input and
   target; the bin's noise variance is ``σ² / W`` with ``W`` its total sample weight
   (heteroscedastic noise, exact for the mean of W independent observations).
3. **Hyperparameters** maximize the log marginal likelihood (analytic gradient, L-BFGS-B,
   optional restarts) of at most ``n_hyper`` bins (a random subset if there are more), split
   into blocks of at most ``block_size`` bins: the objective is the sum of the blocks' log
   marginal likelihoods (independent experts sharing one set of hyperparameters), at
   O(n · block_size²) cost per evaluation instead of O(n³). Bins are assigned to blocks at
   random by default (as in the distributed GP of Deisenroth & Ng, ICML 2015: every block
   sees how the target varies *between* distant operating points — fast and slow ramps,
   rising and falling branches), or as compact regions (recursive median splits: full
   local density, but each block sees one branch at one ramp rate), or ``auto`` (both
   optimized on four fifths of the bins, the hyperparameters predicting the remaining fifth
   better kept). Leave-one-experiment-out on the stand's training experiments preferred
   random blocks for the paper pipeline (``studies/ml_model_choices.py``, choice 0: summed
   RMSE 0.870 bar against 0.893 auto and 0.913 compact). On 4000 scattered samples random
   blocks match scikit-learn's exact GP with per-input RBF length scales (compact blocks do
   not), but not with one isotropic RQ length scale, where compact blocks and ``auto`` do
   (``benchmarks/bench_gp.py``).
4. **Re-binning**: with the length scales ℓ known, bins are rebuilt with cells of
   ``max(bin_width, bin_frac · r_j)`` per input, ``r_j = ℓ_j · min(1, √α)`` the kernel's
   resolution (a rational quadratic with small α mixes in length scales well below ℓ),
   coarsened further until at most ``max_points`` bins remain.
5. One Cholesky factorization of the re-binned problem gives the predictive mean weights.
6. **Standard deviation on coarser bins**: the predictive standard deviation is the same GP's
   (same hyperparameters) given a coarser binning of the training data, built as in step 4
   with the cell fraction coarsened further until at most ``max_std_points`` bins remain
   (the final bins themselves when they are few enough). It costs m² per prediction
   (m ≤ ``max_std_points``) instead of n² (n ≤ ``max_points``), so that an exported FMU
   computes it within a 1 kHz step, and the FMU and this model compute the same number.
   The mean is unaffected.

On scattered data without redundancy (every sample its own bin, ``n ≤ n_hyper``) this is the
exact GP of scikit-learn's ``GaussianProcessRegressor`` with a ``ConstantKernel * kernel``
and noise, and gives the same predictions for the same hyperparameters.
"""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
from scipy.linalg import LinAlgError, cho_solve, cholesky, solve_triangular
from scipy.linalg.lapack import dpotri
from scipy.optimize import minimize
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import check_random_state
from sklearn.utils.validation import _check_sample_weight, check_is_fitted, validate_data

from ._threads import single_thread
from .binning import grid_bins
from .kernels import KERNELS, KernelSpec, kernel_spec

__all__ = ["LocalGPRegressor", "log_marginal_likelihood", "split_blocks"]

_BLOCK_ELEMENTS = 131_072  # kernel entries per prediction block (1 MB: stays in cache)
_VALIDATION_POINTS = 1500  # most bins conditioned on when scoring a block assignment


def _jittered_cholesky(K: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of K, adding diagonal jitter (1e-10 → 1e-4 × mean diag) if needed."""
    try:
        return cholesky(K, lower=True, check_finite=False)
    except LinAlgError:
        pass
    scale = float(np.mean(np.diag(K)))
    for jitter in (1e-10, 1e-8, 1e-6, 1e-4):
        try:
            return cholesky(K + jitter * scale * np.eye(K.shape[0]), lower=True, check_finite=False)
        except LinAlgError:
            continue
    raise LinAlgError("kernel matrix is not positive definite even with jitter")


def _cho_inverse(L: np.ndarray) -> np.ndarray:
    """K⁻¹ from the lower Cholesky factor L of K (LAPACK ``potri``: half the work of solving
    against the identity)."""
    inv, info = dpotri(L, lower=1)
    if info != 0:
        raise LinAlgError(f"inverse from the Cholesky factor failed (LAPACK potri info={info})")
    inv = np.tril(inv)
    inv += inv.T  # numpy buffers the overlapping transpose
    inv[np.diag_indices_from(inv)] *= 0.5
    return inv


def split_blocks(
    x: np.ndarray, size: int, assignment: str = "compact", rng=None
) -> list[np.ndarray]:
    """Index blocks of at most ``size`` points.

    Parameters
    ----------
    x : numpy.ndarray
        n × d points (scaled units).
    size : int
        Largest block (≥ 1).
    assignment : {"compact", "random"}
        ``compact``: recursive median splits of the widest input (each block a local region
        at full data density). ``random``: a random partition into ``ceil(n / size)`` equal
        blocks (each block spans the whole input space at a fraction of the density).
    rng : numpy.random.RandomState or None
        Source of the random partition.

    Returns
    -------
    list of numpy.ndarray
        Disjoint index arrays covering ``range(n)``, each sorted.
    """
    if assignment == "random":
        n = x.shape[0]
        k = max(1, math.ceil(n / size))
        perm = check_random_state(rng).permutation(n)
        return [np.sort(perm[i::k]) for i in range(k)]
    out: list[np.ndarray] = []
    stack = [np.arange(x.shape[0])]
    while stack:
        idx = stack.pop()
        if idx.size <= size:
            out.append(np.sort(idx))
            continue
        pts = x[idx]
        j = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
        order = np.argsort(pts[:, j], kind="stable")
        half = idx.size // 2
        stack += [idx[order[:half]], idx[order[half:]]]
    return out


def log_marginal_likelihood(
    kernel: KernelSpec,
    theta: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    weight: np.ndarray,
    eval_gradient: bool = False,
) -> float | tuple[float, np.ndarray]:
    """Log marginal likelihood of a zero-mean GP with heteroscedastic noise ``σ² / weight``.

    Parameters
    ----------
    kernel : KernelSpec
        Kernel family.
    theta : numpy.ndarray
        Kernel log-hyperparameters followed by ``log σ²`` (noise variance per unit weight, in
        normalized target units squared).
    x : numpy.ndarray
        n × d scaled inputs.
    y : numpy.ndarray
        n normalized targets.
    weight : numpy.ndarray
        n positive weights (effective observations per point).
    eval_gradient : bool
        Also return the gradient with respect to ``theta``.

    Returns
    -------
    float or (float, numpy.ndarray)
        The log marginal likelihood (nats), and its gradient if asked; ``-inf`` (gradient 0)
        where the kernel matrix is not positive definite.
    """
    noise = math.exp(theta[-1]) / weight
    n = y.size
    if eval_gradient:
        K, contract = kernel.with_contractions(theta[:-1], x)
    else:
        K = kernel(theta[:-1], x)
    K[np.diag_indices_from(K)] += noise
    try:
        L = cholesky(K, lower=True, check_finite=False)
    except LinAlgError:
        return (-np.inf, np.zeros_like(theta)) if eval_gradient else -np.inf
    a = cho_solve((L, True), y, check_finite=False)
    lml = -0.5 * float(y @ a) - float(np.log(np.diag(L)).sum()) - 0.5 * n * math.log(2 * math.pi)
    if not eval_gradient:
        return lml
    W = np.outer(a, a)
    W -= _cho_inverse(L)
    grad = np.empty(theta.size)
    grad[:-1] = 0.5 * contract(W)
    grad[-1] = 0.5 * float(np.diag(W) @ noise)
    return lml, grad


class LocalGPRegressor(RegressorMixin, BaseEstimator):
    """Exact GP on bin means of redundant samples (RQ or RBF kernel, per-input length scales).

    Parameters
    ----------
    kernel : {"rq", "rbf"}
        Rational quadratic ``s² (1 + r²/2α)^(−α)`` or RBF ``s² exp(−r²/2)``,
        ``r² = Σ (Δx_j / ℓ_j)²`` on standardized inputs.
    ard : bool
        One length scale per input (default) or one shared length scale.
    bin_width : float
        First-stage grid cell, in standard deviations of each input (default 0.01); 0 merges
        identical inputs only.
    bin_frac : float
        Final grid cell as a fraction of each fitted length scale (default 0.1).
    max_points : int
        At most this many bins in the final GP (its O(n³) solve; default 3000).
    max_std_points : int
        At most this many bins (a count, ≥ 2) in the GP the predictive standard deviation is
        computed from (default 300: a real-time cost choice, m²/2 ≈ 4.5·10⁴ multiply-adds
        per sample, which an exported FMU does within a 1 kHz step; not tuned for accuracy).
        The std (target units) is the predictive std of the same GP (same hyperparameters)
        given these coarser bins of the training data; when the final GP has no more bins
        than this, they are the same bins and the same std.
    n_hyper : int
        At most this many bins (random subset) in the marginal-likelihood optimization
        (default 2000).
    block_size : int
        Largest block of the blocked marginal likelihood (default 250); with ``n_hyper ≤
        block_size`` the likelihood is exact.
    block_assignment : {"random", "compact", "auto"}
        How bins are assigned to blocks (:func:`split_blocks`; default ``"random"``).
        ``"auto"``: the hyperparameters are optimized with each assignment on four fifths of
        the bins, and those that predict the held-out fifth better are kept (fitted choice
        in ``block_assignment_``, validation errors in ``block_validation_``).
    optimizer : bool
        Maximize the marginal likelihood (default); False keeps the initial hyperparameters.
    n_restarts : int
        Extra optimizer starts, log-uniform within the bounds (default 0).
    max_iter : int
        L-BFGS-B iterations per start (default 100).
    length_scale : float
        Initial length scale, in standard deviations of the inputs (default 1).
    alpha : float
        Initial scale mixture α of the RQ kernel (default 1).
    signal_var : float
        Initial signal variance s², in units of the target variance (default 1).
    noise_var : float
        Initial noise variance σ² of one observation of weight 1, in units of the target
        variance (default 1e-2).
    length_scale_bounds, alpha_bounds, signal_var_bounds, noise_var_bounds : (float, float)
        Bounds of the optimization, same units as the initial values.
    normalize_y : bool
        Centre and scale the target by its (weighted) mean and standard deviation (default).
    random_state : int, RandomState or None
        Seed of the subset and restart draws.

    Attributes
    ----------
    theta_ : numpy.ndarray
        Fitted log-hyperparameters (kernel, then ``log σ²``).
    length_scales_ : numpy.ndarray
        Fitted length scales in input units (per input).
    alpha_ : float
        Fitted α (``inf`` for the RBF kernel).
    noise_var_ : float
        Fitted noise variance of one weight-1 observation, in target units squared.
    log_marginal_likelihood_value_ : float
        (Blocked) log marginal likelihood at ``theta_`` on the optimization bins (nats).
    n_bins_ : int
        Number of bins of the final GP.
    n_iter_ : int
        L-BFGS-B iterations of the marginal-likelihood optimization (all starts).
    bin_widths_ : numpy.ndarray
        Final grid cell per input, in input units.
    X_bins_, y_bins_, w_bins_ : numpy.ndarray
        Bin means (scaled inputs, normalized targets) and weights of the final GP.
    dual_coef_ : numpy.ndarray
        ``K⁻¹ y`` of the final GP (normalized units).
    X_std_bins_, w_std_bins_ : numpy.ndarray
        Bin means (scaled inputs) and weights of the GP the standard deviation is computed
        from (at most ``max_std_points`` bins; the final bins when they are that few).
    n_std_bins_ : int
        Number of those bins.
    std_bin_widths_ : numpy.ndarray
        Their grid cell per input, in input units.
    n_features_in_ : int
        Number of inputs.
    """

    def __init__(
        self,
        kernel: str = "rq",
        ard: bool = True,
        bin_width: float = 0.01,
        bin_frac: float = 0.1,
        max_points: int = 3000,
        max_std_points: int = 300,
        n_hyper: int = 2000,
        block_size: int = 250,
        block_assignment: str = "random",
        optimizer: bool = True,
        n_restarts: int = 0,
        max_iter: int = 100,
        length_scale: float = 1.0,
        alpha: float = 1.0,
        signal_var: float = 1.0,
        noise_var: float = 1e-2,
        length_scale_bounds: tuple[float, float] = (1e-2, 1e3),
        alpha_bounds: tuple[float, float] = (1e-2, 1e3),
        signal_var_bounds: tuple[float, float] = (1e-3, 1e3),
        noise_var_bounds: tuple[float, float] = (1e-8, 1e1),
        normalize_y: bool = True,
        random_state=None,
    ) -> None:
        self.kernel = kernel
        self.ard = ard
        self.bin_width = bin_width
        self.bin_frac = bin_frac
        self.max_points = max_points
        self.max_std_points = max_std_points
        self.n_hyper = n_hyper
        self.block_size = block_size
        self.block_assignment = block_assignment
        self.optimizer = optimizer
        self.n_restarts = n_restarts
        self.max_iter = max_iter
        self.length_scale = length_scale
        self.alpha = alpha
        self.signal_var = signal_var
        self.noise_var = noise_var
        self.length_scale_bounds = length_scale_bounds
        self.alpha_bounds = alpha_bounds
        self.signal_var_bounds = signal_var_bounds
        self.noise_var_bounds = noise_var_bounds
        self.normalize_y = normalize_y
        self.random_state = random_state

    # -- set-up ------------------------------------------------------------------------------

    def _check_params(self) -> None:
        if str(self.kernel).lower() not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {self.kernel!r}")
        for name in ("bin_width", "bin_frac"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        if self.block_assignment not in ("auto", "random", "compact"):
            raise ValueError(
                "block_assignment must be 'auto', 'random' or 'compact', got "
                f"{self.block_assignment!r}"
            )
        for name in ("max_points", "max_std_points", "n_hyper", "block_size"):
            if int(getattr(self, name)) < 2:
                raise ValueError(f"{name} must be >= 2, got {getattr(self, name)!r}")
        for name in ("length_scale", "alpha", "signal_var", "noise_var"):
            lo, hi = getattr(self, name + "_bounds")
            v = getattr(self, name)
            if not (0 < lo <= hi) or not (lo <= v <= hi):
                raise ValueError(
                    f"{name}={v!r} must lie within {name}_bounds=({lo!r}, {hi!r}), bounds > 0"
                )

    def _bounds(self, spec: KernelSpec) -> np.ndarray:
        rows = [self.signal_var_bounds] + [self.length_scale_bounds] * spec.n_length
        if spec.name == "rq":
            rows.append(self.alpha_bounds)
        rows.append(self.noise_var_bounds)
        return np.log(np.asarray(rows, dtype=float))

    def _theta0(self, spec: KernelSpec) -> np.ndarray:
        vals = [self.signal_var] + [self.length_scale] * spec.n_length
        if spec.name == "rq":
            vals.append(self.alpha)
        vals.append(self.noise_var)
        return np.log(np.asarray(vals, dtype=float))

    # -- fit ---------------------------------------------------------------------------------

    def fit(self, X, y, sample_weight=None) -> LocalGPRegressor:
        """Fit the GP.

        Parameters
        ----------
        X : array_like
            n × d inputs (any units; standardized internally).
        y : array_like
            n targets (e.g. clutch pressure, bar).
        sample_weight : array_like, optional
            n non-negative weights: the number of independent observations each sample
            stands for (default 1). A sample of weight k is the same as k identical samples.

        Returns
        -------
        LocalGPRegressor
            self, fitted.
        """
        # one BLAS thread: the blocks are small, and the final O(n³) factorization of a few
        # thousand bins was up to 20x slower multi-threaded on a loaded 2-core machine
        with single_thread("blas"):
            return self._fit(X, y, sample_weight)

    def _fit(self, X, y, sample_weight) -> LocalGPRegressor:
        self._check_params()
        X, y = validate_data(self, X, y, y_numeric=True, dtype=np.float64)
        w = _check_sample_weight(sample_weight, X, dtype=np.float64, ensure_non_negative=True)
        if not (w > 0).any():
            raise ValueError("at least one sample weight must be positive")
        W = w.sum()
        x_mean = (w @ X) / W
        x_std = np.sqrt((w @ (X - x_mean) ** 2) / W)
        x_std[~(x_std > 1e-12 * np.maximum(1.0, np.abs(x_mean)))] = 1.0
        if self.normalize_y:
            y_mean = float(w @ y / W)
            y_std = float(np.sqrt(w @ (y - y_mean) ** 2 / W))
            if not y_std > 1e-12 * max(1.0, abs(y_mean)):
                y_std = 1.0
        else:
            y_mean, y_std = 0.0, 1.0
        self.x_mean_, self.x_scale_ = x_mean, x_std
        self.y_mean_, self.y_scale_ = y_mean, y_std
        xs = (X - x_mean) / x_std
        yn = (y - y_mean) / y_std
        spec = kernel_spec(self.kernel, X.shape[1], self.ard)
        self.kernel_ = spec

        bins = grid_bins(xs, yn, w, float(self.bin_width))
        rng = check_random_state(self.random_state)
        theta = np.clip(self._theta0(spec), *self._bounds(spec).T)
        self.n_iter_ = 0
        self.block_validation_ = {}
        assignment = self.block_assignment
        if assignment == "auto" and self.optimizer and len(bins) > 2 * int(self.block_size):
            theta, assignment = self._choose_blocks(spec, bins, rng)  # on 4/5 of the bins
        elif assignment == "auto":
            assignment = "random"  # one block, or nothing to optimize: the same either way
        sub = np.arange(len(bins))
        if sub.size > self.n_hyper:
            sub = np.sort(rng.choice(sub.size, int(self.n_hyper), replace=False))
        xh, yh, wh = bins.x[sub], bins.y[sub], bins.weight[sub]
        blocks = split_blocks(xh, int(self.block_size), assignment, rng)
        if self.optimizer:  # from the chosen hyperparameters with "auto", else from the start
            start = theta if self.block_validation_ else None
            theta = self._optimize(spec, xh, yh, wh, blocks, rng, start=start)
        self.block_assignment_ = assignment
        self.theta_ = theta
        self.log_marginal_likelihood_value_ = float(
            sum(log_marginal_likelihood(spec, theta, xh[b], yh[b], wh[b]) for b in blocks)
        )

        ell = self._resolution_scaled(spec, theta)
        frac = float(self.bin_frac)
        widths = np.maximum(float(self.bin_width), frac * ell)
        final = grid_bins(xs, yn, w, widths)
        while len(final) > self.max_points:
            frac = max(frac, 1e-3) * 1.25
            widths = np.maximum(float(self.bin_width), frac * ell)
            final = grid_bins(xs, yn, w, widths)
        self.bin_widths_ = widths * x_std
        self._set_posterior(final.x, final.y, final.weight)
        coarse = final
        while len(coarse) > self.max_std_points:  # the std's bins: the same grid, coarser
            frac = max(frac, 1e-3) * 1.25
            widths = np.maximum(float(self.bin_width), frac * ell)
            coarse = grid_bins(xs, yn, w, widths)
        if coarse is final:
            self._set_std_posterior(self.X_bins_, self.w_bins_, self.bin_widths_, self._L)
        else:
            self._set_std_posterior(coarse.x, coarse.weight, widths * x_std)
        return self

    def _choose_blocks(self, spec: KernelSpec, bins, rng) -> tuple[np.ndarray, str]:
        """Hyperparameters from random and from compact blocks; keep those that predict a
        held-out fifth of the bins better (weighted squared error). Returns (theta, choice)."""
        n = len(bins)
        perm = rng.permutation(n)
        n_val = max(1, n // 5)
        val, fit = perm[:n_val], perm[n_val:]
        post = fit if fit.size <= _VALIDATION_POINTS else rng.choice(fit, _VALIDATION_POINTS, False)
        sub = fit if fit.size <= self.n_hyper else rng.choice(fit, int(self.n_hyper), False)
        xh, yh, wh = bins.x[sub], bins.y[sub], bins.weight[sub]
        best, best_err = None, np.inf
        for assignment in ("random", "compact"):
            blocks = split_blocks(xh, int(self.block_size), assignment, rng)
            theta = self._optimize(spec, xh, yh, wh, blocks, rng)
            K = spec(theta[:-1], bins.x[post])
            K[np.diag_indices_from(K)] += math.exp(theta[-1]) / bins.weight[post]
            try:
                coef = cho_solve((_jittered_cholesky(K), True), bins.y[post], check_finite=False)
            except LinAlgError:
                continue
            pred = spec(theta[:-1], bins.x[val], bins.x[post]) @ coef
            wv = bins.weight[val]
            err = float(wv @ (pred - bins.y[val]) ** 2 / wv.sum())
            self.block_validation_[assignment] = err
            if err < best_err:
                best, best_err = (theta, assignment), err
        if best is None:
            raise LinAlgError("kernel matrix is not positive definite for any block assignment")
        return best

    def _optimize(self, spec, x, y, w, blocks, rng, start=None) -> np.ndarray:
        bounds = self._bounds(spec)
        parts = [(x[b], y[b], w[b]) for b in blocks]

        def objective(theta):
            total, grad = 0.0, np.zeros_like(theta)
            for xb, yb, wb in parts:
                lml, g = log_marginal_likelihood(spec, theta, xb, yb, wb, eval_gradient=True)
                if not np.isfinite(lml):
                    return 1e25, np.zeros_like(theta)
                total += lml
                grad += g
            return -total, -grad

        theta0 = self._theta0(spec) if start is None else start
        starts = [np.clip(theta0, bounds[:, 0], bounds[:, 1])]
        for _ in range(int(self.n_restarts)):
            starts.append(rng.uniform(bounds[:, 0], bounds[:, 1]))
        best_theta, best_val = starts[0], np.inf
        self.n_iter_ = 0
        for theta0 in starts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                res = minimize(
                    objective,
                    theta0,
                    jac=True,
                    method="L-BFGS-B",
                    bounds=bounds,
                    options={"maxiter": int(self.max_iter)},
                )
            self.n_iter_ += int(res.nit)
            if res.fun < best_val:
                best_theta, best_val = np.asarray(res.x, dtype=float), float(res.fun)
        return best_theta

    def _set_posterior(self, xb: np.ndarray, yb: np.ndarray, wb: np.ndarray) -> None:
        """Factorize the final GP on bins (scaled inputs, normalized targets, weights)."""
        spec, theta = self.kernel_, self.theta_
        K = spec(theta[:-1], xb)
        K[np.diag_indices_from(K)] += math.exp(theta[-1]) / wb
        L = _jittered_cholesky(K)
        self.X_bins_, self.y_bins_, self.w_bins_ = xb, yb, wb
        self.dual_coef_ = cho_solve((L, True), yb, check_finite=False)
        self._L = L
        self.n_bins_ = int(yb.size)

    def _factor(self) -> np.ndarray:
        """Cholesky factor of the final GP (recomputed after loading)."""
        L = getattr(self, "_L", None)
        if L is None:
            L = self._bins_factor(self.X_bins_, self.w_bins_)
            self._L = L
        return L

    def _bins_factor(self, xb: np.ndarray, wb: np.ndarray) -> np.ndarray:
        """Cholesky factor of ``K + diag(σ² / w)`` on bins (scaled inputs, weights)."""
        K = self.kernel_(self.theta_[:-1], xb)
        K[np.diag_indices_from(K)] += math.exp(self.theta_[-1]) / wb
        return _jittered_cholesky(K)

    def _set_std_posterior(
        self, xb: np.ndarray, wb: np.ndarray, widths: np.ndarray, L: np.ndarray | None = None
    ) -> None:
        """The bins (scaled inputs, weights; cells in input units) of the std's GP."""
        self.X_std_bins_, self.w_std_bins_, self.std_bin_widths_ = xb, wb, widths
        self.n_std_bins_ = int(wb.size)
        self._L_std = L

    def _std_factor(self) -> np.ndarray:
        """Cholesky factor of the std's GP (the final GP's when they share the bins)."""
        if self.X_std_bins_ is self.X_bins_:
            return self._factor()
        L = getattr(self, "_L_std", None)
        if L is None:
            L = self._bins_factor(self.X_std_bins_, self.w_std_bins_)
            self._L_std = L
        return L

    @staticmethod
    def _resolution_scaled(spec: KernelSpec, theta: np.ndarray) -> np.ndarray:
        _, ell, alpha = spec.unpack(theta[:-1])
        return ell * min(1.0, math.sqrt(alpha))

    # -- results -----------------------------------------------------------------------------

    @property
    def resolution_(self) -> np.ndarray:
        """Kernel resolution per input, input units: ``ℓ_j · min(1, √α)``."""
        check_is_fitted(self, "theta_")
        return self._resolution_scaled(self.kernel_, self.theta_) * self.x_scale_

    @property
    def length_scales_(self) -> np.ndarray:
        """Fitted length scales in input units (one per input)."""
        check_is_fitted(self, "theta_")
        return self.kernel_.unpack(self.theta_[:-1])[1] * self.x_scale_

    @property
    def alpha_(self) -> float:
        """Fitted RQ scale mixture α (``inf`` for the RBF kernel)."""
        check_is_fitted(self, "theta_")
        return self.kernel_.unpack(self.theta_[:-1])[2]

    @property
    def noise_var_(self) -> float:
        """Fitted noise variance of one weight-1 observation (target units squared)."""
        check_is_fitted(self, "theta_")
        return math.exp(self.theta_[-1]) * self.y_scale_**2

    @property
    def signal_var_(self) -> float:
        """Fitted signal variance s² (target units squared)."""
        check_is_fitted(self, "theta_")
        return math.exp(self.theta_[0]) * self.y_scale_**2

    @property
    def at_bounds_(self) -> list[str]:
        """Hyperparameters that ended on (within 1 % of) a bound of their search range.

        A hyperparameter on its bound means the likelihood wanted a value outside the
        range (an RQ α on its lower bound: a heavier-tailed mixture of length scales than
        allowed; a noise variance on its lower bound: the bins look noise-free). Entries
        read ``"alpha (lower bound 0.01)"``; length scales are named by input index. The
        bounds (``*_bounds``) hold for the standardized inputs and target; where that is
        not the unit :meth:`hyperparameters` reports in, the entry also gives the bound in
        input units (length scales) or target units squared (variances):
        ``"length_scale[1] (upper bound 1e+03 standardized = 4.71e+04 in input units)"``.
        """
        check_is_fitted(self, "theta_")
        spec = self.kernel_
        names = ["signal_var"] + [f"length_scale[{j}]" for j in range(spec.n_length)]
        # what a standardized value is in the units of hyperparameters(): None where the same
        y2 = float(self.y_scale_) ** 2
        x_scale = np.atleast_1d(np.asarray(self.x_scale_, dtype=float))
        units = [(y2, "target units²")]
        if len(x_scale) == spec.n_length:  # one length scale per input
            units += [(float(s), "input units") for s in x_scale]
        else:  # isotropic on standardized inputs: no single value in input units
            units += [None] * spec.n_length
        if spec.name == "rq":
            names.append("alpha")
            units.append(None)
        names.append("noise_var")
        units.append((y2, "target units²"))
        bounds = self._bounds(spec)
        out = []
        for name, th, (lo, hi), unit in zip(names, self.theta_, bounds, units, strict=True):
            for side, b in (("lower", lo), ("upper", hi)):
                if abs(th - b) <= math.log(1.01):
                    text = f"{name} ({side} bound {math.exp(b):.3g}"
                    if unit is not None and unit[0] != 1.0:
                        text += f" standardized = {math.exp(b) * unit[0]:.3g} in {unit[1]}"
                    out.append(text + ")")
        return out

    def hyperparameters(self) -> dict[str, float | list[float]]:
        """Fitted hyperparameters in engineering units, JSON-ready."""
        check_is_fitted(self, "theta_")
        return {
            "kernel": self.kernel_.name,
            "length_scales": [float(v) for v in self.length_scales_],
            "alpha": float(self.alpha_) if math.isfinite(self.alpha_) else None,  # None: RBF
            "signal_var": float(self.signal_var_),
            "noise_var": float(self.noise_var_),
            "log_marginal_likelihood": float(self.log_marginal_likelihood_value_),
            "n_bins": int(self.n_bins_),
            "at_bounds": self.at_bounds_,
        }

    # -- predict -----------------------------------------------------------------------------

    def _scale(self, X: np.ndarray) -> np.ndarray:
        return (X - self.x_mean_) / self.x_scale_

    def _mean_scaled(self, xs: np.ndarray) -> np.ndarray:
        """Predictive mean (target units) at scaled inputs, in blocks."""
        spec, theta = self.kernel_, self.theta_
        s2, ell, alpha = spec.unpack(theta[:-1])
        xb = self.X_bins_ / ell
        bb = np.einsum("ij,ij->i", xb, xb)
        coef = self.dual_coef_ * (s2 * self.y_scale_)
        out = np.empty(xs.shape[0])
        step = max(1, _BLOCK_ELEMENTS // max(xb.shape[0], 1))
        for i in range(0, xs.shape[0], step):
            a = xs[i : i + step] / ell
            d2 = a @ xb.T
            d2 *= -2.0
            d2 += np.einsum("ij,ij->i", a, a)[:, None]
            d2 += bb
            np.maximum(d2, 0.0, out=d2)
            out[i : i + step] = spec._profile(d2, alpha) @ coef
        return out + self.y_mean_

    def _std_scaled(self, xs: np.ndarray) -> np.ndarray:
        """Predictive standard deviation of the latent function (target units), given the
        std bins: ``y_scale · sqrt(max(s² − vᵀv, 0))``, ``v = L_s⁻¹ k_s``."""
        L = self._std_factor()
        spec, theta = self.kernel_, self.theta_
        out = np.empty(xs.shape[0])
        step = max(1, _BLOCK_ELEMENTS // max(self.X_std_bins_.shape[0], 1))
        prior = math.exp(theta[0])
        for i in range(0, xs.shape[0], step):
            ks = spec(theta[:-1], xs[i : i + step], self.X_std_bins_)
            v = solve_triangular(L, ks.T, lower=True, check_finite=False)
            var = prior - np.einsum("ij,ij->j", v, v)
            out[i : i + step] = np.sqrt(np.maximum(var, 0.0))
        return out * self.y_scale_

    def predict(self, X, return_std: bool = False):
        """Predictive mean (and standard deviation) at ``X``.

        Parameters
        ----------
        X : array_like
            m × d inputs, same units as in :meth:`fit`.
        return_std : bool
            Also return the predictive standard deviation of the latent function (noise
            excluded), in target units: that of the same GP given the coarser std bins (at
            most ``max_std_points``; see the class docstring), cheap enough for a real-time
            step.

        Returns
        -------
        mean : numpy.ndarray
            m predictions (target units, e.g. bar).
        std : numpy.ndarray
            m standard deviations (target units); only if ``return_std``.
        """
        check_is_fitted(self, "dual_coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        xs = self._scale(X)
        with single_thread("blas"):
            mean = self._mean_scaled(xs)
            if return_std:
                return mean, self._std_scaled(xs)
        return mean

    def conditioned_on(self, X, y, sample_weight=None) -> LocalGPRegressor:
        """This GP conditioned on other data, hyperparameters kept (nothing optimized).

        The copy keeps the fitted hyperparameters, the input and target scaling and the
        final bin grid, and is binned and factorized on ``X, y`` instead — e.g. the fitted
        GP without one training experiment, for leave-one-experiment-out predictions at
        the cost of one factorization (no marginal-likelihood optimization). Its std is
        computed from its own final bins.

        Parameters
        ----------
        X : array_like
            n × d inputs, same units as in :meth:`fit`.
        y : array_like
            n targets (target units).
        sample_weight : array_like, optional
            n effective-observation weights (default 1 each).

        Returns
        -------
        LocalGPRegressor
            The conditioned copy (this GP is unchanged).
        """
        check_is_fitted(self, "dual_coef_")
        X = np.asarray(X, dtype=float)
        y = np.asarray(y, dtype=float)
        w = _check_sample_weight(sample_weight, X)
        out = copy.copy(self)
        bins = grid_bins(
            self._scale(X), (y - self.y_mean_) / self.y_scale_, w, self.bin_widths_ / self.x_scale_
        )
        out._set_posterior(bins.x, bins.y, bins.weight)
        out._set_std_posterior(out.X_bins_, out.w_bins_, out.bin_widths_, out._L)
        return out

    # -- persistence -------------------------------------------------------------------------

    def get_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        """Learned state as (JSON-ready dict, arrays) for :mod:`~clutchlab.residual_ml.persist`."""
        check_is_fitted(self, "dual_coef_")
        meta = {
            "kernel": self.kernel_.name,
            "ard": self.kernel_.ard,
            "n_dims": self.kernel_.n_dims,
            "y_mean": self.y_mean_,
            "y_scale": self.y_scale_,
            "n_features_in": int(self.n_features_in_),
            "log_marginal_likelihood": self.log_marginal_likelihood_value_,
        }
        arrays = {
            "theta": self.theta_,
            "x_mean": self.x_mean_,
            "x_scale": self.x_scale_,
            "X_bins": self.X_bins_,
            "y_bins": self.y_bins_,
            "w_bins": self.w_bins_,
            "dual_coef": self.dual_coef_,
            "bin_widths": self.bin_widths_,
            "X_std_bins": self.X_std_bins_,
            "w_std_bins": self.w_std_bins_,
            "std_bin_widths": self.std_bin_widths_,
        }
        return meta, arrays

    def set_state(self, meta: dict, arrays: dict[str, np.ndarray]) -> LocalGPRegressor:
        """Restore the learned state written by :meth:`get_state`; returns self.

        A state written before the std bins existed (no ``X_std_bins``) computes the standard
        deviation on the final bins, as it was computed then.
        """
        self.kernel_ = kernel_spec(meta["kernel"], int(meta["n_dims"]), bool(meta["ard"]))
        self.y_mean_ = float(meta["y_mean"])
        self.y_scale_ = float(meta["y_scale"])
        self.n_features_in_ = int(meta["n_features_in"])
        self.log_marginal_likelihood_value_ = float(meta["log_marginal_likelihood"])
        self.theta_ = np.asarray(arrays["theta"], dtype=float)
        self.x_mean_ = np.asarray(arrays["x_mean"], dtype=float)
        self.x_scale_ = np.asarray(arrays["x_scale"], dtype=float)
        self.X_bins_ = np.asarray(arrays["X_bins"], dtype=float)
        self.y_bins_ = np.asarray(arrays["y_bins"], dtype=float)
        self.w_bins_ = np.asarray(arrays["w_bins"], dtype=float)
        self.dual_coef_ = np.asarray(arrays["dual_coef"], dtype=float)
        self.bin_widths_ = np.asarray(arrays["bin_widths"], dtype=float)
        self.n_bins_ = int(self.y_bins_.size)
        self._L = None
        xs = np.asarray(arrays.get("X_std_bins", self.X_bins_), dtype=float)
        ws = np.asarray(arrays.get("w_std_bins", self.w_bins_), dtype=float)
        if np.array_equal(xs, self.X_bins_) and np.array_equal(ws, self.w_bins_):
            # the final bins (a few of them, or a file written before the std bins)
            self._set_std_posterior(self.X_bins_, self.w_bins_, self.bin_widths_)
        else:
            widths = np.asarray(arrays["std_bin_widths"], dtype=float)
            self._set_std_posterior(xs, ws, widths)
        return self

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags

    def prediction_arrays(self, inverse: bool = False) -> dict[str, object]:
        """The arrays the prediction is computed from, for re-implementing it elsewhere (FMU).

        ``mean(x) = y_mean + Σ_i weights_i · κ(r_i²)``, ``r_i² = Σ_j ((z_j − points_ij) /
        length_scales_j)²``, ``z = (x − x_mean) / x_scale``, with ``κ(r²) = (1 + r²/2α)^(−α)``
        (``"rq"``) or ``exp(−r²/2)`` (``"rbf"``). Latent standard deviation, from the std
        bins (the GP given a coarser binning, see the class docstring): ``y_scale ·
        sqrt(max(s² − vᵀv, 0))``, ``v = L_s⁻¹ k``, ``k_i = s² κ(r_i²)`` with ``r_i`` taken
        to ``std_points``, ``s² = signal_var``.

        Parameters
        ----------
        inverse : bool
            Also return ``std_l_inv`` = L_s⁻¹ (m × m, m ≤ ``max_std_points``), needed for
            the standard deviation.

        Returns
        -------
        dict
            ``kernel`` ("rq" / "rbf"), ``x_mean`` and ``x_scale`` (d, input units),
            ``length_scales`` (d, standardized units), ``alpha`` (RQ scale mixture; inf for
            RBF), ``points`` (n × d bin means, standardized), ``weights`` (n, target units,
            e.g. bar), ``y_mean`` (target units), ``signal_var`` (s², normalized units),
            ``y_scale`` (target units), ``std_points`` (m × d std bin means,
            standardized), ``std_l_inv`` (m × m lower-triangular inverse of the Cholesky
            factor of ``K_s + diag(σ² / w_s)``, normalized units, or None).
        """
        check_is_fitted(self, "dual_coef_")
        s2, ell, alpha = self.kernel_.unpack(self.theta_[:-1])
        d = self.X_bins_.shape[1]
        l_inv = None
        if inverse:
            L = self._std_factor()
            eye = np.eye(L.shape[0])
            l_inv = solve_triangular(L, eye, lower=True, check_finite=False)
        return {
            "kernel": self.kernel_.name,
            "x_mean": np.asarray(self.x_mean_, dtype=float).copy(),
            "x_scale": np.asarray(self.x_scale_, dtype=float).copy(),
            "length_scales": np.broadcast_to(np.asarray(ell, dtype=float), (d,)).copy(),
            "alpha": float(alpha),
            "points": np.asarray(self.X_bins_, dtype=float).copy(),
            "weights": np.asarray(self.dual_coef_, dtype=float) * (s2 * self.y_scale_),
            "y_mean": float(self.y_mean_),
            "signal_var": float(s2),
            "y_scale": float(self.y_scale_),
            "std_points": np.asarray(self.X_std_bins_, dtype=float).copy(),
            "std_l_inv": l_inv,
        }
