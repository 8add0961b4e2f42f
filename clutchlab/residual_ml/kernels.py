"""Stationary kernels of the local GPs: rational quadratic and RBF, per-input length scales.

Both kernels work on inputs already divided by the length scales. The hyperparameters live in
log space, in the order ``[log s², log ℓ_1 … log ℓ_d, (log α)]`` (one ``log ℓ`` when the kernel
is isotropic, ``log α`` for the rational quadratic only):

- rational quadratic, ``k(x, x') = s² · (1 + r² / (2α))^(−α)``,
- RBF (squared exponential), ``k(x, x') = s² · exp(−r² / 2)``,

with ``r² = Σ_j (x_j − x'_j)² / ℓ_j²``; as α → ∞ the first tends to the second. These are
scikit-learn's ``ConstantKernel * RationalQuadratic`` and ``ConstantKernel * RBF`` (with
per-input length scales, which scikit-learn's ``RationalQuadratic`` lacks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["KERNELS", "KernelSpec", "kernel_spec", "sq_dist"]

#: Kernel names understood by :func:`kernel_spec`.
KERNELS = ("rq", "rbf")


def sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances between the rows of ``a`` (n × d) and ``b`` (m × d).

    Uses one matrix product (``|a|² + |b|² − 2 a·bᵀ``) and clips the rounding below 0.

    Parameters
    ----------
    a, b : numpy.ndarray
        Points in length-scale units (dimensionless).

    Returns
    -------
    numpy.ndarray
        n × m array of squared distances (dimensionless).
    """
    aa = np.einsum("ij,ij->i", a, a)
    bb = np.einsum("ij,ij->i", b, b)
    d2 = a @ b.T
    d2 *= -2.0
    d2 += aa[:, None]
    d2 += bb[None, :]
    np.maximum(d2, 0.0, out=d2)
    return d2


@dataclass(frozen=True)
class KernelSpec:
    """A kernel family with its hyperparameter layout.

    Parameters
    ----------
    name : {"rq", "rbf"}
        Rational quadratic or RBF.
    n_dims : int
        Number of inputs d.
    ard : bool
        One length scale per input (True) or one shared length scale (False).
    """

    name: str
    n_dims: int
    ard: bool = True

    def __post_init__(self) -> None:
        if self.name not in KERNELS:
            raise ValueError(f"unknown kernel {self.name!r}; known: {', '.join(KERNELS)}")
        if self.n_dims < 1:
            raise ValueError(f"a kernel needs at least one input, got n_dims={self.n_dims}")

    @property
    def n_length(self) -> int:
        """Number of length scales."""
        return self.n_dims if self.ard else 1

    @property
    def n_params(self) -> int:
        """Number of kernel hyperparameters (signal variance, length scales, α)."""
        return 1 + self.n_length + (1 if self.name == "rq" else 0)

    @property
    def param_names(self) -> list[str]:
        """Names of the log-hyperparameters, in order."""
        names = ["log_signal_var"] + [f"log_length_{j}" for j in range(self.n_length)]
        return names + (["log_alpha"] if self.name == "rq" else [])

    def unpack(self, theta: np.ndarray) -> tuple[float, np.ndarray, float]:
        """Signal variance s², per-input length scales ℓ (d,), α (inf for RBF)."""
        theta = np.asarray(theta, dtype=float)
        s2 = float(np.exp(theta[0]))
        ell = np.exp(theta[1 : 1 + self.n_length])
        ell = np.broadcast_to(ell, (self.n_dims,)).copy()
        alpha = float(np.exp(theta[1 + self.n_length])) if self.name == "rq" else np.inf
        return s2, ell, alpha

    def _profile(self, d2: np.ndarray, alpha: float) -> np.ndarray:
        """Unit-variance kernel value from r², in place."""
        if self.name == "rbf":
            d2 *= -0.5
        else:
            d2 *= 0.5 / alpha
            np.log1p(d2, out=d2)
            d2 *= -alpha
        np.exp(d2, out=d2)
        return d2

    def __call__(self, theta: np.ndarray, a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
        """Kernel matrix K(a, b).

        Parameters
        ----------
        theta : numpy.ndarray
            Log-hyperparameters (:attr:`param_names`).
        a, b : numpy.ndarray
            Inputs (n × d, m × d) in the scaled units of the regressor; ``b`` defaults to ``a``.

        Returns
        -------
        numpy.ndarray
            n × m kernel matrix (units of s², i.e. normalized target squared).
        """
        s2, ell, alpha = self.unpack(theta)
        a = a / ell
        b = a if b is None else b / ell
        k = self._profile(sq_dist(a, b), alpha)
        k *= s2
        return k

    def diag(self, theta: np.ndarray, n: int) -> np.ndarray:
        """Prior variance k(x, x) for n points (s², stationary)."""
        return np.full(n, float(np.exp(theta[0])))

    def _gradient_terms(self, theta: np.ndarray, x: np.ndarray):
        """What both gradient forms share: s², α, the centred scaled inputs, r², the
        unit-variance kernel, ``dr`` (dk/dlog ℓ_j = s²·dr·r_j²) and, for the rational
        quadratic, ``1 + r²/2α`` and its log (None for the RBF)."""
        s2, ell, alpha = self.unpack(theta)
        xs = x / ell
        xs -= xs.mean(axis=0)  # distances unchanged; the contractions' expansion keeps digits
        d2 = sq_dist(xs, xs)
        if self.name == "rbf":
            kern = np.exp(-0.5 * d2)
            return s2, alpha, xs, d2, kern, kern, None, None  # dk/d(r²) = −½ k
        base = 1.0 + d2 / (2.0 * alpha)
        logb = np.log(base)
        kern = np.exp(-alpha * logb)
        return s2, alpha, xs, d2, kern, kern / base, base, logb  # (1 + r²/2α)^(−α−1)

    def with_gradient(self, theta: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, list]:
        """K(x, x) and its derivatives with respect to each log-hyperparameter.

        Parameters
        ----------
        theta : numpy.ndarray
            Log-hyperparameters.
        x : numpy.ndarray
            n × d inputs (scaled units).

        Returns
        -------
        K : numpy.ndarray
            n × n kernel matrix.
        grads : list of numpy.ndarray
            ``dK/dθ_i`` (n × n each), in the order of :attr:`param_names`.
        """
        s2, alpha, xs, d2, kern, dr, base, logb = self._gradient_terms(theta, x)
        K = s2 * kern
        grads = [K]
        if self.ard:
            for j in range(self.n_dims):
                rj2 = (xs[:, j, None] - xs[None, :, j]) ** 2
                grads.append(s2 * dr * rj2)
        else:
            grads.append(s2 * dr * d2)
        if self.name == "rq":
            u = d2 / (2.0 * alpha)
            # dk/dlog α = α · k · (−log(1 + u) + u / (1 + u))
            grads.append(K * alpha * (-logb + u / base))
        return K, grads

    def with_contractions(self, theta: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, object]:
        """K(x, x) and a function that contracts a symmetric matrix with every ``dK/dθ_i``.

        The marginal likelihood's gradient needs only ``Σ_kl W_kl ∂K_kl/∂θ_i`` for one
        symmetric ``W``; this gives those sums without forming the d + 2 derivative
        matrices of :meth:`with_gradient`: for a length scale
        ``Σ_kl M_kl (x_kj − x_lj)² = 2 Σ_k m_k x_kj² − 2 x_jᵀ M x_j`` with
        ``M = W ⊙ ∂k/∂(r²)``-like weights and ``m`` its row sums (inputs centred first,
        so the expansion loses no digits to a common offset).

        Parameters
        ----------
        theta : numpy.ndarray
            Log-hyperparameters.
        x : numpy.ndarray
            n × d inputs (scaled units).

        Returns
        -------
        K : numpy.ndarray
            n × n kernel matrix (a new array the caller may modify).
        contract : callable
            ``contract(W)`` → array of ``Σ W ⊙ dK/dθ_i`` in the order of
            :attr:`param_names`, for a symmetric n × n ``W``.
        """
        s2, alpha, xs, d2, kern, dr, base, logb = self._gradient_terms(theta, x)

        def contract(W: np.ndarray) -> np.ndarray:
            out = np.empty(self.n_params)
            out[0] = s2 * np.vdot(W, kern)
            M = W * dr
            M *= s2
            if self.ard:
                m = M.sum(axis=1)
                out[1 : 1 + self.n_dims] = 2.0 * (m @ xs**2) - 2.0 * np.einsum(
                    "kj,kj->j", xs, M @ xs
                )
            else:
                out[1] = np.vdot(M, d2)
            if self.name == "rq":
                u = d2 / (2.0 * alpha)
                u /= base
                u -= logb
                u *= kern
                out[-1] = s2 * alpha * np.vdot(W, u)
            return out

        return s2 * kern, contract


def kernel_spec(name: str, n_dims: int, ard: bool = True) -> KernelSpec:
    """The :class:`KernelSpec` of kernel ``name`` ("rq" or "rbf") on ``n_dims`` inputs."""
    return KernelSpec(str(name).lower(), int(n_dims), bool(ard))
