"""Sparse regression of the residual on a library of candidate terms (pysindy).

The terms are polynomials (degree ≤ 2, with interactions) of the standardized signals
of :data:`~.residuals.SIGNALS` — current, dI/dt and its sign, pressure and its rate,
line pressure, oil temperature, dither amplitude and frequency — built by pysindy's
``PolynomialLibrary`` and selected by its sequentially thresholded least squares
(``STLSQ``). It shows which signals drive the residual; it names no physics (that is
:mod:`.scoring`'s job).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass, field

import numpy as np

from .residuals import SIGNALS, ResidualSet

__all__ = ["SparseFit", "sparse_regression"]

#: At most this many residuals enter the regression (evenly thinned beyond).
MAX_ROWS = 20_000
#: A signal (or library term) this correlated with one already in is left out as its alias.
ALIAS_CORR = 0.98
#: Ridge penalty of STLSQ per residual, on standardized terms.
RIDGE = 0.01


@dataclass
class SparseFit:
    """Sparse model ``r ≈ σ_r Σ ξ_j θ_j(z)`` of the residual on standardized signals ``z``.

    Attributes
    ----------
    terms : list of dict
        Kept terms, largest |coefficient| first: ``term`` (pysindy name over the signal
        names), ``coef`` (residual standard deviations per standardized term).
    r2 : float
        Fraction of the residual variance the sparse model explains.
    signals : list of str
        Signals that appear in a kept term, by total |coefficient|.
    threshold : float
        STLSQ threshold used.
    n_library : int
        Number of candidate terms.
    aliases : dict
        Signals left out because they move with one already in (|corr| > 0.98 on these
        data, e.g. a dither amplitude that is a linear function of the current): name ->
        the signal that stands for it.
    """

    terms: list[dict] = field(default_factory=list)
    r2: float = 0.0
    signals: list[str] = field(default_factory=list)
    threshold: float = 0.0
    n_library: int = 0
    aliases: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return asdict(self)

    def equation(self, n_terms: int = 6) -> str:
        """The largest terms as text: ``r/σ ≈ +0.52 pressure_bar −0.31 didt_sign …``."""
        if not self.terms:
            return "r/σ ≈ 0 (no term kept)"
        parts = [f"{t['coef']:+.2f} {t['term']}" for t in self.terms[:n_terms]]
        more = f" … ({len(self.terms) - n_terms} more)" if len(self.terms) > n_terms else ""
        return "r/σ ≈ " + " ".join(parts) + more


def sparse_regression(res: ResidualSet, threshold: float = 0.05, degree: int = 2) -> SparseFit:
    """STLSQ of the kept residuals on a polynomial library of the standardized signals.

    Parameters
    ----------
    res : ResidualSet
        Residuals (bar) and signals.
    threshold : float
        STLSQ threshold on the standardized coefficients.
    degree : int
        Polynomial degree of the library.

    Returns
    -------
    SparseFit
    """
    import pysindy as ps

    r = res.r[res.keep]
    names, cols, aliases = [], [], {}
    for name in SIGNALS:
        x = res.signals[name][res.keep]
        sd = float(np.std(x))
        if not (x.size and sd > 1e-9 * (1.0 + abs(float(np.mean(x))))):
            continue
        z = (x - x.mean()) / sd
        twin = next(
            (n for n, c in zip(names, cols, strict=True) if abs(np.mean(z * c)) > ALIAS_CORR), None
        )
        if twin is not None:
            aliases[name] = twin
            continue
        names.append(name)
        cols.append(z)
    sd_r = float(np.std(r))
    if not names or sd_r <= 0 or r.size < 10:
        return SparseFit(threshold=threshold, aliases=aliases)
    step = max(len(r) // MAX_ROWS, 1)
    z = np.column_stack(cols)[::step]
    y = ((r - r.mean()) / sd_r)[::step]
    lib = ps.PolynomialLibrary(degree=degree, include_bias=False)
    lib.fit(z)
    theta = np.asarray(lib.transform(z))
    feature_names = lib.get_feature_names(names)
    mu, sd = theta.mean(axis=0), theta.std(axis=0)
    ok = sd > 0
    theta = (theta[:, ok] - mu[ok]) / sd[ok]
    feature_names = [f for f, k in zip(feature_names, ok, strict=True) if k]
    kept: list[int] = []
    for k in range(theta.shape[1]):
        if all(abs(np.mean(theta[:, k] * theta[:, j])) <= ALIAS_CORR for j in kept):
            kept.append(k)
    theta = theta[:, kept]
    feature_names = [feature_names[k] for k in kept]
    opt = ps.STLSQ(threshold=threshold, alpha=RIDGE * len(y), max_iter=50)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        opt.fit(theta, y.reshape(-1, 1))
    coef = np.asarray(opt.coef_).ravel()
    pred = theta @ coef
    r2 = float(1.0 - np.sum((y - pred) ** 2) / np.sum(y**2))
    order = np.argsort(-np.abs(coef))
    terms = [{"term": feature_names[k], "coef": float(coef[k])} for k in order if coef[k] != 0]
    weight = {n: 0.0 for n in names}
    for t in terms:
        for n in names:
            if n in t["term"].split(" ") or any(
                part.split("^")[0] == n for part in t["term"].split(" ")
            ):
                weight[n] += abs(t["coef"])
    used = [n for n in sorted(weight, key=lambda n: -weight[n]) if weight[n] > 0]
    return SparseFit(terms, r2, used, threshold, len(feature_names), aliases)
