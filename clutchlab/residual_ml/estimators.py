"""The paper's three stages as estimators: GP on (I, A_d, f_d), + dI/dt, SVC-partitioned GP.

=====================  ===========================================  ==========================
variant                estimator                                    paper
=====================  ===========================================  ==========================
``gp_base``            :class:`GPBaseline` — one GP on I, A_d, f_d   stage 1
``gp_didt``            :class:`GPWithDerivative` — + dI/dt           stage 2
``paper_svc_gp``       :class:`SVCPartitionedGP` — latch decision     stage 3 (final model)
                       + one GP per latch state (the paper: RBF-SVC
                       classifier and RQ GPs, ``paper_faithful``)
=====================  ===========================================  ==========================

All GPs are :class:`~clutchlab.residual_ml.local_gp.LocalGPRegressor` (binned, hyperparameters
by marginal likelihood); see :mod:`~clutchlab.residual_ml.base` for the accepted inputs.
"""

from __future__ import annotations

import inspect
from types import MappingProxyType

import numpy as np

from ..data import Trace
from ..errors import DataError, ModelError, ParameterWarning, warn_at_caller
from ._threads import map_folds
from .base import Block, TraceEstimator
from .classifiers import lean_decision, make_classifier
from .features import BASE_FEATURES, LAG_DIDT_FEATURES, target_pressure
from .labels import LatchLabelRule
from .latch_event import (
    EventDecision,
    decision_current_columns,
    event_features,
    fit_event_decision,
    latch_events,
)
from .latch_local import LocalEventDecision, fit_local_event_decision
from .latch_timing import (
    LatchTiming,
    mixture_interval_std,
    rate_anchors,
    switch_errors,
    switches,
)
from .local_gp import LocalGPRegressor
from .paths import knot_indices, piecewise_classes, predict_on_path
from .rate_bridge import bridge_weight, group_log_rates
from .residual_variance import fit_variance_floor, loeo_residuals, variance_floor

__all__ = [
    "DEFAULT_LATCH_MODEL",
    "GP_PRESSURE_RATE_SCALE",
    "LATCH_BANDWIDTH",
    "LATCH_MODELS",
    "LATCH_RATE_SCALE",
    "LATCH_RATE_SCALES",
    "PRESSURE_RATE_SCALE",
    "STD_OPTIONS",
    "GPBaseline",
    "GPWithDerivative",
    "SVCPartitionedGP",
    "mean_only",
]

#: Values of ``SVCPartitionedGP(latch_model=...)``, and its default.
LATCH_MODELS: tuple[str, ...] = ("classifier", "event", "local_event")
DEFAULT_LATCH_MODEL = "local_event"
#: Default ``κ`` of :mod:`~clutchlab.residual_ml.latch_timing` (``latch_rate_scale``) per
#: latch model: calibrated by ``studies/latch_timing.py`` on held-back training-side ramps
#: (5 s and 20 s, trained on 2.5 s + 40 s) of the stand and four zoo plants, seeds 0–2 —
#: the smallest value of the grid 0, 0.5, 1, 1.5, 2, 3 with ≥ 90 % latch-window coverage on
#: every circuit in its worst seed (BENCHMARKS.md, "Latch-timing uncertainty"): 1.5 for
#: the local latch-event law, 2 for the classifier (1.5 when the rule read the mean over
#: seeds); the one-plane event law was not calibrated and takes the classifier's.
LATCH_RATE_SCALES: MappingProxyType[str, float] = MappingProxyType(
    {"local_event": 1.5, "classifier": 2.0, "event": 2.0}
)
LATCH_RATE_SCALE = LATCH_RATE_SCALES[DEFAULT_LATCH_MODEL]
#: Default ``κ_p`` of the pressure's rate bridge (``pressure_rate_scale``,
#: :mod:`~clutchlab.residual_ml.rate_bridge`), calibrated likewise with the default latch
#: model and its ``κ`` (``studies/latch_timing.py --scale pressure``: the smallest value of
#: the same grid with ≥ 90 % regulated-region coverage on every circuit in its worst seed).
PRESSURE_RATE_SCALE = 1.5
#: Default ``κ_p`` of the single GPs' rate bridge (``GPBaseline`` / ``GPWithDerivative``
#: ``pressure_rate_scale``): there it also carries the latch switch between the trained
#: rates, which one GP moves with its dI/dt feature. Calibrated by
#: ``studies/gp_uncertainty.py`` on held-back training-side ramps (BENCHMARKS.md).
GP_PRESSURE_RATE_SCALE = 1.5
#: Default bandwidth of the local latch-event law (``latch_bandwidth``): the value of the
#: grid 0.2, 0.35, 0.5, 0.7, 1 with the lowest latch-timing error on held-back
#: training-side ramps (5 s and 20 s, trained on 2.5 s + 40 s) of the stand and four zoo
#: plants, seeds 0–2 (``studies/latch_event.py --local``; 0.2 and 0.35 tie within 0.2 %).
LATCH_BANDWIDTH = 0.2
#: The predictive-std options of the estimators and their values (the default first, the
#: GP's own std last; an estimator has those of its parameters): the model check and
#: :func:`mean_only` read them too.
STD_OPTIONS: MappingProxyType[str, tuple[str, str]] = MappingProxyType(
    {
        "latch_uncertainty": ("mixture", "none"),
        "rate_uncertainty": ("bridge", "none"),
        "noise_model": ("frequency", "constant"),
        "residual_variance": ("loeo", "none"),
    }
)
#: Below this |dI/dt| (mA/s) a sample holds: no rate to interpolate.
_MOVING_MA_S = 10.0
#: Median of a χ² variable with one degree of freedom: median(r²) / this estimates σ².
_MEDIAN_CHI2_1 = 0.454936


def mean_only(est):
    """``est`` with the std-only parts of its fit switched off (its mean is unchanged).

    For fits whose predictions are only scored by their mean (folds of a model choice): the
    :data:`STD_OPTIONS` cost extra decision fits, leave-one-experiment-out refits and
    residual evaluations and do not move the mean. Other estimators are returned as they
    are.
    """
    params = est.get_params(deep=False)
    off = {k: choices[-1] for k, choices in STD_OPTIONS.items() if k in params}
    return est.set_params(**off) if off else est


class _GPParams:
    """GP keyword arguments shared by the estimators."""

    _default_kernel = "rbf"

    def _kernel(self) -> str:
        return self.kernel if self.kernel is not None else self._default_kernel

    def _gp(self) -> LocalGPRegressor:
        return LocalGPRegressor(
            kernel=self._kernel(),
            ard=self.ard,
            bin_width=self.bin_width,
            bin_frac=self.bin_frac,
            max_points=self.max_points,
            n_hyper=self.n_hyper,
            n_restarts=self.n_restarts,
            random_state=self.random_state,
        )

    @staticmethod
    def _gp_fn(gp: LocalGPRegressor, return_std: bool, noise=None):
        """Mean, and the predictive std of a *measured* dither-period mean (bar): the GP's
        latent std and its observation noise (the variance of one weight-1 observation,
        i.e. one dither period's mean; or ``noise(x)``, bar² per row, when given), so a
        ±2σ band is where a measurement falls."""
        const = float(gp.noise_var_) if return_std else 0.0

        def fn(x):
            xs = gp._scale(x)
            if return_std:
                var = const if noise is None else noise(x)
                return gp._mean_scaled(xs), np.sqrt(gp._std_scaled(xs) ** 2 + var)
            return gp._mean_scaled(xs)

        return fn

    def _didt_column(self) -> int:
        """Column of the dI/dt feature among all features (−1 when absent)."""
        return decision_current_columns(self.feature_names_)[1]

    def _trained_log_rates(self, blocks: list[Block]) -> list[float]:
        """Log ramp rate of each trained rate group (one median |dI/dt| per experiment)."""
        didt = self._didt_column()
        if didt < 0 or blocks[0].name == "arrays":
            return []
        per_exp = []
        for blk in blocks:
            rate = np.abs(blk.X[:, didt])
            moving = rate > _MOVING_MA_S
            if moving.any():
                per_exp.append(float(np.log(np.median(rate[moving]))))
        return [float(np.mean([per_exp[j] for j in g])) for g in group_log_rates(per_exp)]

    def _rate_bridge_var(self, X: np.ndarray, knots: np.ndarray, mean_at) -> np.ndarray | None:
        """Per-sample variance (bar²) of interpolating the pressure between the trained rates.

        ``pressure_rate_scale`` times the change of the mean between the two bracketing
        trained rates (the sample's features with its dI/dt set to each; ``mean_at(Xs,
        knots)`` gives the mean at the knots' rows ``Xs``), through
        :mod:`~clutchlab.residual_ml.rate_bridge`'s bridge; 0 on samples that hold. None
        when ``rate_uncertainty`` is ``"none"``, without a dI/dt feature or with fewer than
        two trained rates.
        """
        anchors = getattr(self, "train_log_rates_", [])
        didt = self._didt_column()
        if self.rate_uncertainty != "bridge" or len(anchors) < 2 or didt < 0:
            return None
        rate = np.abs(X[knots, didt])
        moving = rate > _MOVING_MA_S
        var = np.zeros(knots.size)
        if moving.any():
            kn = knots[moving]
            k, v = bridge_weight(np.log(rate[moving]), anchors)
            sign = np.sign(X[kn, didt])
            ends = []
            for side in (k, k + 1):
                Xs = X[kn].copy()
                Xs[:, didt] = sign * np.exp(np.asarray(anchors)[side])
                ends.append(mean_at(Xs, kn))
            var[moving] = (self.pressure_rate_scale * (ends[1] - ends[0])) ** 2 * v
        var = np.interp(np.arange(X.shape[0]), knots, var)
        return np.where(np.abs(X[:, didt]) > _MOVING_MA_S, var, 0.0)

    def _check_std_options(self) -> None:
        """ModelError unless each :data:`STD_OPTIONS` parameter holds one of its values."""
        params = self.get_params(deep=False)
        for name, choices in STD_OPTIONS.items():
            if name in params and params[name] not in choices:
                raise ModelError(
                    f"{name} must be {' or '.join(map(repr, choices))}, got {params[name]!r}"
                )


class GPBaseline(_GPParams, TraceEstimator):
    """Stage 1 of the paper: one GP on nominal current, dither amplitude and frequency.

    Parameters
    ----------
    features : tuple of str, optional
        Feature names (default ``("current_mA", "dither_amp_mA", "dither_freq_Hz")``).
    didt_periods : float
        dI/dt filter window in dither periods, when ``didt_mA_s`` is a feature (default 5).
    target : {"period_mean", "raw"}
        Training target: the dither-period-mean clutch pressure (default) or the raw one.
    lag_s : float or "auto"
        Time constant of the ``current_lag_mA`` feature, s, when it is one of the features;
        ``"auto"`` (default): chosen from the training experiments by leave-one-ramp-rate-out
        (:func:`~clutchlab.residual_ml.select_lag`; fitted value in ``lag_s_``).
    kernel : {"rq", "rbf"}, optional
        GP kernel. Default (None): the one chosen by leave-one-experiment-out on the 18
        training experiments of the default stand (6 held out in turn, RMSE of the
        dither-period-mean pressure; ``studies/ml_model_choices.py``, choice 1): RBF for
        :class:`GPBaseline` (0.615 against 0.679 bar for RQ) and :class:`SVCPartitionedGP`
        (0.104 against 0.118 bar), rational quadratic for :class:`GPWithDerivative` (0.164
        against 0.283 bar).
    ard : bool
        One length scale per feature (default).
    bin_width, bin_frac, max_points, n_hyper, n_restarts
        Binning and optimization settings of
        :class:`~clutchlab.residual_ml.local_gp.LocalGPRegressor`.
    knot_tol : float
        Path length between prediction knots along a trace, in units of the GPs' kernel
        resolution (default 0.1; 0 evaluates every sample). On the default stand data the
        dither-period-mean prediction then differs from exact evaluation of every sample by
        at most ~0.02 bar, at 5–10x the speed.
    max_knot_gap : int
        Most samples between prediction knots (default 100).
    random_state : int or None
        Seed of the GP's subset and restarts (default 0).
    rate_uncertainty : {"bridge", "none"}
        ``bridge`` (default): the predictive std of a sample on a ramp also holds the
        uncertainty of interpolating between the trained ramp rates — the GP's change
        between the two bracketing trained rates (the sample's features with its dI/dt set
        to each), times ``pressure_rate_scale``, through
        :mod:`~clutchlab.residual_ml.rate_bridge`'s bridge. For one GP over both latch
        states this also covers the latch switch, whose current moves with the rate. Needs
        a dI/dt feature and two trained rates (so nothing for :class:`GPBaseline`'s default
        features); ``none``: not added.
    pressure_rate_scale : float
        ``κ_p`` of that term (dimensionless; default :data:`GP_PRESSURE_RATE_SCALE`).
    residual_variance : {"loeo", "none"}
        ``loeo`` (default): the observation noise of the predictive std is at least a
        floor learned from the GP's leave-one-experiment-out residuals over the features
        (:mod:`~clutchlab.residual_ml.residual_variance`: the latched plateau's
        line-pressure wander, the snap the smooth mean rounds off). Needs two training
        experiments; costs one factorization per experiment and one more GP fit. ``none``:
        the GP's constant noise. The mean is unchanged either way.

    Attributes
    ----------
    gp_ : LocalGPRegressor
        The fitted GP.
    feature_names_ : list of str
        Feature columns, in order.
    train_experiments_ : list of str
        Names of the training experiments (empty when fitted on arrays).
    train_log_rates_ : list of float
        The trained ramp rates, ``ln(|dI/dt| / (mA/s))`` per rate group (empty without a
        dI/dt feature or on array input).
    variance_floor_ : LocalGPRegressor or None
        The GP of the log squared leave-one-experiment-out residual (None with
        ``residual_variance="none"``, one training experiment, or array input).
    """

    _default_features = BASE_FEATURES
    _default_kernel = "rbf"

    def __init__(
        self,
        features: tuple[str, ...] | None = None,
        didt_periods: float = 5.0,
        target: str = "period_mean",
        lag_s: float | str = "auto",
        kernel: str | None = None,
        ard: bool = True,
        bin_width: float = 0.01,
        bin_frac: float = 0.1,
        max_points: int = 3000,
        n_hyper: int = 2000,
        n_restarts: int = 0,
        knot_tol: float = 0.1,
        max_knot_gap: int = 100,
        random_state: int | None = 0,
        rate_uncertainty: str = "bridge",
        pressure_rate_scale: float = GP_PRESSURE_RATE_SCALE,
        residual_variance: str = "loeo",
    ) -> None:
        self.features = features
        self.didt_periods = didt_periods
        self.target = target
        self.lag_s = lag_s
        self.rate_uncertainty = rate_uncertainty
        self.pressure_rate_scale = pressure_rate_scale
        self.residual_variance = residual_variance
        self.kernel = kernel
        self.ard = ard
        self.bin_width = bin_width
        self.bin_frac = bin_frac
        self.max_points = max_points
        self.n_hyper = n_hyper
        self.n_restarts = n_restarts
        self.knot_tol = knot_tol
        self.max_knot_gap = max_knot_gap
        self.random_state = random_state

    def _fit_blocks(self, blocks: list[Block]) -> None:
        self._check_std_options()
        b = self._stack(blocks)
        self.gp_ = self._gp().fit(b.X, b.y, sample_weight=b.weight)
        self.train_log_rates_ = self._trained_log_rates(blocks)
        self.variance_floor_ = None
        if self.residual_variance == "loeo" and len(blocks) >= 2 and blocks[0].name != "arrays":
            Xr, r = loeo_residuals(self.gp_, blocks)
            self.variance_floor_ = fit_variance_floor(Xr, r, self._gp())

    def _observation_noise(self):
        """Per-row observation-noise variance (bar²): at least the residual-variance floor
        (None: the GP's constant noise)."""
        floor = getattr(self, "variance_floor_", None)
        if floor is None:
            return None
        gp_noise = float(self.gp_.noise_var_)
        return lambda x: np.maximum(gp_noise, variance_floor(floor, np.asarray(x)))

    def _predict_matrix(self, X: np.ndarray, path: bool, return_std: bool):
        fn = self._gp_fn(self.gp_, return_std, self._observation_noise() if return_std else None)
        if not path:
            return fn(X)
        knots = knot_indices(X, self.gp_.resolution_, self.knot_tol, self.max_knot_gap)
        classes = np.zeros(X.shape[0], dtype=np.int8)
        out = predict_on_path(X, classes, knots, {0: fn}, return_std)
        if not return_std:
            return out
        mean, std = out
        var = self._rate_bridge_var(X, knots, lambda Xs, _: self.gp_.predict(Xs))
        return mean, (std if var is None else np.sqrt(std**2 + var))

    def resolution(self) -> np.ndarray:
        """Per-feature kernel resolution used to place prediction knots (feature units)."""
        self._check_fitted()
        return self.gp_.resolution_


class GPWithDerivative(GPBaseline):
    """Stage 2 of the paper: :class:`GPBaseline` plus the filtered dI/dt as a feature.

    Same parameters as :class:`GPBaseline`; the default features are
    ``("current_lag_mA", "dither_amp_mA", "dither_freq_Hz", "didt_mA_s", "direction")`` (the
    nominal current through the circuit's lag, ``lag_s``) and the default kernel is the
    rational quadratic.
    """

    _default_features = LAG_DIDT_FEATURES
    _default_kernel = "rq"


class SVCPartitionedGP(_GPParams, TraceEstimator):
    """The paper's final model: a latch decision partitions the data, one GP per partition.

    Training: latch labels from the measured pressure
    (:class:`~clutchlab.residual_ml.labels.LatchLabelRule`); a latch decision is fitted on
    latched / unlatched samples — by default the local latch-event law
    (``latch_model="local_event"``), with ``latch_model="classifier"`` the paper's classifier
    (RBF SVC by default, the ``classifier`` and ``svc_*`` options), which is otherwise only
    the fallback; one GP (RBF by default, see ``kernel``) per latch state on that state's
    samples. Prediction: the decision picks the GP of every sample. The paper chose the
    rational-quadratic kernel for the local GPs; here the default is the RBF kernel, which
    leave-one-experiment-out preferred on the default stand data (``kernel="rq"`` gives the
    paper's choice).

    Parameters
    ----------
    features : tuple of str, optional
        Feature names (default
        ``("current_lag_mA", "dither_amp_mA", "dither_freq_Hz", "didt_mA_s", "direction")``:
        the nominal current through the circuit's lag, ``lag_s``).
    didt_periods, target, lag_s, kernel, ard, bin_width, bin_frac, max_points, n_hyper,
    n_restarts, knot_tol, max_knot_gap, random_state
        As in :class:`GPBaseline` (``didt_periods`` in dither periods, ``lag_s`` in s).
    label_rule : LatchLabelRule, optional
        Latch-label rule (default parameters when None).
    event_points : {"exclude", "assign"}
        Latch-event samples train no GP (``"exclude"``, default) or the GP of their
        Schmitt-trigger state (``"assign"``). With ``"assign"`` the unlatched GP has to
        follow the snap transient, which sits at a different current for every ramp rate.
        Leave-one-experiment-out on the training experiments of the default stand
        (``studies/ml_model_choices.py``, choice 2): 0.104 bar excluding, 0.110 bar
        assigning.
    classifier_features : tuple of str, optional
        Features the classifier sees (default: all of ``features``).
    classifier : str
        Classifier of :data:`~clutchlab.residual_ml.classifiers.CLASSIFIERS` (default
        ``"rbf_svc"``); only ``rbf_svc``, ``logistic_regression`` and ``linear_svc`` can be
        saved. It decides the latch state with ``latch_model="classifier"``, or when a
        latch-event law cannot be fitted; set otherwise while a law decides, it has no
        effect and :meth:`fit` says so (``ParameterWarning``), as for the ``svc_*`` options.
    svc_C, svc_gamma : float
        RBF-SVC penalty and width (on weighted standardized features; defaults 100, 1).
    svc_max_points : int
        Most training bins of the RBF SVC (default 4000).
    latch_model : {"classifier", "event", "local_event"}
        What decides the latch state: ``classifier`` (the paper: ``classifier`` on the
        classifier features), ``event``, the latch-event law of
        :mod:`~clutchlab.residual_ml.latch_event` (latch currents linear in the ramp rate,
        thresholds linear in the dither), or ``local_event``, the same law fitted locally
        in the dither setting (:mod:`~clutchlab.residual_ml.latch_local`, bandwidth
        ``latch_bandwidth``; the default: on held-back training-side ramps of the stand
        and four zoo plants it had the lower latch-timing error and RMSE on every circuit,
        ``studies/latch_event.py --local``). Both laws need a current, a dI/dt and a
        direction feature among the classifier features; without them, e.g. on feature
        arrays, or with fewer than two latch events of a direction for the local law, the
        classifier decides (``latch_model_`` says which did).
    latch_bandwidth : float
        Bandwidth ``h`` of ``latch_model="local_event"`` in standard deviations of the
        latch events' dither amplitude and frequency (default :data:`LATCH_BANDWIDTH`).
    latch_line : {"auto", "off"}
        ``auto`` (default): with ``latched_reference="line"`` and line pressure logged, the
        local law tests inside the training set whether the switch currents follow line
        pressure and keeps the coupling when it lowers their leave-one-event-out error
        enough (:func:`~clutchlab.residual_ml.latch_local.line_coupling`; the decision then
        needs line pressure). ``off``: never.
    latched_reference : {"line", "none"}
        ``line`` (default): the latched GP learns the clutch pressure *below line
        pressure* (the latched plateau is line pressure less a small offset that
        depends on the operating point) and adds the experiment's line pressure back, so
        the plateau follows line-pressure wander the features cannot see. Used when
        every training experiment logs ``line_pressure_bar``; prediction then needs it
        too. ``none``: the latched GP learns the clutch pressure itself (the paper).
    latch_uncertainty : {"mixture", "none"}
        ``mixture`` (default): the predictive std near a predicted switch covers a wrong
        latch state — the switch current's error is estimated inside the training set and
        the prediction there becomes a mixture of both regimes
        (:mod:`~clutchlab.residual_ml.latch_timing`; the mean is unchanged). ``none``: the
        std is the GP's alone.
    latch_rate_scale : float or None
        ``κ`` of :mod:`~clutchlab.residual_ml.latch_timing` (dimensionless): how much of the
        switch-current change between two trained ramp rates is taken as the uncertainty
        of interpolating it at a rate between them. None (default): the value calibrated
        for the latch model (:data:`LATCH_RATE_SCALES`).
    rate_uncertainty : {"bridge", "none"}
        ``bridge`` (default): the predictive std of a sample on a ramp also holds the
        uncertainty of interpolating the pressure between the trained ramp rates — the
        regime GP's change between the two bracketing trained rates (the sample's features
        with its dI/dt set to each), times ``pressure_rate_scale``, through
        :mod:`~clutchlab.residual_ml.rate_bridge`'s bridge. Needs a dI/dt feature and two
        trained rates. ``none``: not added.
    pressure_rate_scale : float
        ``κ_p`` of that term (dimensionless).
    noise_model : {"frequency", "constant"}
        Observation noise in the predictive std of a measured dither-period mean:
        ``frequency`` (default) at least the noise floor ``c + s·f`` per latch regime,
        fitted to the training residuals against the dither frequency ``f`` (a period
        mean of white noise has a variance proportional to ``f``); ``constant``: the GP's
        noise variance. Needs a ``dither_freq_Hz`` feature; the mean is unchanged.

    Attributes
    ----------
    gps_ : dict of int to LocalGPRegressor
        GP per latch state (0 unlatched, 1 latched).
    classifier_ : BinnedClassifier or None
        The fitted classifier (None when training data hold one latch state only).
    decision_ : callable or None
        Lean decision function of the classifier (> 0: latched).
    classifier_train_accuracy_ : float
        Classifier accuracy on its (non-event) training samples.
    latch_model_ : {"classifier", "event", "local_event", "none"}
        What decides the latch state as fitted (``none``: the training data hold one latch
        state, which is then predicted everywhere).
    latched_reference_ : {"line", "none"}
        The latched GP's reference as fitted (``none`` when a training experiment has no
        line pressure, or on array input).
    latch_timing_ : LatchTiming or None
        The switch-current error model (None with ``latch_uncertainty="none"``, one latch
        state, array input, or no current feature among the classifier features).
    train_log_rates_ : list of float
        The trained ramp rates, ``ln(|dI/dt| / (mA/s))`` per rate group (empty without a
        dI/dt feature or on array input).
    noise_by_freq_ : dict of int to (float, float)
        Per regime, ``(c, s)`` of the noise floor ``c + s·f``: bar², bar²/Hz (empty
        with ``noise_model="constant"``, no dither-frequency feature, or array input).
    """

    _default_features = LAG_DIDT_FEATURES

    def __init__(
        self,
        features: tuple[str, ...] | None = None,
        didt_periods: float = 5.0,
        target: str = "period_mean",
        lag_s: float | str = "auto",
        label_rule: LatchLabelRule | None = None,
        event_points: str = "exclude",
        classifier_features: tuple[str, ...] | None = None,
        classifier: str = "rbf_svc",
        svc_C: float = 100.0,
        svc_gamma: float = 1.0,
        svc_max_points: int = 4000,
        latch_model: str = DEFAULT_LATCH_MODEL,
        latch_bandwidth: float = LATCH_BANDWIDTH,
        latch_line: str = "auto",
        latched_reference: str = "line",
        latch_uncertainty: str = "mixture",
        latch_rate_scale: float | None = None,
        rate_uncertainty: str = "bridge",
        pressure_rate_scale: float = PRESSURE_RATE_SCALE,
        noise_model: str = "frequency",
        kernel: str | None = None,
        ard: bool = True,
        bin_width: float = 0.01,
        bin_frac: float = 0.1,
        max_points: int = 3000,
        n_hyper: int = 2000,
        n_restarts: int = 0,
        knot_tol: float = 0.1,
        max_knot_gap: int = 100,
        random_state: int | None = 0,
    ) -> None:
        self.features = features
        self.didt_periods = didt_periods
        self.target = target
        self.lag_s = lag_s
        self.label_rule = label_rule
        self.event_points = event_points
        self.classifier_features = classifier_features
        self.classifier = classifier
        self.svc_C = svc_C
        self.svc_gamma = svc_gamma
        self.svc_max_points = svc_max_points
        self.latch_model = latch_model
        self.latch_bandwidth = latch_bandwidth
        self.latch_line = latch_line
        self.latched_reference = latched_reference
        self.latch_uncertainty = latch_uncertainty
        self.latch_rate_scale = latch_rate_scale
        self.rate_uncertainty = rate_uncertainty
        self.pressure_rate_scale = pressure_rate_scale
        self.noise_model = noise_model
        self.kernel = kernel
        self.ard = ard
        self.bin_width = bin_width
        self.bin_frac = bin_frac
        self.max_points = max_points
        self.n_hyper = n_hyper
        self.n_restarts = n_restarts
        self.knot_tol = knot_tol
        self.max_knot_gap = max_knot_gap
        self.random_state = random_state

    def _make_classifier(self):
        return make_classifier(
            self.classifier,
            random_state=self.random_state,
            C=self.svc_C,
            gamma=self.svc_gamma,
            max_points=self.svc_max_points,
            feature_names=[self.feature_names_[j] for j in self._clf_cols()],
        )

    def _clf_cols(self) -> list[int]:
        if not self.classifier_features:
            return list(range(len(self.feature_names_)))
        missing = [f for f in self.classifier_features if f not in self.feature_names_]
        if missing:
            raise ModelError(
                f"classifier_features {missing} are not among the features {self.feature_names_}"
            )
        return [self.feature_names_.index(f) for f in self.classifier_features]

    def _decide(self, X: np.ndarray, ref: np.ndarray | None = None) -> np.ndarray:
        return _decision_values(self.decision_, X[:, self.classifier_columns_], ref)

    def _block(self, trace: Trace, physics: dict[str, np.ndarray] | None = None) -> Block:
        b = super()._block(trace, physics)
        if self.latched_reference == "line" and trace.has("line_pressure_bar"):
            b.ref = target_pressure(trace, self.target, "line_pressure_bar")
        return b

    def _trace_ref(self, trace: Trace) -> np.ndarray | None:
        """The latched reference of ``trace`` (bar) when the model was fitted with one."""
        if getattr(self, "latched_reference_", "none") != "line":
            return None
        if not trace.has("line_pressure_bar"):
            where = trace.name + (f" ({trace.source})" if trace.source is not None else "")
            raise DataError(
                f"{where}: no line_pressure_bar; this model predicts the latched plateau "
                "relative to line pressure (latched_reference='line', as fitted: its training "
                "experiments logged it): log line pressure, give the experiment a constant "
                "one (line_pressure_bar = 17.7 under [defaults] in its channel map), or fit "
                "with latched_reference='none' (`clutchlab train --latched-reference none`)"
            )
        # As logged (not period-averaged), as the FMU and the step predictor see it: the
        # prediction stays causal, and its period mean is the period-mean reference.
        return np.asarray(trace.get("line_pressure_bar"), dtype=float)

    def _fit_blocks(self, blocks: list[Block]) -> None:
        if self.event_points not in ("assign", "exclude"):
            raise ModelError(
                f"event_points must be 'assign' or 'exclude', got {self.event_points!r}"
            )
        if self.latched_reference not in ("line", "none"):
            raise ModelError(
                f"latched_reference must be 'line' or 'none', got {self.latched_reference!r}"
            )
        if self.latch_line not in ("auto", "off"):
            raise ModelError(f"latch_line must be 'auto' or 'off', got {self.latch_line!r}")
        b = self._stack(blocks)
        use_ref = self.latched_reference == "line" and b.ref is not None
        self.latched_reference_ = "line" if use_ref else "none"
        clean = b.labels >= 0
        present = sorted(set(np.unique(b.labels[clean]).tolist()))
        self.classifier_columns_ = self._clf_cols()
        if self.latch_model not in LATCH_MODELS:
            raise ModelError(f"latch_model must be one of {LATCH_MODELS}, got {self.latch_model!r}")
        self._check_std_options()
        self.latch_timing_ = None
        if len(present) >= 2:
            self.classifier_, self.decision_ = self._fit_decision(blocks, b)
            ref = None if b.ref is None else b.ref[clean]
            pred = (self._decide(b.X[clean], ref) > 0).astype(int)
            self.classifier_train_accuracy_ = float(np.mean(pred == b.labels[clean]))
            self.single_state_ = None
        else:
            self.classifier_ = None
            self.decision_ = None
            self.classifier_train_accuracy_ = 1.0
            self.single_state_ = int(present[0]) if present else int(b.state[0])
        group = b.state if self.event_points == "assign" else np.where(clean, b.labels, -1)
        self.gps_ = {}
        for g in (0, 1):
            rows = group == g
            if rows.sum() >= 2:
                y = b.y[rows] - b.ref[rows] if (use_ref and g == 1) else b.y[rows]
                self.gps_[g] = self._gp().fit(b.X[rows], y, sample_weight=b.weight[rows])
        if not self.gps_:
            raise ModelError(
                f"too few training samples for any latch state (n_samples={b.y.size}; each "
                "latch state needs at least 2)"
            )
        self.noise_by_freq_ = self._fit_noise_by_freq(blocks, use_ref)
        if self.latch_uncertainty == "mixture" and self.decision_ is not None:
            self.latch_timing_ = self._estimate_latch_timing(blocks)
        self.train_log_rates_ = self._trained_log_rates(blocks)
        self._warn_unused_classifier_options()

    #: Options that act only when a classifier decides the latch state.
    _CLASSIFIER_OPTIONS = ("classifier", "svc_C", "svc_gamma", "svc_max_points")

    def _warn_unused_classifier_options(self) -> None:
        """A ParameterWarning naming the classifier options set away from their defaults
        when a latch-event law, not the classifier, decided the latch state."""
        if self.decision_ is None or self.classifier_ is not None:
            return  # one latch state, or the classifier decides: nothing is ignored
        defaults = inspect.signature(type(self).__init__).parameters
        given = [
            f"{n}={getattr(self, n)!r}"
            for n in self._CLASSIFIER_OPTIONS
            if getattr(self, n) != defaults[n].default
        ]
        if given:
            warn_at_caller(
                f"{type(self).__name__}: {', '.join(given)} had no effect: the latch state is "
                f"decided by the {self.latch_model_} law (latch_model={self.latch_model!r}), "
                "not by a classifier (the classifier is only its fallback when the training "
                "data hold too few latch events); latch_model='classifier' uses them, as the "
                "paper did",
                ParameterWarning,
            )

    def _freq_column(self) -> int:
        names = self.feature_names_
        return names.index("dither_freq_Hz") if "dither_freq_Hz" in names else -1

    def _observation_noise(self, g: int):
        """Per-row observation-noise variance (bar²) of regime ``g``, or None (the GP's)."""
        coef = (getattr(self, "noise_by_freq_", None) or {}).get(g)
        col = self._freq_column()
        if coef is None or col < 0:
            return None
        c, slope = coef
        gp_noise = float(self.gps_[g].noise_var_)
        return lambda x: np.maximum(gp_noise, c + slope * np.asarray(x)[:, col])

    def _fit_noise_by_freq(self, blocks: list[Block], use_ref: bool) -> dict:
        """``(c, s)`` of the noise floor ``c + s·f`` per regime from the training residuals.

        The target is a dither-period mean: white measurement noise averaged over one
        period has a variance proportional to the dither frequency ``f`` (fewer samples per
        period), which one constant noise of the GP cannot follow (on a zoo plant's latched
        plateau the error grew 0.0059 / 0.0075 / 0.0089 bar at 30 / 50 / 70 Hz while the
        std stayed 0.0057 bar). Per training experiment a robust noise variance of each
        regime's in-sample residual (every 10th sample; median of r² / 0.455, the median of
        χ²₁, so transients do not count) is taken; per dither frequency the smallest of them
        is the floor (the experiment the GP fits best); ``c, s ≥ 0`` are fitted to the
        floors by non-negative least squares (``s = 0`` with one frequency). The predictive
        noise is then ``max(GP noise, c + s·f)``.
        """
        from scipy.optimize import nnls

        col = self._freq_column()
        if self.noise_model != "frequency" or col < 0 or blocks[0].name == "arrays":
            return {}
        group_of = (lambda b: b.state) if self.event_points == "assign" else (lambda b: b.labels)
        out = {}
        for g, gp in self.gps_.items():
            floor: dict[float, float] = {}
            for blk in blocks:
                rows = np.flatnonzero(group_of(blk) == g)[::10]
                if rows.size < 20:
                    continue
                y = blk.y[rows] - (blk.ref[rows] if (use_ref and g == 1) else 0.0)
                var = float(np.median((y - gp.predict(blk.X[rows])) ** 2) / _MEDIAN_CHI2_1)
                f = round(float(np.median(blk.X[rows, col])), 3)
                floor[f] = min(var, floor.get(f, np.inf))
            if not floor:
                continue
            f = np.array(sorted(floor))
            design = np.column_stack([np.ones_like(f), f if f.size > 1 else np.zeros_like(f)])
            coef, _ = nnls(design, np.array([floor[k] for k in sorted(floor)]))
            out[g] = (float(coef[0]), float(coef[1]))
        return out

    def _fit_decision(self, blocks: list[Block], b: Block | None = None):
        """Classifier (or None) and lean decision function fitted on ``blocks``."""
        b = self._stack(blocks) if b is None else b
        cols = self.classifier_columns_
        names = [self.feature_names_[j] for j in cols]
        if self.latch_model in ("event", "local_event") and event_features(names):
            events = [e for blk in blocks for e in latch_events(blk.X[:, cols], blk.state)]
            if self.latch_model == "event":
                return None, fit_event_decision(events, names)
            # The default law needs two events of each direction; with fewer (one
            # training experiment, a latch that never releases) the classifier decides.
            if min(sum(s == d for _, s in events) for d in (1, -1)) >= 2:
                line = self._event_line(blocks)
                never = [_peak_row(blk.X[:, cols], names) for blk in blocks if not blk.state.any()]
                return None, fit_local_event_decision(
                    events, names, self.latch_bandwidth, line, censored=never
                )
        clean = b.labels >= 0
        clf = self._make_classifier().fit(b.X[clean][:, cols], b.labels[clean])
        return clf, lean_decision(clf)

    def _event_line(self, blocks: list[Block]) -> np.ndarray | None:
        """Line pressure (bar) at each latch event of ``blocks`` (the order of
        :func:`latch_events`), or None without a line reference."""
        off = self.latch_line == "off" or self.latched_reference != "line"
        if off or any(blk.ref is None for blk in blocks):
            return None
        return np.array([blk.ref[k] for blk in blocks for k, _ in switches(blk.state)])

    def _timing_columns(self) -> tuple[int, int]:
        """Columns of the decision's current and dI/dt features (−1 when absent)."""
        names = [self.feature_names_[j] for j in self.classifier_columns_]
        cur, didt = decision_current_columns(names)
        cols = self.classifier_columns_
        return (cols[cur] if cur >= 0 else -1), (cols[didt] if didt >= 0 else -1)

    def _estimate_latch_timing(self, blocks: list[Block]) -> LatchTiming | None:
        """Switch-current errors of decisions fitted without each training experiment."""
        cur, didt = self._timing_columns()
        if cur < 0 or len(blocks) < 2 or blocks[0].name == "arrays":
            return None
        errors: dict[int, list[float]] = {1: [], -1: []}
        missed = {1: 0, -1: 0}
        events = []
        res = self.resolution()
        cols = self.classifier_columns_

        def held_out(k: int):
            """Predicted latch state of experiment ``k`` by a decision fitted without it."""
            rest = blocks[:k] + blocks[k + 1 :]
            present = {int(v) for blk in rest for v in np.unique(blk.labels[blk.labels >= 0])}
            if len(present) < 2:
                return None
            try:
                _, decide = self._fit_decision(rest)
            except ModelError:  # e.g. too few latch events without this experiment
                return None
            X = blocks[k].X
            knots = knot_indices(X, res, self.knot_tol, self.max_knot_gap)
            return _path_classes(
                lambda Z, ref: _decision_values(decide, Z[:, cols], ref), X, knots, blocks[k].ref
            )

        # The folds are independent and their binning, sorting and libsvm calls release the
        # GIL: two threads take ~0.6x the wall time of one on 2 cores; results keep the
        # fold order, so they do not depend on the scheduling.
        predicted = map_folds(held_out, len(blocks))
        for held, pred in zip(blocks, predicted, strict=True):
            if pred is None:
                continue
            got, lost = switch_errors(held.state, pred, held.X[:, cur])
            for d in (1, -1):
                errors[d] += got[d]
                missed[d] += lost[d]
            rate = np.abs(held.X[:, didt]) if didt >= 0 else np.full(held.X.shape[0], np.nan)
            events += [(float(rate[j]), float(held.X[j, cur]), d) for j, d in switches(held.state)]
        if not (errors[1] or errors[-1]):
            return None
        anchors = rate_anchors([e for e in events if np.isfinite(e[0])])
        return LatchTiming(
            fit_rms_mA={
                d: float(np.sqrt(np.mean(np.square(errors[d])))) if errors[d] else 0.0
                for d in (1, -1)
            },
            log_rates={d: anchors[d][0] for d in (1, -1)},
            currents={d: anchors[d][1] for d in (1, -1)},
            n_errors={d: len(errors[d]) for d in (1, -1)},
            n_missed=missed,
        )

    def _widen_for_rate(self, X, classes, knots, std, fns) -> np.ndarray:
        """``std`` with the pressure's rate-interpolation variance (``rate_uncertainty``)."""

        def mean_at(Xs: np.ndarray, kn: np.ndarray) -> np.ndarray:
            mu = np.empty(kn.size)
            for g in (0, 1):
                sel = classes[kn] == g
                if sel.any():
                    mu[sel] = fns[g](Xs[sel])[0]
            return mu

        var = self._rate_bridge_var(X, knots, mean_at)
        return std if var is None else np.sqrt(std**2 + var)

    def _widen_at_switches(self, X, classes, mean, std, ref, fns) -> np.ndarray:
        """``std`` where a wrong latch state is possible: the mixture's equivalent std."""
        timing = getattr(self, "latch_timing_", None)
        if timing is None or not (classes[1:] != classes[:-1]).any():
            return std
        cur, didt = self._timing_columns()
        rows, p = timing.windows(
            classes, X[:, cur], X[:, didt] if didt >= 0 else None, self._latch_rate_scale()
        )
        if rows.size == 0:
            return std
        other = 1 - classes[rows]
        o_mean = np.empty(rows.size)
        o_std = np.empty(rows.size)
        for g in (0, 1):
            sel = other == g
            if sel.any():
                o_mean[sel], o_std[sel] = fns[g](X[rows[sel]])
        if ref is not None:
            o_mean = o_mean + np.where(other == 1, ref[rows], 0.0)
        out = std.copy()
        out[rows] = mixture_interval_std(mean[rows], std[rows], o_mean, o_std, p)
        return out

    def _latch_rate_scale(self) -> float:
        """``κ``: the parameter, or the value calibrated for the fitted latch model."""
        if self.latch_rate_scale is not None:
            return float(self.latch_rate_scale)
        return LATCH_RATE_SCALES.get(self.latch_model_, LATCH_RATE_SCALES["classifier"])

    @property
    def latch_model_(self) -> str:
        """What decides the latch state as fitted: ``event``, ``local_event``,
        ``classifier`` or ``none``."""
        dec = self.decision_
        if dec is None:
            return "none"
        if isinstance(dec, EventDecision | LocalEventDecision):
            return dec.kind
        return "classifier"

    def _classes(
        self, X: np.ndarray, knots: np.ndarray | None, ref: np.ndarray | None = None
    ) -> np.ndarray:
        if self.decision_ is None:
            return np.full(X.shape[0], self.single_state_, dtype=np.int8)
        if knots is None:
            return (self._decide(X, ref) > 0).astype(np.int8)
        return _path_classes(self._decide, X, knots, ref)

    def _fns(self, return_std: bool) -> dict:
        fns = {
            g: self._gp_fn(gp, return_std, self._observation_noise(g))
            for g, gp in self.gps_.items()
        }
        for g in (0, 1):  # a state without its own GP borrows the other's
            if g not in fns:
                fns[g] = fns[1 - g]
        return fns

    def resolution(self) -> np.ndarray:
        """Per-feature kernel resolution for the prediction knots (feature units).

        The smallest over the partitions' GPs, each scaled by ``sqrt(s_max / s)`` with
        ``s`` its signal std and ``s_max`` the largest: between knots the interpolation
        error grows as ``s (Δ/ℓ)²``, so a GP of small amplitude (the latched plateau's
        offset below line pressure, a few hundredths of a bar) keeps the same error bound
        at wider knot spacing instead of setting it for both.
        """
        self._check_fitted()
        amp = {g: np.sqrt(max(gp.signal_var_, 1e-300)) for g, gp in self.gps_.items()}
        top = max(amp.values())
        return np.min(
            [gp.resolution_ * np.sqrt(top / amp[g]) for g, gp in self.gps_.items()], axis=0
        )

    def _predict_matrix(
        self, X: np.ndarray, path: bool, return_std: bool, ref: np.ndarray | None = None
    ):
        """Prediction per row of ``X``; ``ref`` (bar, per row) is added where latched.

        A model fitted with ``latched_reference_ == "line"`` needs ``ref`` (the line
        pressure): feature rows alone do not carry it.
        """
        if getattr(self, "latched_reference_", "none") == "line" and ref is None:
            raise ModelError(
                "this SVCPartitionedGP predicts the latched plateau relative to line pressure: "
                "predict on traces (with line_pressure_bar), or fit with "
                "latched_reference='none' to predict on feature arrays"
            )
        fns = self._fns(return_std)
        if not path:
            classes = self._classes(X, None, ref)
            mean = np.empty(X.shape[0])
            std = np.empty(X.shape[0]) if return_std else None
            for g in (0, 1):
                rows = classes == g
                if rows.any():
                    out = fns[g](X[rows])
                    if return_std:
                        mean[rows], std[rows] = out
                    else:
                        mean[rows] = out
        else:
            knots = knot_indices(X, self.resolution(), self.knot_tol, self.max_knot_gap)
            classes = self._classes(X, knots, ref)
            out = predict_on_path(X, classes, knots, fns, return_std)
            mean, std = out if return_std else (out, None)
            if return_std:
                std = self._widen_for_rate(X, classes, knots, std, fns)
        line = getattr(self, "latched_reference_", "none") == "line"
        if line:
            mean = mean + np.where(classes == 1, ref, 0.0)
        if return_std and path:
            std = self._widen_at_switches(X, classes, mean, std, ref if line else None, fns)
        return (mean, std) if return_std else mean

    def _predict_trace(self, trace: Trace, return_std: bool):
        return self._predict_matrix(
            self._trace_matrix(trace), path=True, return_std=return_std, ref=self._trace_ref(trace)
        )

    def predict_latch(self, X) -> np.ndarray | list[np.ndarray]:
        """Predicted latch state (1 latched, 0 unlatched) per sample of a trace or matrix."""
        from .base import as_traces

        self._check_fitted()
        traces = as_traces(X)
        if traces is None:
            return self._classes(np.asarray(X, dtype=float), None)
        outs = []
        for t in traces:
            F = self._trace_matrix(t)
            knots = knot_indices(F, self.resolution(), self.knot_tol, self.max_knot_gap)
            outs.append(self._classes(F, knots, self._trace_ref(t)))
        return outs[0] if len(outs) == 1 and not isinstance(X, list | tuple) else outs


def _decision_values(decide, Z: np.ndarray, ref: np.ndarray | None) -> np.ndarray:
    """Decision values (> 0: latched) of rows ``Z``; ``ref`` (line pressure, bar) goes to a
    decision that follows it (:attr:`LocalEventDecision.uses_line`)."""
    if getattr(decide, "uses_line", False):
        return decide(Z, line=ref)
    return decide(Z)


def _path_classes(decide, X: np.ndarray, knots: np.ndarray, ref: np.ndarray | None):
    """:func:`piecewise_classes` of ``decide(X, ref)`` with ``ref`` carried along the
    rows, so the samples evaluated between knots get their own line pressure."""
    if ref is None:
        return piecewise_classes(X, knots, lambda Z: decide(Z, None))
    Xr = np.column_stack([X, ref])
    return piecewise_classes(Xr, knots, lambda Z: decide(Z[:, :-1], Z[:, -1]))


def _peak_row(X: np.ndarray, names: list[str]) -> np.ndarray:
    """Decision row of a never-latched experiment: the row at its peak current with the
    fastest rise before it (mA/s) in the dI/dt column (the rate its peak was reached at)."""
    cur, didt = decision_current_columns(names)
    k = int(np.argmax(X[:, cur]))
    row = X[k].copy()
    if didt >= 0:
        row[didt] = float(np.max(X[: k + 1, didt]))
    return row
