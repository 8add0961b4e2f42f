"""A floor under a single GP's predictive variance, from its leave-one-experiment-out residuals.

One GP over the whole operating range (``gp_base``, ``gp_didt``) has one noise variance,
while its error is far from uniform: on the latched plateau the clutch pressure follows the
line pressure's wander, which its features do not see, and at a latch snap its smooth mean
rounds off a step of several bar. Its own std says neither: on the held-back 5 s and 20 s
ramps of the default stand (seeds 0–2, trained on 2.5 s + 40 s) ±2σ of ``gp_didt``'s own
std held 76–81 % of the latched-plateau samples and 45–49 % of those within 0.15 s of a
switch.

Here the variance of a *measured* dither-period mean around the prediction is learned where
the GP cannot see it:

1. residuals of the fitted GP's mean on each training experiment, with that experiment
   left out (:meth:`LocalGPRegressor.conditioned_on`: same hyperparameters, one
   factorization per experiment), every ``stride``-th sample;
2. a second GP (RBF, ARD) on the same features regresses ``ln r²``; since
   ``E[ln χ²₁] = −1.27``, ``exp(m(x) + 1.27)`` estimates the residual variance at ``x``
   (the heteroscedastic-GP construction of Kersting et al., "Most likely heteroscedastic
   Gaussian process regression", ICML 2007, with held-out instead of in-sample residuals:
   in sample the GP fits part of the training runs' line wander through their dither
   settings, and on the default stand, seed 0, its latched-plateau residual was 0.11 bar
   RMS in sample against 0.17 bar on the held-back ramps).

The predictive variance is then ``max(GP variance, floor)``: the floor never narrows a band.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import clone

from ._threads import map_folds, single_thread
from .local_gp import LocalGPRegressor

__all__ = ["LOG_CHI2_1_MEAN", "fit_variance_floor", "loeo_residuals", "variance_floor"]

#: ``E[ln χ²₁] = −γ − ln 2`` (γ Euler's constant): the bias of ``ln r²`` against ``ln σ²``.
LOG_CHI2_1_MEAN = -1.2703628454614782
#: Added to ``r²`` before the log (bar²): residuals below 1 mbar are not resolved.
_R2_FLOOR_BAR2 = 1e-6


def loeo_residuals(gp: LocalGPRegressor, blocks, stride: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of ``gp``'s mean on each block, predicted with that block left out.

    Parameters
    ----------
    gp : LocalGPRegressor
        The GP fitted on all ``blocks``.
    blocks : sequence
        Training experiments, each with ``X`` (n × d features), ``y`` (n targets, bar) and
        ``weight`` (n effective-observation weights).
    stride : int
        Every ``stride``-th sample of each block is predicted.

    Returns
    -------
    X : numpy.ndarray
        m × d features of the predicted samples.
    r : numpy.ndarray
        m residuals, measured minus predicted (bar).
    """

    def held_out(k: int) -> tuple[np.ndarray, np.ndarray]:
        rest = [b for j, b in enumerate(blocks) if j != k]
        with single_thread("blas"):
            fold = gp.conditioned_on(
                np.vstack([b.X for b in rest]),
                np.concatenate([b.y for b in rest]),
                np.concatenate([b.weight for b in rest]),
            )
        held = blocks[k]
        rows = np.arange(0, held.X.shape[0], max(1, int(stride)))
        return held.X[rows], held.y[rows] - fold.predict(held.X[rows])

    # The folds are independent and their factorizations release the GIL: one BLAS thread
    # per fold, two folds at a time; results keep the fold order.
    out = map_folds(held_out, len(blocks))
    return np.vstack([x for x, _ in out]), np.concatenate([r for _, r in out])


def fit_variance_floor(
    X: np.ndarray, r: np.ndarray, gp: LocalGPRegressor | None = None
) -> LocalGPRegressor:
    """The GP of ``ln r²`` over the features (RBF, ARD; see the module docstring).

    Parameters
    ----------
    X : numpy.ndarray
        m × d features.
    r : numpy.ndarray
        m residuals (bar).
    gp : LocalGPRegressor, optional
        Unfitted GP whose settings (binning, subset, seed) the floor's GP takes, with the
        RBF kernel — the estimator's own; default ``LocalGPRegressor(random_state=0)``.

    Returns
    -------
    LocalGPRegressor
        Fitted on ``ln(r² + 1e-6 bar²)``.
    """
    base = gp if gp is not None else LocalGPRegressor(random_state=0)
    return clone(base).set_params(kernel="rbf").fit(X, np.log(np.square(r) + _R2_FLOOR_BAR2))


def variance_floor(floor_gp: LocalGPRegressor, X: np.ndarray) -> np.ndarray:
    """Residual variance (bar²) at ``X``: ``exp(m(x) − E[ln χ²₁])``."""
    return np.exp(floor_gp.predict(X) - LOG_CHI2_1_MEAN)
