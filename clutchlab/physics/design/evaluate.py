"""Evaluate design points: simulate the scenario, compute the metrics, never raise.

:func:`evaluate_batch` is what a worker process (local pool or Dask worker) runs. It is a
pure function of the spec and the design vectors, so a point gives the same numbers in
any process; the model and its compiled code are built once per process and spec.
"""

from __future__ import annotations

import time
import traceback
from typing import Any

import numpy as np

from ..settings import SimulationSettings
from ..simulate import simulate
from . import metrics as m
from .sampling import DesignPoint
from .scenario import DitherChoice, ramp_trace, step_trace
from .spec import SCENARIO_VARIABLES, SweepSpec

__all__ = ["STATUS_FAILED", "STATUS_OK", "DesignEvaluator", "evaluate_batch"]

STATUS_OK, STATUS_FAILED = "ok", "failed"

_EVALUATORS: dict[str, DesignEvaluator] = {}


class DesignEvaluator:
    """Simulates design points of one spec and computes their metrics.

    Parameters
    ----------
    spec : SweepSpec
        The sweep spec; validated here as a spec file is (a spec built or changed in code
        is checked too).

    Raises
    ------
    SpecError
        Listing every problem of ``spec``, before any simulation.
    """

    def __init__(self, spec: SweepSpec) -> None:
        from .spec_parse import check_spec

        check_spec(spec)
        self.spec = spec
        self.model = spec.model.build()
        self.base = spec.model.base_params(self.model)
        self.settings = SimulationSettings(
            drive="command",
            substeps=spec.simulation.substeps,
            settle_s=spec.simulation.settle_s,
            dither_waveform=spec.scenario.dither_waveform,
            # a finite but unphysical result (±10⁴ bar from a step too long for the
            # design's dynamics, once stored as ``ok``) raises: the point is ``failed``
            out_of_range="raise",
        )
        self.metric_names = m.metric_names(
            tuple(r.label for r in spec.scenario.ramps), spec.scenario.step is not None
        )

    def evaluate(self, point: DesignPoint) -> dict[str, Any]:
        """One result row: id, index, status, error, design values, metrics, wall and CPU time (s).

        Any exception (a diverging integrator raises ``SimulationError``) gives a row with
        ``status = "failed"``, the exception type and message in ``error`` and NaN metrics.
        """
        t0, c0 = time.perf_counter(), time.process_time()
        row: dict[str, Any] = {
            "point_id": point.point_id,
            "index": point.index,
            "status": STATUS_OK,
            "error": "",
        }
        row |= {k: float(v) for k, v in point.values.items()}
        try:
            row |= self._metrics(point.values)
        except Exception as exc:
            row["status"] = STATUS_FAILED
            where = traceback.extract_tb(exc.__traceback__)[-1]
            row["error"] = f"{type(exc).__name__}: {exc} [{where.name}:{where.lineno}]"
            row |= dict.fromkeys(self.metric_names, float("nan"))
        row["wall_s"] = time.perf_counter() - t0
        row["cpu_s"] = time.process_time() - c0
        return row

    def _metrics(self, values: dict[str, float]) -> dict[str, float]:
        spec, sc = self.spec, self.spec.scenario
        params = self.base.replace(
            **{k: v for k, v in values.items() if k not in SCENARIO_VARIABLES}
        )
        dither = DitherChoice(
            freq_Hz=values.get("dither_freq_Hz", sc.dither_freq_Hz),
            shape=sc.dither_shape,
            amp_scale=values.get("dither_amp_scale", 1.0),
            waveform=sc.dither_waveform,
        )
        fs = spec.simulation.sample_rate_Hz
        ms = spec.metrics
        line = sc.line_pressure_bar
        out: dict[str, float] = {}
        slowest = max(sc.ramps, key=lambda r: r.ramp_s)
        for ramp in sc.ramps:
            trace = ramp_trace(ramp, dither, sc, fs)
            raw = simulate(self.model, params, trace, self.settings).pressure_bar
            mean = m.period_mean(raw, fs, dither.freq_Hz)
            t, i = trace.time_s, trace.get("current_cmd_mA")
            h, r = ramp.hold_s, ramp.ramp_s
            rising = (t > h) & (t < h + r)
            falling = (t > 2 * h + r) & (t < 2 * h + 2 * r)
            out[f"hysteresis_{ramp.label}_bar"] = m.hysteresis_width(
                i, mean, rising, falling, line, ms
            )
            if ramp is slowest:
                on, off = m.latch_currents(i, mean, rising, falling, line, ms.latch_margin_bar)
                period = int(np.ceil(fs / dither.freq_Hz))  # samples in one dither period
                pp, rms = m.ripple(i, raw, mean, rising, line, ms, min_samples=period)
                out |= {
                    "regulated_gain_bar_per_A": m.regulated_gain(i, mean, rising, line, ms),
                    "latch_on_mA": on,
                    "latch_off_mA": off,
                    "ripple_pp_bar": pp,
                    "ripple_rms_bar": rms,
                }
        if sc.step is not None:
            trace, t_step = step_trace(sc.step, dither, sc, fs)
            raw = simulate(self.model, params, trace, self.settings).pressure_bar
            mean = m.period_mean(raw, fs, dither.freq_Hz)
            n_final = max(int(np.ceil(fs / dither.freq_Hz)), int(0.05 * fs))
            rise, settle = m.response_times(trace.time_s, mean, t_step, ms, n_final)
            out |= {"rise_10_90_s": rise, "settle_s": settle}
        return {k: float(out[k]) for k in self.metric_names}


def evaluator_for(spec: SweepSpec) -> DesignEvaluator:
    """The evaluator of ``spec`` in this process (built once per spec core)."""
    key = spec.core_hash
    if key not in _EVALUATORS:
        _EVALUATORS[key] = DesignEvaluator(spec)
    return _EVALUATORS[key]


def evaluate_batch(spec: SweepSpec, points: list[DesignPoint]) -> list[dict[str, Any]]:
    """Evaluate ``points`` of ``spec`` in order; one row per point (see :meth:`evaluate`).

    Parameters
    ----------
    spec : SweepSpec
        The sweep spec (pickled to worker processes).
    points : list of DesignPoint
        Points to evaluate.

    Returns
    -------
    list of dict
        Result rows; a failing point gives a ``failed`` row, never an exception.
    """
    try:
        ev = evaluator_for(spec)
    except Exception as exc:  # the model itself cannot be built in this worker
        msg = f"{type(exc).__name__}: {exc}"
        return [
            {"point_id": p.point_id, "index": p.index, "status": STATUS_FAILED, "error": msg}
            | dict(p.values)
            for p in points
        ]
    return [ev.evaluate(p) for p in points]
