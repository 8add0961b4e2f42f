"""The synthetic test stand: a higher-fidelity model that writes datasets in the data contract.

The stand is the same component model with (a) effects the default fit model does
not declare, (b) "as-built" parameters that differ from the datasheet defaults,
(c) the dither resolved through the current loop at a finer step, (d) line and
prime pressure wandering, (e) sensor noise and ADC quantization on every channel.
Its truth (effects, parameters, seed) is written *beside* the dataset folder,
never inside it.
"""

from __future__ import annotations

import difflib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from ...data import Dataset, Trace, save_dataset
from ...data.io_dataset import MANIFEST_NAME, experiment_name_problems
from ...data.output import check_folder_files, check_output, write_file_atomic
from ...errors import DataError, ModelError, OutputError
from ..assembly import MODEL_INPUTS
from ..effects import effect_names, missing_effect
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..settings import SimulationSettings
from ..simulate import simulate_inputs
from .environment import (
    BenchNoise,
    bench_drive,
    bench_problems,
    experiment_meta,
    experiment_name,
    measured_signals,
)
from .scenarios import RAMPS, DitherSetting, RampProfile

__all__ = [
    "BUILTIN_EFFECTS",
    "DEFAULT_SETTINGS",
    "StandConfig",
    "StandRun",
    "as_built_values",
    "run_stand",
    "truth_path",
    "write_stand",
]

#: Effects always present on the stand (undeclared in the default fit model).
BUILTIN_EFFECTS: tuple[str, ...] = ("stribeck_friction", "flow_force", "sensor_lag")

#: Dither settings of the full stand: 3 frequencies × 3 amplitude shapes.
DEFAULT_SETTINGS: tuple[DitherSetting, ...] = tuple(
    DitherSetting(f, s) for f in (30.0, 50.0, 70.0) for s in ("A", "B", "C")
)


def as_built_values() -> dict[str, float]:
    """The stand unit's "as-built" deviations from the datasheet (engineering units).

    More friction and a tighter damping orifice than the datasheet says: the
    default-parameter model underestimates hysteresis, as in the source paper.
    """
    return {
        "reg_F_c": 1.6,
        "vfs_d_orf": 0.40,
        "vfs_K_m": 14.4,
        "vfs_F_pre": 1.1,
        "reg_F0": -1.6,
        "latch_F0": 28.3,
        "cacc_k": 36.0,
        "fluid_beta": 1.3,
        "slag_tau": 4.0,
    }


@dataclass(frozen=True)
class StandConfig:
    """What the stand runs.

    Attributes
    ----------
    effects : tuple of str
        Extra library effects switched on (on top of the built-ins).
    builtin_effects : bool
        Include :data:`BUILTIN_EFFECTS` (False: the base model + noise only).
    settings : tuple of DitherSetting
        Dither settings; each is run at every ramp.
    ramps : tuple of RampProfile
        Ramp profiles.
    seed : int
        Seed of noise, wander and temperature drift.
    sample_rate_Hz : float
        Logging rate (Hz).
    substeps : int
        ROS2 steps per sample (finer than the fit model's default).
    overrides : dict
        Truth parameter values replacing the as-built ones (engineering units).
    pressure_noise_bar, current_noise_mA : float
        Standard deviation of sensor noise.
    pressure_lsb_bar, current_lsb_mA : float
        ADC quantization steps.

    Raises
    ------
    ModelError
        Listing every problem of the settings, ramps, seed, sample rate, substeps and noise
        (:func:`~clutchlab.physics.stand.environment.bench_problems`).
    """

    effects: tuple[str, ...] = ()
    builtin_effects: bool = True
    settings: tuple[DitherSetting, ...] = DEFAULT_SETTINGS
    ramps: tuple[RampProfile, ...] = tuple(RAMPS.values())
    seed: int = 0
    sample_rate_Hz: float = 1000.0
    substeps: int = 8
    overrides: dict[str, float] = field(default_factory=dict)
    pressure_noise_bar: float = 0.025
    current_noise_mA: float = 2.0
    pressure_lsb_bar: float = 0.01
    current_lsb_mA: float = 0.5

    def __post_init__(self) -> None:
        problems = bench_problems(
            self.settings,
            self.ramps,
            self.seed,
            self.sample_rate_Hz,
            self.substeps,
            self.noise,
        )
        if problems:
            raise ModelError("invalid stand configuration:\n  - " + "\n  - ".join(problems))

    @property
    def noise(self) -> BenchNoise:
        """The bench's measurement chain (sensor noise and ADC steps)."""
        return BenchNoise(
            self.pressure_noise_bar,
            self.current_noise_mA,
            self.pressure_lsb_bar,
            self.current_lsb_mA,
        )

    def model(self) -> CircuitModel:
        """The stand's truth model (built-in + requested effects)."""
        names = list(BUILTIN_EFFECTS) if self.builtin_effects else []
        for e in effect_names(self.effects, "stand effects"):  # unknown names fail here
            if e not in names:
                names.append(e)
        return CircuitModel().with_effects(*names)

    def truth_params(self, model: CircuitModel | None = None) -> ParameterSet:
        """Truth parameters: as-built deviations (where the parameter exists) + overrides."""
        model = model or self.model()
        names = {p.name for p in model.parameters}
        unknown = sorted(set(self.overrides) - names)
        if unknown:
            raise ModelError(
                "invalid stand overrides:\n  - "
                + "\n  - ".join(_unknown_override(n, names) for n in unknown)
            )
        values = {k: v for k, v in as_built_values().items() if k in names}
        return model.params(**(values | self.overrides))


@dataclass(frozen=True)
class StandRun:
    """A generated dataset with its truth.

    Attributes
    ----------
    dataset : Dataset
        The measured experiments (noise, quantization and wander included).
    model : CircuitModel
        The stand's truth model (built-in and requested effects).
    params : ParameterSet
        The truth parameter values, engineering units.
    config : StandConfig
        What was run.
    true_pressure : dict of str to numpy.ndarray
        Per experiment, the noise-free clutch pressure at the clutch node (bar) on the
        experiment's time grid.
    """

    dataset: Dataset
    model: CircuitModel
    params: ParameterSet
    config: StandConfig
    true_pressure: dict[str, np.ndarray]

    def truth(self) -> dict:
        """JSON-ready truth: effects, every parameter value, seed, settings."""
        return {
            "effects": list(self.model.effect_names),
            "parameters": {
                p.name: {"value": self.params[p.name], "unit": p.unit}
                for p in self.model.parameters
            },
            "changed_from_defaults": self.params.changed(),
            "seed": self.config.seed,
            "substeps": self.config.substeps,
            "noise": self.config.noise.as_dict(),
        }


def run_stand(config: StandConfig | None = None, progress: bool = True) -> StandRun:
    """Simulate every ramp × dither setting of ``config``; return the dataset and its truth."""
    config = config or StandConfig()
    model = config.model()
    params = config.truth_params(model)
    sim = SimulationSettings(drive="command", substeps=config.substeps, settle_s=1.0)
    rng = np.random.default_rng(config.seed)
    names = [s.name for s in MODEL_INPUTS]
    fns = model.functions("command")
    i_state = fns.state_index("i")
    traces, truth_p = [], {}
    jobs = [(r, k, s) for r in config.ramps for k, s in enumerate(config.settings)]
    for ramp, k, setting in tqdm(jobs, desc="stand", unit="exp", disable=not progress):
        drive = bench_drive(ramp, setting, k, rng, config.sample_rate_Hz)
        t = drive.time_s
        u = np.zeros((len(t), len(names)))
        u[:, names.index("current_nom_mA")] = drive.current_nom_mA
        u[:, names.index("dither_amp_mA")] = drive.dither_amp_mA
        u[:, names.index("dither_freq_Hz")] = setting.freq_Hz
        u[:, names.index("dither_phase")] = setting.freq_Hz * t + drive.phase0
        u[:, names.index(f"wave_{setting.waveform}")] = 1.0
        u[:, names.index("line_pressure_bar")] = drive.line_bar
        u[:, names.index("prime_pressure_bar")] = drive.prime_bar
        u[:, names.index("oil_temp_C")] = drive.oil_temp_C
        x, y = simulate_inputs(model, params, t, u, "command", sim)
        name = experiment_name(ramp, setting)
        truth_p[name] = y[:, 1].copy()
        signals = measured_signals(rng, drive, x[:, i_state], y[:, 0], config.noise)
        traces.append(Trace(name, signals, meta=experiment_meta(ramp, setting)))
    dataset = Dataset(
        traces,
        manifest_extra={
            "source": "clutchlab synthetic test stand",
            "sample_rate_Hz": config.sample_rate_Hz,
        },
    )
    return StandRun(dataset, model, params, config, truth_p)


def _unknown_override(name: str, known: set[str]) -> str:
    """The problem of an override of a parameter the stand's model lacks: the effect that
    owns it (to add with ``StandConfig(effects=...)``), or the closest known names."""
    missing = missing_effect(name)
    if missing is not None:
        owner, text = missing
        return f"{name}: it {text} (StandConfig(effects=({owner!r},), overrides=...))"
    close = difflib.get_close_matches(name, sorted(known), n=3)
    hint = f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
    return f"{name}: unknown parameter{hint}"


def truth_path(out: str | Path) -> Path:
    """Where the truth of a dataset written to ``out`` goes: ``<out>.truth.json`` beside it.

    ``out`` without a name of its own (``.``, ``data/..``) is resolved first.
    """
    out = Path(out)
    if out.name in ("", ".", ".."):
        out = out.resolve()
    return out.with_name(out.name + ".truth.json")


def write_stand(
    out: str | Path,
    config=None,
    *,
    overwrite: bool = False,
    progress: bool = True,
    figure: bool = True,
) -> StandRun:
    """Run the stand and write the dataset folder, its overview PNG and the truth file.

    Parameters
    ----------
    out : path
        Dataset folder to create (``manifest.json`` + one CSV per experiment).
    config : StandConfig or PlantConfig, optional
        What to run: the stand, or a plant of the zoo
        (:class:`~clutchlab.physics.stand.plants.PlantConfig`); the full default stand
        when omitted.
    overwrite : bool
        Replace an existing dataset folder.
    progress : bool
        Show a progress bar.
    figure : bool
        Write ``pressure_vs_current.png`` (the three ramps) into the folder.

    Returns
    -------
    StandRun or PlantRun
    """
    from .plants import PlantConfig, run_plant

    out = Path(out)
    config = StandConfig() if config is None else config
    if not isinstance(config, StandConfig | PlantConfig):
        raise TypeError(f"write_stand: config must be a StandConfig or PlantConfig, not {config!r}")
    # the folder is swapped in whole: not the current folder or one holding it
    check_output(out, kind="folder", overwrite=overwrite, what="dataset folder", whole=True)
    check_output(truth_path(out), kind="file", overwrite=overwrite, what="truth file")
    _check_truth_is_ours(truth_path(out))
    _check_files(out, config, figure)  # before the (minutes long) simulation
    if isinstance(config, PlantConfig):
        run = run_plant(config, progress=progress)
    else:
        run = run_stand(config, progress=progress)
    extra = {}
    if figure:
        from .overview import plot_pressure_vs_current

        fig = plot_pressure_vs_current(run.dataset)
        extra["pressure_vs_current.png"] = lambda path: fig.savefig(path, dpi=120, format="png")
    save_dataset(run.dataset, out, overwrite=overwrite, extra=extra)
    truth = json.dumps(run.truth(), indent=2, ensure_ascii=False) + "\n"
    write_file_atomic(truth_path(out), truth.encode("utf-8"), overwrite=True)
    return run


def _check_files(out: Path, config, figure: bool) -> None:
    """What :func:`save_dataset` would refuse, checked before the simulation.

    Experiment names that are not portable file names (a ramp label ``a/b``), and a user's
    file (or another kind of clutchlab output) in ``out`` where a dataset file would go.
    """
    names = [experiment_name(r, s) for r in config.ramps for s in config.settings]
    if problems := experiment_name_problems(names):
        raise DataError(f"cannot write the dataset {out}", problems)
    files = [f"{n}.csv" for n in names] + [MANIFEST_NAME]
    if figure:
        files.append("pressure_vs_current.png")
    check_folder_files(out, files, what="dataset folder")


def _check_truth_is_ours(path: Path) -> None:
    """Refuse to replace a ``<out>.truth.json`` that is not a truth file clutchlab wrote.

    ``--overwrite`` replaces the dataset folder's files clutchlab wrote; a file of the user's
    that happens to stand where the truth goes is not one of them.
    """
    if not path.is_file():
        return
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        doc = None
    if not (isinstance(doc, dict) and {"effects", "parameters", "seed", "noise"} <= set(doc)):
        raise OutputError(
            f"truth file {path}: exists and is not a truth file clutchlab wrote; move it "
            "away or choose another --out"
        )
