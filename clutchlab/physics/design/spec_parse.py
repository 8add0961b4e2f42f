"""Parsing and validation of a sweep spec: every problem is collected, then raised at once."""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import numpy as np

from ...data import SIGNALS
from ...errors import ModelError
from ..effects import effect_names, missing_effect
from ..model import CircuitModel
from ..settings import is_finite_real
from ..stand.scenarios import DITHER_SHAPES, RAMPS, RampProfile, dither_amplitude
from .limits import SweepLimits
from .metrics import MetricSettings
from .spec import (
    MAX_DITHER_MA,
    SCENARIO_VARIABLES,
    WAVEFORMS,
    ModelSpec,
    SamplingSpec,
    ScenarioSpec,
    SimulationSpec,
    SpecError,
    StepSpec,
    SweepSpec,
    Variable,
    _model,
)

__all__ = ["check_spec", "parse_spec", "spec_to_doc"]

_TOP = {"name", "model", "scenario", "simulation", "metrics", "sampling", "variables"}


def _table(doc: dict, key: str, allowed: set[str], problems: list[str]) -> dict:
    tab = doc.get(key, {})
    if not isinstance(tab, dict):
        problems.append(f"[{key}] must be a table")
        return {}
    for k in sorted(set(tab) - allowed):
        problems.append(f"[{key}] unknown key {k!r}; known: {', '.join(sorted(allowed))}")
    return tab


#: Largest nominal current of the circuit and of the stand's ramps (mA).
MAX_CURRENT_MA = 1100.0


def _number(tab: dict, key: str, where: str, default: float, problems: list[str]) -> float:
    v = tab.get(key, default)
    if not is_finite_real(v):
        problems.append(f"{where} {key} must be a finite number, got {v!r}")
        return default
    return float(v)


def parse_spec(doc: dict, source: str = "spec") -> SweepSpec:
    """Validate a parsed TOML document and build the :class:`SweepSpec`.

    Raises
    ------
    SpecError
        Listing every problem found.
    """
    problems: list[str] = []
    for k in sorted(set(doc) - _TOP):
        problems.append(f"unknown top-level key {k!r}; known: {', '.join(sorted(_TOP))}")
    model_spec, model = _parse_model(doc, problems)
    scenario = _parse_scenario(doc, problems)
    simulation = _parse_simulation(doc, problems)
    metrics = _parse_metrics(doc, problems)
    sampling = _parse_sampling(doc, problems)
    variables = _parse_variables(doc, model, model_spec, sampling, problems)
    if sampling.method == "lhs" and not variables and not problems:
        problems.append("[[variables]]: at least one design variable is needed")
    if simulation.sample_rate_Hz > 0:
        _check_dither(scenario, simulation, variables, problems)
    _check_size(scenario, simulation, sampling, variables, problems)
    if problems:
        raise SpecError(problems, source)
    return SweepSpec(
        model=model_spec,
        scenario=scenario,
        simulation=simulation,
        metrics=metrics,
        sampling=sampling,
        variables=tuple(variables),
        name=str(doc.get("name", "sweep")),
        source=source,
    )


def _check_size(scenario, simulation, sampling, variables, problems: list[str]) -> None:
    """The sweep's size against :class:`SweepLimits`, without building any point."""
    limits = SweepLimits.from_env()
    if sampling.method == "grid":
        n = math.prod(len(v.values) if v.values else v.levels for v in variables)
    else:
        n = sampling.n
    if n > limits.max_points:
        problems.append(
            f"[sampling] {n} design points, more than the limit of {limits.max_points} "
            "(raise it with CLUTCHLAB_SWEEP_MAX_POINTS if you mean it)"
        )
    seconds = sum(r.duration_s + simulation.settle_s for r in scenario.ramps)
    if scenario.step is not None:
        seconds += scenario.step.duration_s + simulation.settle_s
    if not math.isfinite(seconds) or seconds > limits.max_simulated_s:
        problems.append(
            f"[scenario] {seconds:.6g} s simulated per design point, more than the limit of "
            f"{limits.max_simulated_s:g} s (raise it with CLUTCHLAB_SWEEP_MAX_SIMULATED_S)"
        )


def _parse_model(doc: dict, problems: list[str]) -> tuple[ModelSpec, CircuitModel | None]:
    tab = _table(doc, "model", {"effects", "baseline", "parameters"}, problems)
    try:
        effects = list(effect_names(tab.get("effects", []), "[model] effects"))
    except ModelError as exc:
        problems.append(str(exc))
        effects = []
    baseline = tab.get("baseline", "default")
    if baseline not in ("default", "stand"):
        problems.append(f"[model] baseline {baseline!r} is not 'default' or 'stand'")
        baseline = "default"
    fixed = tab.get("parameters", {})
    if not isinstance(fixed, dict):
        problems.append("[model.parameters] must be a table of name = value")
        fixed = {}
    try:
        model = _model(tuple(effects))
    except ModelError as exc:
        problems.append(f"[model] effects: {exc}")
        return ModelSpec((), baseline, {}), None
    known = {p.name: p for p in model.parameters}
    clean = {}
    for name, value in fixed.items():
        if name not in known:
            problems.append(_unknown_parameter(name, known, "[model.parameters]"))
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            problems.append(f"[model.parameters] {name} must be a number, got {value!r}")
            continue
        msg = known[name].check(float(value))
        if msg:
            problems.append(f"[model.parameters] {msg}")
        clean[name] = float(value)
    return ModelSpec(tuple(effects), baseline, clean), model


def _unknown_parameter(name: str, known: dict, where: str) -> str:
    missing = missing_effect(name)
    if missing is not None:
        return f"{where} parameter {name!r} {missing[1]}: add it to [model] effects"
    names = sorted(known) + sorted(SCENARIO_VARIABLES)
    return f"{where} unknown parameter {name!r}; known: {', '.join(names)}"


def _parse_ramp(item: Any, k: int, problems: list[str]) -> RampProfile | None:
    if isinstance(item, str):
        if item not in RAMPS:
            problems.append(
                f"[scenario] ramps[{k}]: unknown ramp {item!r}; known: {', '.join(RAMPS)} "
                "(or a table {label, ramp_s, hold_s, peak_mA})"
            )
            return None
        return RAMPS[item]
    if isinstance(item, dict):
        extra = sorted(set(item) - {"label", "ramp_s", "hold_s", "peak_mA"})
        if extra or "label" not in item or "ramp_s" not in item:
            problems.append(
                f"[scenario] ramps[{k}]: a custom ramp needs label and ramp_s "
                f"(optional hold_s, peak_mA); unknown keys: {extra}"
            )
            return None
        where = f"[scenario] ramps[{k}]"
        if not isinstance(item["label"], str) or not item["label"].strip():
            problems.append(f"{where}: label must be a non-empty string, got {item['label']!r}")
        ramp = RampProfile(
            str(item["label"]),
            _number(item, "ramp_s", where, 1.0, problems),
            _number(item, "hold_s", where, 1.0, problems),
            _number(item, "peak_mA", where, 1100.0, problems),
        )
        if ramp.ramp_s <= 0 or ramp.hold_s <= 0 or not 0 < ramp.peak_mA <= 1100:
            problems.append(f"{where}: need ramp_s > 0, hold_s > 0, 0 < peak_mA ≤ 1100")
        return ramp
    problems.append(f"[scenario] ramps[{k}] must be a ramp name or a table")
    return None


def _parse_scenario(doc: dict, problems: list[str]) -> ScenarioSpec:
    keys = {"ramps", "dither", "step", "line_pressure_bar", "prime_pressure_bar", "oil_temp_C"}
    tab = _table(doc, "scenario", keys, problems)
    raw = tab.get("ramps", ["fast"])
    if not isinstance(raw, list) or not raw:
        problems.append("[scenario] ramps must be a non-empty list")
        raw = ["fast"]
    ramps = [r for k, item in enumerate(raw) if (r := _parse_ramp(item, k, problems))]
    labels = [r.label for r in ramps]
    if len(set(labels)) != len(labels):
        problems.append(f"[scenario] ramps: duplicate labels in {labels}")
    dither = _table(tab, "dither", {"freq_Hz", "shape", "waveform"}, problems)
    shape = dither.get("shape", "B")
    if not isinstance(shape, str) or shape not in DITHER_SHAPES:
        problems.append(
            f"[scenario.dither] unknown shape {shape!r}; known: {', '.join(DITHER_SHAPES)}"
        )
    waveform = dither.get("waveform", "sine")
    if waveform not in WAVEFORMS:
        problems.append(f"[scenario.dither] waveform {waveform!r} is not one of {WAVEFORMS}")
    step = None
    if tab.get("step", {}) is not False:
        st = _table(tab, "step", {"from_mA", "to_mA", "hold_s", "duration_s"}, problems)
        d = StepSpec()
        values = [_number(st, k, "[scenario.step]", getattr(d, k), problems) for k in asdict(d)]
        try:
            step = StepSpec(*values)
        except SpecError as exc:  # every problem of the spec is listed together
            problems.extend(exc.problems)
            step = d
    d = ScenarioSpec()
    line = _number(tab, "line_pressure_bar", "[scenario]", d.line_pressure_bar, problems)
    prime = _number(tab, "prime_pressure_bar", "[scenario]", d.prime_pressure_bar, problems)
    oil = _number(tab, "oil_temp_C", "[scenario]", d.oil_temp_C, problems)
    problems += _supply_problems(line, prime, oil)
    return ScenarioSpec(
        ramps=tuple(ramps) or d.ramps,
        dither_freq_Hz=_number(dither, "freq_Hz", "[scenario.dither]", 50.0, problems),
        dither_shape=str(shape),
        dither_waveform=str(waveform),
        step=step,
        line_pressure_bar=line,
        prime_pressure_bar=prime,
        oil_temp_C=oil,
    )


def _supply_problems(line: float, prime: float, oil: float) -> list[str]:
    """Line / prime pressure (bar, gauge) and oil temperature (°C) a circuit can run at."""
    out = []
    p_lo, p_hi = (
        SIGNALS["line_pressure_bar"].plausible_min,
        SIGNALS["line_pressure_bar"].plausible_max,
    )
    t_lo, t_hi = SIGNALS["oil_temp_C"].plausible_min, SIGNALS["oil_temp_C"].plausible_max
    if not 0 < line <= p_hi:
        out.append(f"[scenario] line_pressure_bar {line:g} bar not in (0, {p_hi:g}] bar")
    if not p_lo <= prime < line:
        out.append(
            f"[scenario] prime_pressure_bar {prime:g} bar must be ≥ {p_lo:g} bar and below "
            f"line_pressure_bar ({line:g} bar)"
        )
    if not t_lo <= oil <= t_hi:
        out.append(f"[scenario] oil_temp_C {oil:g} °C not in {t_lo:g}–{t_hi:g} °C")
    return out


def _parse_simulation(doc: dict, problems: list[str]) -> SimulationSpec:
    tab = _table(doc, "simulation", {"substeps", "sample_rate_Hz", "settle_s"}, problems)
    sub = tab.get("substeps", 4)
    if isinstance(sub, bool) or not isinstance(sub, int) or not 1 <= sub <= 64:
        problems.append(f"[simulation] substeps must be an integer in 1..64, got {sub!r}")
        sub = 4
    spec = SimulationSpec(
        substeps=sub,
        sample_rate_Hz=_number(tab, "sample_rate_Hz", "[simulation]", 1000.0, problems),
        settle_s=_number(tab, "settle_s", "[simulation]", 0.5, problems),
    )
    if not 100 <= spec.sample_rate_Hz <= 20000:
        problems.append(f"[simulation] sample_rate_Hz {spec.sample_rate_Hz} not in 100–20000 Hz")
    if spec.settle_s < 0:
        problems.append("[simulation] settle_s must be ≥ 0")
    return spec


def _parse_metrics(doc: dict, problems: list[str]) -> MetricSettings:
    d = MetricSettings()
    tab = _table(doc, "metrics", set(asdict(d)), problems)
    kw = {}
    for k, default in asdict(d).items():
        if k not in tab:
            continue
        v = tab[k]
        if isinstance(default, tuple):
            numbers = isinstance(v, list) and len(v) == 2 and all(is_finite_real(x) for x in v)
            if not (numbers and 0 <= v[0] < v[1] <= MAX_CURRENT_MA):
                problems.append(
                    f"[metrics] {k} must be [low, high] with 0 ≤ low < high ≤ "
                    f"{MAX_CURRENT_MA:g} (mA), got {v!r}"
                )
                continue
            kw[k] = (float(v[0]), float(v[1]))
        else:
            kw[k] = _number(tab, k, "[metrics]", default, problems)
    try:
        return MetricSettings(**kw)
    except ValueError as exc:
        problems.append(f"[metrics] {exc}")
        return d


def _parse_sampling(doc: dict, problems: list[str]) -> SamplingSpec:
    tab = _table(doc, "sampling", {"method", "n", "seed"}, problems)
    method = tab.get("method", "lhs")
    if method not in ("lhs", "grid"):
        problems.append(f"[sampling] method {method!r} is not 'lhs' or 'grid'")
        method = "lhs"
    n, seed = tab.get("n", 0), tab.get("seed", 0)
    if method == "lhs" and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        problems.append(f"[sampling] n must be a positive integer for lhs, got {n!r}")
        n = 0
    if method == "grid" and "n" in tab:
        problems.append("[sampling] n is not used by grid sampling (set levels per variable)")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        problems.append(f"[sampling] seed must be a non-negative integer, got {seed!r}")
        seed = 0
    return SamplingSpec(method, int(n) if method == "lhs" else 0, seed)


_VAR_KEYS = {"name", "low", "high", "scale", "levels", "values"}


def _parse_variables(
    doc: dict,
    model: CircuitModel | None,
    model_spec: ModelSpec,
    sampling: SamplingSpec,
    problems: list[str],
) -> list[Variable]:
    raw = doc.get("variables", [])
    if not isinstance(raw, list):
        problems.append("variables must be an array of tables ([[variables]])")
        return []
    known = {p.name: p for p in model.parameters} if model is not None else {}
    out, seen = [], set()
    for k, item in enumerate(raw):
        where = f"[[variables]] #{k + 1}"
        if not isinstance(item, dict) or "name" not in item:
            problems.append(f"{where}: needs a name")
            continue
        name = str(item["name"])
        where = f"[[variables]] {name}"
        for key in sorted(set(item) - _VAR_KEYS):
            problems.append(f"{where}: unknown key {key!r}; known: {', '.join(sorted(_VAR_KEYS))}")
        if name in seen:
            problems.append(f"{where}: listed twice")
        seen.add(name)
        if name in model_spec.parameters:
            problems.append(f"{where}: also fixed in [model.parameters]")
        if name in SCENARIO_VARIABLES:
            unit, lo, hi, _ = SCENARIO_VARIABLES[name]
        elif name in known:
            p = known[name]
            unit, lo, hi = p.unit, p.lower, p.upper
        else:
            if model is not None:
                problems.append(_unknown_parameter(name, known, where))
            continue
        var = _parse_one_variable(item, name, unit, where, sampling, problems)
        if var is None:
            continue
        for v in (var.low, var.high, *var.values):
            if not lo <= v <= hi:
                problems.append(f"{where}: {v:g} {unit} outside the bounds [{lo:g}, {hi:g}] {unit}")
                break
        out.append(var)
    return out


def _parse_one_variable(
    item: dict, name: str, unit: str, where: str, sampling: SamplingSpec, problems: list[str]
) -> Variable | None:
    scale = item.get("scale", "linear")
    if scale not in ("linear", "log"):
        problems.append(f"{where}: scale {scale!r} is not 'linear' or 'log'")
        return None
    values = item.get("values", [])
    if not isinstance(values, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in values
    ):
        problems.append(f"{where}: values must be a list of numbers")
        return None
    if values and sampling.method != "grid":
        problems.append(f"{where}: values are only for grid sampling")
        return None
    if values:
        low, high = float(min(values)), float(max(values))
    elif "low" not in item or "high" not in item:
        problems.append(f"{where}: needs low and high (or values, for a grid)")
        return None
    else:
        n_before = len(problems)
        low = _number(item, "low", where, 0.0, problems)
        high = _number(item, "high", where, 0.0, problems)
        if len(problems) > n_before:
            return None
        if not low < high:
            problems.append(f"{where}: low ({low:g}) must be below high ({high:g})")
            return None
    if scale == "log" and low <= 0:
        problems.append(f"{where}: log scale needs low > 0")
        return None
    levels = item.get("levels", 3)
    if isinstance(levels, bool) or not isinstance(levels, int) or levels < 2:
        problems.append(f"{where}: levels must be an integer ≥ 2, got {levels!r}")
        return None
    if "levels" in item and sampling.method != "grid":
        problems.append(f"{where}: levels are only for grid sampling")
    return Variable(name, low, high, scale, levels, tuple(float(v) for v in values), unit)


def _check_dither(
    scenario: ScenarioSpec,
    simulation: SimulationSpec,
    variables: list[Variable],
    problems: list[str],
) -> None:
    """The dither must be resolved: at least 4 samples per period."""
    swept = [v.high for v in variables if v.name == "dither_freq_Hz"]
    freqs = swept or [scenario.dither_freq_Hz]  # the variable replaces freq_Hz in every point
    f_max = simulation.sample_rate_Hz / 4.0
    if max(freqs) > f_max:
        problems.append(
            f"dither frequency up to {max(freqs):g} Hz is not resolved at "
            f"{simulation.sample_rate_Hz:g} Hz sampling (max {f_max:g} Hz)"
        )
    if scenario.dither_freq_Hz <= 0:
        problems.append("[scenario.dither] freq_Hz must be > 0")
    scales = [v.high for v in variables if v.name == "dither_amp_scale"]
    if scales and scenario.dither_shape in DITHER_SHAPES:
        peak = float(dither_amplitude(scenario.dither_shape, np.linspace(0.0, 1100.0, 1101)).max())
        if scales[0] * peak > MAX_DITHER_MA + 1e-9:
            problems.append(
                f"[[variables]] dither_amp_scale: high {scales[0]:g} × shape "
                f"{scenario.dither_shape} (peak {peak:g} mA) exceeds the {MAX_DITHER_MA:g} mA "
                f"dither range; use high ≤ {MAX_DITHER_MA / peak:.4g}"
            )


def spec_to_doc(spec: SweepSpec) -> dict[str, Any]:
    """The TOML document (as parsed) that :func:`parse_spec` turns into ``spec``."""
    sc = spec.scenario
    scenario: dict[str, Any] = {
        "ramps": [asdict(r) for r in sc.ramps],
        "dither": {"freq_Hz": sc.dither_freq_Hz, "shape": sc.dither_shape},
        "line_pressure_bar": sc.line_pressure_bar,
        "prime_pressure_bar": sc.prime_pressure_bar,
        "oil_temp_C": sc.oil_temp_C,
    }
    scenario["dither"]["waveform"] = sc.dither_waveform
    scenario["step"] = asdict(sc.step) if sc.step is not None else False
    metrics = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(spec.metrics).items()}
    sampling: dict[str, Any] = {"method": spec.sampling.method, "seed": spec.sampling.seed}
    if spec.sampling.method == "lhs":
        sampling["n"] = spec.sampling.n
    variables = []
    for v in spec.variables:
        item: dict[str, Any] = {"name": v.name, "scale": v.scale}
        if v.values:
            item["values"] = list(v.values)
        else:
            item |= {"low": v.low, "high": v.high}
            if spec.sampling.method == "grid":
                item["levels"] = v.levels
        variables.append(item)
    return {
        "name": spec.name,
        "model": {
            "effects": list(spec.model.effects),
            "baseline": spec.model.baseline,
            "parameters": dict(spec.model.parameters),
        },
        "scenario": scenario,
        "simulation": asdict(spec.simulation),
        "metrics": metrics,
        "sampling": sampling,
        "variables": variables,
    }


def check_spec(spec: SweepSpec) -> None:
    """Validate a spec built in code as :func:`load_spec` validates a file.

    The dataclasses check nothing themselves; :func:`~.runner.run_sweep` calls this so that a
    ``dataclasses.replace(spec, ...)`` with a negative line pressure or an unknown dither
    shape is refused with every problem before any work, not simulated point by point.

    Raises
    ------
    SpecError
        Listing every problem found.
    """
    if not isinstance(spec, SweepSpec):
        raise TypeError(f"expected a SweepSpec, not {spec!r}")
    parse_spec(spec_to_doc(spec), spec.source)
