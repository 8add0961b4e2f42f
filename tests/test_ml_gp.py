"""Local GP regression: kernels, likelihood gradient, agreement with scikit-learn, binning."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import approx_fprime
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, RationalQuadratic, WhiteKernel
from sklearn.gaussian_process.kernels import ConstantKernel as C

from clutchlab.residual_ml import LocalGPRegressor, grid_bins, kernel_spec, log_marginal_likelihood
from clutchlab.residual_ml.local_gp import split_blocks
from clutchlab.residual_ml.paths import knot_indices, piecewise_classes, predict_on_path


def _data(n=60, d=3, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2, 2, (n, d))
    y = np.sin(X[:, 0]) + 0.5 * X[:, 1] ** 2 + 0.05 * rng.standard_normal(n)
    return X, y


@pytest.mark.parametrize("name", ["rq", "rbf"])
@pytest.mark.parametrize("ard", [True, False])
def test_lml_gradient_matches_finite_differences(name, ard):
    X, y = _data()
    spec = kernel_spec(name, X.shape[1], ard)
    rng = np.random.default_rng(1)
    theta = rng.normal(0, 0.5, spec.n_params + 1)
    w = rng.uniform(0.5, 3.0, y.size)
    _, grad = log_marginal_likelihood(spec, theta, X, y, w, eval_gradient=True)
    num = approx_fprime(theta, lambda t: log_marginal_likelihood(spec, t, X, y, w), 1e-6)
    np.testing.assert_allclose(grad, num, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("name", ["rq", "rbf"])
@pytest.mark.parametrize("ard", [True, False])
def test_gradient_contractions_equal_the_derivative_matrices(name, ard):
    """The likelihood's gradient sums, taken without the derivative matrices, are theirs."""
    X, _ = _data(80, 4)
    spec = kernel_spec(name, X.shape[1], ard)
    theta = np.random.default_rng(2).normal(0, 0.5, spec.n_params)
    W = np.random.default_rng(3).standard_normal((80, 80))
    W += W.T
    K, grads = spec.with_gradient(theta, X)
    K2, contract = spec.with_contractions(theta, X)
    np.testing.assert_allclose(K2, K, rtol=1e-12, atol=1e-14)
    ref = np.array([np.einsum("ij,ij->", W, g) for g in grads])
    tol = 1e-10 * np.abs(ref).max()
    np.testing.assert_allclose(contract(W), ref, rtol=1e-10, atol=tol)
    # a common offset of the inputs (the kernel ignores it) costs the expansion no digits
    _, shifted = spec.with_contractions(theta, X + 1e4)
    np.testing.assert_allclose(shifted(W), ref, rtol=1e-9, atol=10 * tol)


@pytest.mark.parametrize(
    ("name", "sk_kernel"),
    [
        ("rq", C(1.5) * RationalQuadratic(0.7, 2.0)),
        ("rbf", C(1.5) * RBF(0.7)),
    ],
)
def test_fixed_hyperparameters_equal_sklearn(name, sk_kernel):
    X, y = _data()
    kw = {"length_scale": 0.7, "alpha": 2.0, "signal_var": 1.5, "noise_var": 1e-2}
    gp = LocalGPRegressor(
        kernel=name, ard=False, bin_width=0, bin_frac=0, optimizer=False, normalize_y=False, **kw
    ).fit(X, y)
    xs = (X - X.mean(0)) / X.std(0)
    sk = GaussianProcessRegressor(sk_kernel, alpha=1e-2, optimizer=None).fit(xs, y)
    Xt = _data(40, seed=5)[0]
    m1, s1 = gp.predict(Xt, return_std=True)
    m2, s2 = sk.predict((Xt - X.mean(0)) / X.std(0), return_std=True)
    np.testing.assert_allclose(m1, m2, atol=1e-10)
    np.testing.assert_allclose(s1, s2, atol=1e-10)
    assert gp.log_marginal_likelihood_value_ == pytest.approx(sk.log_marginal_likelihood_value_)


def test_optimized_hyperparameters_agree_with_sklearn():
    X, y = _data()
    gp = LocalGPRegressor(kernel="rq", ard=False, bin_width=0, bin_frac=0).fit(X, y)
    sk_kernel = C(1.0, (1e-3, 1e3)) * RationalQuadratic(
        1.0, 1.0, (1e-2, 1e3), (1e-2, 1e3)
    ) + WhiteKernel(1e-2, (1e-8, 10))
    xs = (X - X.mean(0)) / X.std(0)
    sk = GaussianProcessRegressor(sk_kernel, normalize_y=True).fit(xs, y)
    assert gp.log_marginal_likelihood_value_ == pytest.approx(
        sk.log_marginal_likelihood_value_, abs=1e-3
    )
    Xt = _data(40, seed=5)[0]
    np.testing.assert_allclose(gp.predict(Xt), sk.predict((Xt - X.mean(0)) / X.std(0)), atol=1e-4)


def test_binning_of_redundant_samples_keeps_accuracy_and_shrinks_the_problem():
    # a slow ramp: 20 000 samples of a smooth curve, far more than needed
    t = np.linspace(0.0, 1.0, 20000)
    X = np.column_stack([1100 * t, 40 + 10 * np.sin(6 * t)])
    rng = np.random.default_rng(3)
    f = 0.02 * X[:, 0] + 0.3 * np.sin(X[:, 0] / 90.0)
    y = f + 0.02 * rng.standard_normal(t.size)
    gp = LocalGPRegressor(max_points=400, n_hyper=400, random_state=0).fit(X, y)
    assert gp.n_bins_ <= 400
    err = gp.predict(X[::37]) - f[::37]
    assert np.sqrt(np.mean(err**2)) < 0.01  # below the 0.02 noise: it averages, not just fits


def test_sample_weight_equals_repetition():
    X, y = _data(30)
    w = np.arange(30) % 3 + 1.0
    a = LocalGPRegressor(bin_width=0).fit(X, y, sample_weight=w)
    b = LocalGPRegressor(bin_width=0).fit(
        np.repeat(X, w.astype(int), 0), np.repeat(y, w.astype(int))
    )
    np.testing.assert_allclose(a.predict(X), b.predict(X), atol=1e-6)


def test_grid_bins_means_weights_and_labels():
    x = np.array([[0.0], [0.1], [1.0], [1.05], [1.1]])
    y = np.array([1.0, 3.0, 5.0, 7.0, 9.0])
    b = grid_bins(x, y, np.array([1, 1, 1, 3, 0.0]), 0.5, labels=np.array([0, 0, 0, 1, 1]))
    assert len(b) == 3  # [0, 0.1], [1.0] (label 0), [1.05] (label 1); weight-0 sample dropped
    np.testing.assert_allclose(np.sort(b.y), [2.0, 5.0, 7.0])
    assert b.index[-1] == -1 and set(b.label) == {0, 1}


def test_split_blocks_partition():
    x = np.random.default_rng(0).normal(size=(1000, 3))
    blocks = split_blocks(x, 128)
    assert all(b.size <= 128 for b in blocks)
    np.testing.assert_array_equal(np.sort(np.concatenate(blocks)), np.arange(1000))


def test_knots_and_path_prediction_are_exact_at_tol_zero_and_close_otherwise():
    n = 5000
    x = np.column_stack([np.linspace(0, 1000, n), np.full(n, 50.0)])
    cls = (x[:, 0] > 600).astype(np.int8)

    def fn(z):
        return np.sin(z[:, 0] / 100.0) + 10 * (z[:, 0] > 600)

    every = knot_indices(x, np.array([50.0, 10.0]), 0.0, 20)
    np.testing.assert_array_equal(every, np.arange(n))
    knots = knot_indices(x, np.array([50.0, 10.0]), 0.05, 20)
    assert knots.size < n / 2
    got = predict_on_path(x, cls, knots, {0: fn, 1: fn})
    assert np.abs(got - fn(x)).max() < 1e-3  # no interpolation across the switch at 600
    classes = piecewise_classes(x, knots, lambda z: z[:, 0] - 600.0)
    np.testing.assert_array_equal(classes, cls)


def test_contract_not_fitted_clone_and_bad_params():
    gp = LocalGPRegressor(kernel="rbf", max_points=50)
    with pytest.raises(NotFittedError):
        gp.predict(np.zeros((2, 3)))
    assert clone(gp).get_params() == gp.get_params()
    X, y = _data()
    assert gp.fit(X, y) is gp
    with pytest.raises(ValueError, match="kernel"):
        LocalGPRegressor(kernel="matern").fit(X, y)
    with pytest.raises(ValueError, match="length_scale"):
        LocalGPRegressor(length_scale=1e6).fit(X, y)


def _explicit_std(gp: LocalGPRegressor, Xt: np.ndarray, xb: np.ndarray, wb: np.ndarray):
    """Reference: latent std of an RBF GP with the fitted hyperparameters conditioned on
    bins ``xb`` (scaled inputs) of weights ``wb``, by a dense solve (no Cholesky)."""
    s2, noise = np.exp(gp.theta_[0]), np.exp(gp.theta_[-1])
    ell = gp.length_scales_ / gp.x_scale_  # standardized units

    def kern(a, b):
        return s2 * np.exp(-0.5 * (((a[:, None] - b[None]) / ell) ** 2).sum(-1))

    z = (Xt - gp.x_mean_) / gp.x_scale_
    k = kern(z, xb)
    K = kern(xb, xb) + np.diag(noise / wb)
    var = s2 - np.einsum("ij,ji->i", k, np.linalg.solve(K, k.T))
    return gp.y_scale_ * np.sqrt(np.maximum(var, 0.0))


def _ramp_data(n=20000, seed=3):
    t = np.linspace(0.0, 1.0, n)
    X = np.column_stack([1100 * t, 40 + 10 * np.sin(6 * t)])
    rng = np.random.default_rng(seed)
    y = 0.02 * X[:, 0] + 0.3 * np.sin(X[:, 0] / 90.0) + 0.02 * rng.standard_normal(n)
    return X, y


def test_std_is_the_same_gp_given_the_coarse_std_bins():
    X, y = _ramp_data()
    kw = {"kernel": "rbf", "bin_frac": 0.01, "max_points": 400, "n_hyper": 400, "random_state": 0}
    gp = LocalGPRegressor(max_std_points=40, **kw).fit(X, y)
    assert gp.n_std_bins_ <= 40 < gp.n_bins_
    # a grid binning of all the samples: every sample's weight lands in one std bin
    assert gp.w_std_bins_.sum() == pytest.approx(X.shape[0])
    assert np.all(gp.std_bin_widths_ >= gp.bin_widths_)
    Xt = X[::97] + 3.0  # between the samples
    mean, std = gp.predict(Xt, return_std=True)
    ref = _explicit_std(gp, Xt, gp.X_std_bins_, gp.w_std_bins_)
    np.testing.assert_allclose(std, ref, rtol=1e-6, atol=1e-9)
    # the mean is not touched: the same as with the std on the mean's bins
    fine = LocalGPRegressor(max_std_points=400, **kw).fit(X, y)
    assert fine.X_std_bins_ is fine.X_bins_
    np.testing.assert_array_equal(fine.predict(Xt), mean)
    fine_ref = _explicit_std(fine, Xt, fine.X_bins_, fine.w_bins_)
    np.testing.assert_allclose(fine.predict(Xt, return_std=True)[1], fine_ref, atol=1e-9)
    assert np.abs(std - fine_ref).max() > 1e-6  # the coarse bins do change the std


def test_few_bins_keep_the_std_on_the_final_bins():
    X, y = _data()
    gp = LocalGPRegressor(kernel="rbf", bin_width=0, bin_frac=0, max_std_points=60).fit(X, y)
    assert gp.n_bins_ == 60 and gp.X_std_bins_ is gp.X_bins_ and gp.n_std_bins_ == 60
    Xt = _data(40, seed=5)[0]
    ref = _explicit_std(gp, Xt, gp.X_bins_, gp.w_bins_)
    np.testing.assert_allclose(gp.predict(Xt, return_std=True)[1], ref, rtol=1e-8, atol=1e-12)
    with pytest.raises(ValueError, match="max_std_points"):
        LocalGPRegressor(max_std_points=1).fit(X, y)


def test_state_round_trip_keeps_the_std_bins_and_reads_older_states(tmp_path):
    X, y = _ramp_data(8000)
    gp = LocalGPRegressor(
        kernel="rbf", bin_frac=0.02, max_points=300, n_hyper=300, max_std_points=30
    )
    gp.fit(X, y)
    assert gp.n_std_bins_ < gp.n_bins_
    Xt = X[::53] + 2.0
    mean, std = gp.predict(Xt, return_std=True)
    meta, arrays = gp.get_state()
    # through files, as clutchlab.residual_ml.persist writes them: JSON + NPZ
    (tmp_path / "gp.json").write_text(json.dumps(meta))
    np.savez(tmp_path / "gp.npz", **arrays)
    with np.load(tmp_path / "gp.npz") as npz:
        read = {k: npz[k] for k in npz.files}
    back = LocalGPRegressor().set_state(json.loads((tmp_path / "gp.json").read_text()), read)
    assert back.n_std_bins_ == gp.n_std_bins_ <= 30
    m2, s2 = back.predict(Xt, return_std=True)
    np.testing.assert_array_equal(m2, mean)
    np.testing.assert_allclose(s2, std, rtol=1e-12, atol=1e-15)
    # a state written before the std bins: the std on the final bins, as then
    old = {k: v for k, v in arrays.items() if "std" not in k}
    legacy = LocalGPRegressor().set_state(meta, old)
    assert legacy.X_std_bins_ is legacy.X_bins_
    m3, s3 = legacy.predict(Xt, return_std=True)
    np.testing.assert_array_equal(m3, mean)
    np.testing.assert_allclose(s3, _explicit_std(gp, Xt, gp.X_bins_, gp.w_bins_), atol=1e-9)


def test_hyperparameters_on_a_bound_are_reported():
    rng = np.random.default_rng(4)
    x = rng.uniform(0, 10, (400, 1))
    y = np.sin(x[:, 0]) + rng.normal(0, 0.3, 400)  # noise far above the allowed range
    gp = LocalGPRegressor(kernel="rq", noise_var_bounds=(1e-8, 1e-4), noise_var=1e-5).fit(x, y)
    # the bound holds for the standardized target: also given in target units² (session 41)
    target = f"{1e-4 * gp.y_scale_**2:.3g}"
    assert f"noise_var (upper bound 0.0001 standardized = {target} in target units²)" in (
        gp.at_bounds_
    )
    h = gp.hyperparameters()
    assert h["at_bounds"] == gp.at_bounds_ and h["alpha"] is not None
    json.dumps(h, allow_nan=False)  # JSON-ready
    free = LocalGPRegressor(kernel="rbf").fit(x, y)
    assert free.at_bounds_ == [] and free.hyperparameters()["alpha"] is None
    json.dumps(free.hyperparameters(), allow_nan=False)
