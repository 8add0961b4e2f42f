"""The six latch classifiers of the paper's Table 1, made tractable on ~10⁶ ramp samples.

Every classifier is a scikit-learn pipeline (standardization inside) wrapped in
:class:`BinnedClassifier`, which first collapses the redundant 1 kHz samples into grid bins
of the standardized features (bins never mix labels, so a bin's label is exact):

========================  ==============================================  ===================
name                      model                                           trained on
========================  ==============================================  ===================
``logistic_regression``   ``LogisticRegression``                          bins, count weights
``linear_svc``            ``LinearSVC``                                   bins, count weights
``discretized_lr``        ``KBinsDiscretizer`` (40 uniform bins, one-hot)  bins, count weights
                          + ``LogisticRegression``
``discretized_linear_svc``  same discretizer + ``LinearSVC``              bins, count weights
``gradient_boosting``     ``HistGradientBoostingClassifier`` (histogram     bins, count weights
                          gradient boosting, not the exact
                          ``GradientBoostingClassifier``)
``rbf_svc``               ``SVC(kernel="rbf", C=100, gamma=1)`` on        bins, unweighted,
                          standardized features weighted by               ≤ ``max_points``,
                          :data:`RBF_FEATURE_WEIGHTS`                     refit with fine bins
                                                                          near the boundary
========================  ==============================================  ===================

Settings that are not library defaults (discretizer bins, SVC ``C``, ``gamma`` and feature
weights) were chosen by leave-one-experiment-out accuracy on the training experiments (fast +
slow ramps) of the default stand dataset, never on the medium ramp.

With count weights the weighted bin problem is the sample problem up to the spread of the
features inside a bin, so the linear models and boosting see the same data as on raw samples.
The kernel SVC's training cost grows as O(n²)–O(n³) in points and its ``C`` per point would
scale with a count weight, so it is trained on the bins unweighted (every distinct operating
point once), randomly subsampled to ``max_points`` if there are more.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, ClassifierMixin, TransformerMixin, clone
from sklearn.ensemble import HistGradientBoostingClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import KBinsDiscretizer, StandardScaler
from sklearn.svm import SVC, LinearSVC
from sklearn.utils import check_random_state
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted, validate_data

from ..errors import ModelError
from ._threads import single_thread
from .binning import grid_bins

__all__ = [
    "CLASSIFIERS",
    "RBF_FEATURE_WEIGHTS",
    "BinnedClassifier",
    "ClassifierSpec",
    "ColumnWeights",
    "KernelDecision",
    "LinearDecision",
    "lean_decision",
    "make_classifier",
]


#: Weights of the standardized features in the RBF SVC (others 1), i.e. inverse relative
#: length scales. Chosen by leave-one-experiment-out (LOEO, 6 of the 18 training experiments
#: of the default stand held out in turn): dither frequency 0 and amplitude 0.3 (LOEO 0.9992
#: against 0.9947 with all weights 1 — the latch boundary hardly depends on the frequency, and
#: an isotropic kernel would make a held-out frequency look far from every training point).
#: dI/dt keeps weight 1: LOEO over all 18 training experiments (``studies/ml_model_choices.py``,
#: choice 3, with the lagged-current features) gave 0.9998 / 0.9999 / 0.9998 for weights
#: 0.1 / 0.3 / 1 — a tie, so the neutral weight.
RBF_FEATURE_WEIGHTS: dict[str, float] = {
    "dither_freq_Hz": 0.0,
    "dither_amp_mA": 0.3,
}


class ColumnWeights(TransformerMixin, BaseEstimator):
    """Multiply each column by a fixed weight (a per-feature length scale for a kernel).

    Parameters
    ----------
    weights : array_like or None
        One non-negative weight per column (default all 1); 0 removes the column's influence.
    """

    def __init__(self, weights=None) -> None:
        self.weights = weights

    def fit(self, X, y=None) -> ColumnWeights:
        """Check the weights against the number of columns of ``X``; returns self."""
        X = validate_data(self, X, dtype=np.float64)
        w = np.ones(X.shape[1]) if self.weights is None else np.asarray(self.weights, float)
        if w.shape != (X.shape[1],) or (w < 0).any():
            raise ValueError(f"weights must be {X.shape[1]} values >= 0, got {self.weights!r}")
        self.weights_ = w
        return self

    def transform(self, X) -> np.ndarray:
        """``X * weights`` (column-wise)."""
        check_is_fitted(self, "weights_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return X * self.weights_


class BinnedClassifier(ClassifierMixin, BaseEstimator):
    """Fit a classifier on grid-bin means of its training samples.

    Parameters
    ----------
    estimator : classifier
        The classifier (cloned); its pipeline standardizes on its own.
    bin_width : float
        Grid cell in standard deviations of each feature (default 0.01); 0 merges identical
        points only.
    weighted : bool
        Pass each bin's sample count as ``sample_weight`` (default True).
    max_points : int or None
        At most this many bins (uniform random subset; default None = all).
    refine_width : float or None
        If set, a second fit adds the bins of this finer grid (standard deviations) that lie
        near the first fit's boundary (``|decision| < 1``, or misclassified), at most
        ``max_points`` of them: the boundary is then located to the fine grid's resolution
        at the cost of a few more points (default None: one fit).
    random_state : int, RandomState or None
        Seed of the subset.

    Attributes
    ----------
    estimator_ : classifier
        The fitted classifier.
    classes_ : numpy.ndarray
        Class labels.
    n_train_points_ : int
        Number of (bin) points the classifier was trained on.
    """

    def __init__(
        self,
        estimator=None,
        bin_width: float = 0.01,
        weighted: bool = True,
        max_points: int | None = None,
        refine_width: float | None = None,
        random_state=None,
    ) -> None:
        self.estimator = estimator
        self.bin_width = bin_width
        self.weighted = weighted
        self.max_points = max_points
        self.refine_width = refine_width
        self.random_state = random_state

    def fit(self, X, y, sample_weight=None) -> BinnedClassifier:
        """Bin ``X`` (n × d features) by label ``y`` and fit the classifier on the bins.

        Parameters
        ----------
        X : array_like
            n × d features (any units).
        y : array_like
            n class labels.
        sample_weight : array_like, optional
            n non-negative sample weights (default 1).

        Returns
        -------
        BinnedClassifier
            self, fitted.
        """
        X, y = validate_data(self, X, y, dtype=np.float64)
        check_classification_targets(y)
        codes, self.classes_ = pd.factorize(np.asarray(y), sort=True)  # = np.unique, no sort
        std = X.std(axis=0)
        std[~(std > 0)] = 1.0
        rng = check_random_state(self.random_state)
        bins = grid_bins(X / std, None, sample_weight, float(self.bin_width), labels=codes)
        xb, lb, wb = self._subset(bins.x * std, bins.label, bins.weight, rng)
        if len(np.unique(lb)) < 2:
            raise ValueError("the training bins hold only one class")
        est = self._fit_one(xb, lb, wb)
        if self.refine_width is not None and hasattr(est, "decision_function"):
            fine = grid_bins(X / std, None, sample_weight, float(self.refine_width), codes)
            xf = fine.x * std
            dec = est.decision_function(xf)
            near = (np.abs(dec) < 1.0) | ((dec > 0) != (fine.label == 1))
            xn, ln, wn = self._subset(xf[near], fine.label[near], fine.weight[near], rng)
            xb, lb, wb = np.vstack([xb, xn]), np.concatenate([lb, ln]), np.concatenate([wb, wn])
            est = self._fit_one(xb, lb, wb)
        self.estimator_ = est
        self.n_train_points_ = int(lb.size)
        return self

    def _subset(self, x, codes, w, rng):
        keep = np.arange(codes.size)
        if self.max_points is not None and keep.size > int(self.max_points):
            keep = np.sort(rng.choice(keep.size, int(self.max_points), replace=False))
        return x[keep], codes[keep], w[keep]

    def _fit_one(self, xb, codes, wb):
        est = clone(self.estimator if self.estimator is not None else LogisticRegression())
        lb = self.classes_[codes]
        kw = {}
        if self.weighted:
            name = est.steps[-1][0] if hasattr(est, "steps") else None
            kw = {f"{name}__sample_weight" if name else "sample_weight": wb}
        # the binned problems are small: one thread avoids BLAS / OpenMP oversubscription,
        # which on a loaded 2-core machine made boosting 20-40x slower
        with single_thread():
            est.fit(xb, lb, **kw)
        return est

    def predict(self, X) -> np.ndarray:
        """Class of each row of ``X`` (n × d features)."""
        check_is_fitted(self, "estimator_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        with single_thread():
            return self.estimator_.predict(X)

    def decision_function(self, X) -> np.ndarray:
        """Signed decision value (> 0: ``classes_[1]``) of each row of ``X``."""
        check_is_fitted(self, "estimator_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        if hasattr(self.estimator_, "decision_function"):
            return self.estimator_.decision_function(X)
        proba = self.estimator_.predict_proba(X)
        return proba[:, 1] - 0.5


@dataclass(frozen=True)
class ClassifierSpec:
    """A classifier of the comparison: display name and factory."""

    name: str
    label: str
    factory: Callable[..., BinnedClassifier]


def _discretizer() -> KBinsDiscretizer:
    return KBinsDiscretizer(n_bins=40, encode="onehot", strategy="uniform")


def _lr(random_state=None, **kw) -> BinnedClassifier:
    return BinnedClassifier(
        make_pipeline(StandardScaler(), LogisticRegression(C=10.0, max_iter=1000)),
        random_state=random_state,
    )


def _lsvc(random_state=None, **kw) -> BinnedClassifier:
    return BinnedClassifier(
        make_pipeline(StandardScaler(), LinearSVC(C=1.0, max_iter=20000)),
        random_state=random_state,
    )


def _dlr(random_state=None, **kw) -> BinnedClassifier:
    return BinnedClassifier(
        make_pipeline(_discretizer(), LogisticRegression(C=10.0, max_iter=2000)),
        random_state=random_state,
    )


def _dlsvc(random_state=None, **kw) -> BinnedClassifier:
    return BinnedClassifier(
        make_pipeline(_discretizer(), LinearSVC(C=1.0, max_iter=20000)),
        random_state=random_state,
    )


def _hgb(random_state=None, **kw) -> BinnedClassifier:
    return BinnedClassifier(
        HistGradientBoostingClassifier(max_iter=200, random_state=random_state or 0),
        random_state=random_state,
    )


def _rbf(
    random_state=None,
    C: float = 100.0,
    gamma: float = 1.0,
    max_points: int = 4000,
    feature_names=None,
    bin_width: float = 0.02,
    refine_width: float | None = 0.002,
    **kw,
):
    names = list(feature_names or [])
    weights = [RBF_FEATURE_WEIGHTS.get(n, 1.0) for n in names] if names else None
    return BinnedClassifier(
        make_pipeline(
            StandardScaler(), ColumnWeights(weights), SVC(kernel="rbf", C=C, gamma=gamma)
        ),
        bin_width=bin_width,
        weighted=False,
        max_points=max_points,
        refine_width=refine_width,
        random_state=random_state,
    )


#: The paper's six classifiers, in the order of its Table 1.
CLASSIFIERS: dict[str, ClassifierSpec] = {
    s.name: s
    for s in (
        ClassifierSpec("logistic_regression", "Logistic regression", _lr),
        ClassifierSpec("linear_svc", "Linear SVC", _lsvc),
        ClassifierSpec("discretized_lr", "Discretized logistic regression", _dlr),
        ClassifierSpec("discretized_linear_svc", "Discretized linear SVC", _dlsvc),
        ClassifierSpec("gradient_boosting", "Gradient boosting (histogram)", _hgb),
        ClassifierSpec("rbf_svc", "Nonlinear (RBF) SVC", _rbf),
    )
}


def make_classifier(name: str, random_state=None, **kw) -> BinnedClassifier:
    """A fresh classifier of the comparison by name (:data:`CLASSIFIERS`).

    Parameters
    ----------
    name : str
        One of :data:`CLASSIFIERS`.
    random_state : int or None
        Seed (subsets, boosting).
    **kw
        ``C`` (default 100), ``gamma`` (default 1, on weighted standardized features),
        ``max_points`` (default 4000), ``bin_width`` (default 0.02), ``refine_width``
        (default 0.002; LOEO 0.9998 against 0.9964 without refinement) of the RBF SVC, and
        ``feature_names`` (weights :data:`RBF_FEATURE_WEIGHTS` by name; default all 1).

    Raises
    ------
    ModelError
        If the name is unknown.
    """
    try:
        spec = CLASSIFIERS[name]
    except KeyError:
        raise ModelError(f"unknown classifier {name!r}; known: {', '.join(CLASSIFIERS)}") from None
    return spec.factory(random_state=random_state, **kw)


# -- lean decision functions: fast prediction, single-step use, JSON + NPZ persistence ----------


@dataclass(frozen=True)
class KernelDecision:
    """RBF-SVC decision function ``Σ c_i exp(−γ |z − s_i|²) + b`` on standardized z.

    Attributes
    ----------
    mean, scale : numpy.ndarray
        Standardization of the features (feature units).
    support : numpy.ndarray
        Standardized support vectors (n_sv × d).
    coef : numpy.ndarray
        Dual coefficients (n_sv).
    intercept : float
        Offset b.
    gamma : float
        RBF width γ (standardized units⁻²).
    """

    mean: np.ndarray
    scale: np.ndarray
    support: np.ndarray
    coef: np.ndarray
    intercept: float
    gamma: float

    kind = "rbf_svc"

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Decision value per row of ``X`` (features in their units); > 0 means latched."""
        z = (np.asarray(X, dtype=float) - self.mean) / self.scale
        out = np.empty(z.shape[0])
        sv = self.support
        ss = np.einsum("ij,ij->i", sv, sv)
        step = max(1, 4_000_000 // max(sv.shape[0], 1))
        for i in range(0, z.shape[0], step):
            a = z[i : i + step]
            d2 = a @ sv.T
            d2 *= -2.0
            d2 += np.einsum("ij,ij->i", a, a)[:, None]
            d2 += ss
            d2 *= -self.gamma
            np.exp(d2, out=d2)
            out[i : i + step] = d2 @ self.coef
        return out + self.intercept

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays for an NPZ file."""
        return {
            "mean": self.mean,
            "scale": self.scale,
            "support": self.support,
            "coef": self.coef,
            "intercept": np.array([self.intercept]),
            "gamma": np.array([self.gamma]),
        }

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> KernelDecision:
        """Inverse of :meth:`arrays`."""
        return cls(
            np.asarray(a["mean"]),
            np.asarray(a["scale"]),
            np.asarray(a["support"]),
            np.asarray(a["coef"]),
            float(np.asarray(a["intercept"])[0]),
            float(np.asarray(a["gamma"])[0]),
        )


@dataclass(frozen=True)
class LinearDecision:
    """Linear decision function ``w·z + b`` on standardized z (logistic regression, LinearSVC)."""

    mean: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    intercept: float

    kind = "linear"

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Decision value per row of ``X`` (features in their units); > 0 means latched."""
        z = (np.asarray(X, dtype=float) - self.mean) / self.scale
        return z @ self.weights + self.intercept

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays for an NPZ file."""
        return {
            "mean": self.mean,
            "scale": self.scale,
            "weights": self.weights,
            "intercept": np.array([self.intercept]),
        }

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> LinearDecision:
        """Inverse of :meth:`arrays`."""
        return cls(
            np.asarray(a["mean"]),
            np.asarray(a["scale"]),
            np.asarray(a["weights"]),
            float(np.asarray(a["intercept"])[0]),
        )


class SklearnDecision:
    """Decision function of any fitted classifier (not saveable without pickle)."""

    kind = "sklearn"

    def __init__(self, estimator) -> None:
        self.estimator = estimator

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Decision value per row of ``X``; > 0 means the second class."""
        return self.estimator.decision_function(np.asarray(X, dtype=float))

    def arrays(self) -> dict[str, np.ndarray]:
        raise ModelError(
            f"a {type(self.estimator).__name__} classifier cannot be saved as JSON + NPZ; "
            "use classifier='rbf_svc', 'logistic_regression' or 'linear_svc'"
        )


def lean_decision(clf: BinnedClassifier):
    """Lean decision function of a fitted :class:`BinnedClassifier` (> 0: second class).

    RBF SVCs and linear models behind a ``StandardScaler`` become :class:`KernelDecision` /
    :class:`LinearDecision` (fast, saveable); anything else is wrapped as is.
    """
    est = clf.estimator_
    steps = list(getattr(est, "steps", []))
    weights = None
    if len(steps) == 3 and isinstance(steps[1][1], ColumnWeights):
        weights = steps.pop(1)[1].weights_
    if len(steps) == 2 and isinstance(steps[0][1], StandardScaler):
        scaler, model = steps[0][1], steps[1][1]
        scale = scaler.scale_.copy()
        if weights is not None:
            with np.errstate(divide="ignore"):
                scale = np.where(weights > 0, scale / np.where(weights > 0, weights, 1), np.inf)
        if isinstance(model, SVC) and model.kernel == "rbf":
            return KernelDecision(
                scaler.mean_.copy(),
                scale,
                model.support_vectors_.copy(),
                model.dual_coef_[0].copy(),
                float(model.intercept_[0]),
                float(model._gamma),
            )
        if isinstance(model, LogisticRegression | LinearSVC):
            return LinearDecision(
                scaler.mean_.copy(),
                scale,
                model.coef_[0].copy(),
                float(model.intercept_[0]),
            )
    return SklearnDecision(clf)
