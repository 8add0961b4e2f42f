"""Run a plant of the zoo over the stand's protocol and write the dataset with its truth."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from tqdm.auto import tqdm

from ....data import Dataset, Trace
from ....errors import ModelError
from ..environment import (
    BenchNoise,
    bench_drive,
    bench_problems,
    experiment_meta,
    experiment_name,
    measured_signals,
)
from ..scenarios import RAMPS, DitherSetting, RampProfile
from .common import delayed, run_kernel
from .registry import get_plant

__all__ = ["PlantConfig", "PlantRun", "run_plant"]

#: Dither waveforms a plant's kernel makes (:func:`~.common.dither_wave`).
PLANT_WAVEFORMS = ("sine", "triangle")

_ALL_SETTINGS: tuple[DitherSetting, ...] = tuple(
    DitherSetting(f, s) for f in (30.0, 50.0, 70.0) for s in ("A", "B", "C")
)


@dataclass(frozen=True)
class PlantConfig:
    """What a zoo plant runs.

    Attributes
    ----------
    plant : str
        Name of the plant (see :func:`~clutchlab.physics.stand.plants.plant_names`).
    effects : tuple of str
        Library effects the plant carries in this run (each in its own equations).
    settings : tuple of DitherSetting
        Dither settings; each is run at every ramp.
    ramps : tuple of RampProfile
        Ramp profiles.
    seed : int
        Seed of the as-built unit (parameter draw) and of noise and wander.
    sample_rate_Hz : float
        Logging rate (Hz).
    substeps : int
        Fixed integration steps per logging sample.
    temperature : {"levels", "drift"}
        Oil temperature per run: fixed levels, or warming 40 → 85 °C through every run.
    noise : BenchNoise
        Sensor noise and ADC steps of the bench.

    Raises
    ------
    ModelError
        Listing every problem of the settings (a plant makes sine and triangle dither only),
        ramps, seed, sample rate, substeps, noise and temperature.
    """

    plant: str
    effects: tuple[str, ...] = ()
    settings: tuple[DitherSetting, ...] = _ALL_SETTINGS
    ramps: tuple[RampProfile, ...] = tuple(RAMPS.values())
    seed: int = 0
    sample_rate_Hz: float = 1000.0
    substeps: int = 20
    temperature: str = "levels"
    noise: BenchNoise = field(default_factory=BenchNoise)

    def __post_init__(self) -> None:
        problems = bench_problems(
            self.settings,
            self.ramps,
            self.seed,
            self.sample_rate_Hz,
            self.substeps,
            self.noise,
            waveforms=PLANT_WAVEFORMS,
        )
        effects = [self.effects] if isinstance(self.effects, str) else list(self.effects)
        twice = sorted({e for e in effects if effects.count(e) > 1})
        if twice:
            problems.append(f"effect(s) named twice: {', '.join(map(str, twice))}")
        if self.temperature not in ("levels", "drift"):
            problems.append(f"temperature must be 'levels' or 'drift', not {self.temperature!r}")
        if problems:
            raise ModelError(
                f"invalid configuration of plant {self.plant!r}:\n  - " + "\n  - ".join(problems)
            )


@dataclass(frozen=True)
class PlantRun:
    """A zoo dataset with its truth (the drawn unit)."""

    dataset: Dataset
    config: PlantConfig
    values: dict[str, float]
    true_pressure: dict[str, np.ndarray]

    def truth(self) -> dict:
        """JSON-ready truth: plant, its laws, effects, every drawn parameter, seed."""
        spec = get_plant(self.config.plant)
        units = {p.name: p.unit for p in spec.parameters}
        return {
            "plant": spec.name,
            "laws": spec.laws,
            "effects": list(self.config.effects),
            "effect_how": {e: spec.effects[e].how for e in self.config.effects},
            "parameters": {k: {"value": v, "unit": units[k]} for k, v in self.values.items()},
            "seed": self.config.seed,
            "substeps": self.config.substeps,
            "temperature": self.config.temperature,
            "noise": self.config.noise.as_dict(),
        }


def run_plant(config: PlantConfig, progress: bool = True) -> PlantRun:
    """Draw the unit of ``config.seed`` and run every ramp × dither setting on it.

    The parameter draw and the bench's noise come from separate streams of the seed, so
    the same unit is drawn whatever the settings.
    """
    spec = get_plant(config.plant)
    values = spec.draw(np.random.default_rng([config.seed, 1]), config.effects)
    vec = spec.vector(values)
    rng = np.random.default_rng([config.seed, 2])
    dt = 1.0 / config.sample_rate_Hz
    delay_s = (values.get("dead_ms", 0.0) + values.get("delay_ms", 0.0)) * 1e-3
    traces, truth_p = [], {}
    jobs = [(r, k, s) for r in config.ramps for k, s in enumerate(config.settings)]
    for ramp, k, setting in tqdm(jobs, desc=f"plant {spec.name}", unit="exp", disable=not progress):
        drive = bench_drive(
            ramp, setting, k, rng, config.sample_rate_Hz, temperature=config.temperature
        )
        current, pressure = run_kernel(spec.simulate, vec, drive, config.substeps, setting.waveform)
        pressure = delayed(pressure, delay_s, dt)
        name = experiment_name(ramp, setting)
        truth_p[name] = pressure.copy()
        signals = measured_signals(rng, drive, current, pressure, config.noise)
        traces.append(Trace(name, signals, meta=experiment_meta(ramp, setting)))
    dataset = Dataset(
        traces,
        manifest_extra={
            "source": "clutchlab plant zoo",
            "sample_rate_Hz": config.sample_rate_Hz,
        },
    )
    return PlantRun(dataset, config, values, truth_p)
