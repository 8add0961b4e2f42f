"""Stand scenarios of the discovery must-show: short ramps, one or more undeclared effects.

The stand's "as-built" deviations of parameters that the fit does not free (clutch
accumulator spring, bulk modulus) are set back to the datasheet values here, so that
the effects switched on are the only things the fitted base model cannot represent;
everything else of the stand stays (the as-built values of the freed parameters, the
resolved dither through the current loop at a finer step, line / prime pressure wander,
sensor noise, ADC quantization).
"""

from __future__ import annotations

from ...physics import CircuitModel
from ...physics.fit import DEFAULT_FREE
from ...physics.stand import DitherSetting, RampProfile, StandConfig, as_built_values

__all__ = ["DISCOVERY_RAMPS", "MUST_SHOW_CASES", "discovery_stand", "representable_overrides"]

#: 0 → 1100 → 0 mA ramps of 2.5 / 5 / 10 s with 1 s holds (the stand's are 2.5 / 10 / 40 s):
#: the medium ramp's rate lies between the training rates, at a quarter of the samples.
DISCOVERY_RAMPS: tuple[RampProfile, ...] = (
    RampProfile("fast", 2.5),
    RampProfile("medium", 5.0),
    RampProfile("slow", 10.0),
)

#: Dither settings: one (50 Hz, shape B), or three (30 Hz/A at 40 °C, 50 Hz/B at 55 °C,
#: 70 Hz/C at 70 °C) for effects that need temperature levels or dither shapes.
SETTINGS_1 = (DitherSetting(50.0, "B"),)
SETTINGS_3 = (DitherSetting(30.0, "A"), DitherSetting(50.0, "B"), DitherSetting(70.0, "C"))


def representable_overrides() -> dict[str, float]:
    """Datasheet values for the as-built deviations the default fit cannot absorb."""
    defaults = CircuitModel().default_params()
    names = {p.name for p in CircuitModel().parameters}
    return {k: defaults[k] for k in as_built_values() if k in names and k not in DEFAULT_FREE}


def discovery_stand(
    effects: tuple[str, ...] = (),
    *,
    n_settings: int = 1,
    overrides: dict[str, float] | None = None,
    seed: int = 1,
) -> StandConfig:
    """A short stand configuration with ``effects`` as the only undeclared physics.

    Parameters
    ----------
    effects : tuple of str
        Library effects switched on (the stand's built-in ones are off).
    n_settings : {1, 3}
        Dither settings (see ``SETTINGS_1`` / ``SETTINGS_3``).
    overrides : dict, optional
        Further truth values (engineering units), e.g. an effect's strength.
    seed : int
        Noise seed.
    """
    if n_settings not in (1, 3):
        raise ValueError(f"n_settings must be 1 or 3, got {n_settings}")
    return StandConfig(
        effects=tuple(effects),
        builtin_effects=False,
        settings=SETTINGS_1 if n_settings == 1 else SETTINGS_3,
        ramps=DISCOVERY_RAMPS,
        seed=seed,
        overrides=representable_overrides() | dict(overrides or {}),
    )


#: Must-show cases: effect -> (dither settings, truth overrides). An override raises an
#: effect whose stand-default strength changes the medium-ramp pressure by less than the
#: floor the fitted base model already reaches (latch-snap timing jitter, ~0.02 bar RMSE),
#: so that a 50 % error reduction is possible at all; each stays inside its bounds.
MUST_SHOW_CASES: dict[str, tuple[int, dict[str, float]]] = {
    "supply_droop": (1, {}),
    "accumulator_spring_nonlinearity": (1, {}),
    "eddy_current_lag": (1, {}),
    "spool_leakage": (1, {"leak_G": 1500.0}),
    "vfs_magnetic_hysteresis": (1, {"mhys_H": 2.0}),
    "oil_temperature": (3, {}),
    "sensor_lag": (1, {"slag_tau": 20.0}),
    "transport_delay": (1, {"delay_d": 10.0, "delay_d0": 10.0}),
}
