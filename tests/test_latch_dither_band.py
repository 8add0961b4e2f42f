"""The ``latch_dither_band`` flexible law: a latch band that moves with the dither.

A latch that must see its pilot beyond a threshold for a dwell time, or that filters the
dither, switches at currents that move apart with the dither amplitude by an amount that
depends on the frequency (zoo: quadratic_play, saturating_lugre). The law widens (or
narrows) the model's latch band by ``2w`` in pilot pressure; identity at its defaults and
smoothness are checked for every flexible law in ``test_structure_laws``.
"""

from __future__ import annotations

import numpy as np
import pytest
from latch_support import switch_currents

from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.effects import FLEXIBLE_LAWS
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

RAMPS = (RampProfile("fast", 2.5, 0.5),)
MODEL = CircuitModel().with_effects("latch_dither_band")


@pytest.fixture(scope="module")
def stand_traces():
    settings = (DitherSetting(30.0, "B"), DitherSetting(50.0, "B"), DitherSetting(50.0, "C"))
    cfg = StandConfig(settings=settings, ramps=RAMPS)
    return {t.name: t for t in run_stand(cfg, False).dataset}


def _switch_currents(trace, **values) -> tuple[float, float]:
    """Latch-on and latch-off currents (mA) of the law's model at ``values``."""
    return switch_currents(MODEL, trace, **values)


def test_a_positive_amplitude_term_widens_the_band_more_at_a_larger_dither(stand_traces):
    big, small = stand_traces["fast_50Hz_B"], stand_traces["fast_50Hz_C"]  # ~200 / 40 mA
    widened = {}
    for name, tr in (("big", big), ("small", small)):
        on0, off0 = _switch_currents(tr)
        on1, off1 = _switch_currents(tr, ldb_k0=0.5)
        assert on1 > on0 + 5.0 and off1 < off0, (name, on0, on1, off0, off1)
        widened[name] = (on1 - off1) - (on0 - off0)
    assert widened["big"] > 2.0 * widened["small"], widened


def test_frequency_terms_act_away_from_the_reference_frequency_only(stand_traces):
    at_ref, off_ref = stand_traces["fast_50Hz_B"], stand_traces["fast_30Hz_B"]
    assert _switch_currents(at_ref, ldb_c1=1.0) == pytest.approx(_switch_currents(at_ref), abs=0.5)
    on0, _ = _switch_currents(off_ref)
    on1, _ = _switch_currents(off_ref, ldb_c1=-1.0)  # v = log2(30/50) < 0: w > 0, later
    assert on1 > on0 + 5.0, (on0, on1)


def test_without_dither_the_law_does_nothing(stand_traces):
    tr = stand_traces["fast_50Hz_B"]
    signals = dict(tr.signals)
    signals["dither_amp_mA"] = np.zeros(len(tr))
    plain = type(tr)(tr.name, signals, meta=dict(tr.meta))
    values = {"ldb_c1": 2.0, "ldb_c2": -1.0, "ldb_k0": 1.0, "ldb_k1": 1.0, "ldb_k2": 1.0}
    base = simulate(MODEL, MODEL.params(), plain).pressure_bar
    moved = simulate(MODEL, MODEL.params(**values), plain).pressure_bar
    np.testing.assert_allclose(moved, base, atol=1e-9)


def test_its_five_strengths_are_what_a_fit_frees():
    cls = FLEXIBLE_LAWS["latch_dither_band"]
    assert cls.fit_parameters() == ("ldb_c1", "ldb_c2", "ldb_k0", "ldb_k1", "ldb_k2")
    assert not cls.HELD_SWITCH
    assert all(MODEL.params()[n] == 0.0 for n in cls.fit_parameters())


def test_it_is_added_to_a_fit_already_made_only():
    """Fitted from the datasheet start it did worse (session 55, E4): no structure selection
    and no discovery alternative fits it from there."""
    from clutchlab.physics.fit.structure import STRUCTURES
    from clutchlab.validation.discover.alternatives import alternatives_for

    assert FLEXIBLE_LAWS["latch_dither_band"].WARM_ONLY
    assert all("latch_dither_band" not in laws for laws in STRUCTURES.values())
    free = ("vfs_K_m", "latch_F0")
    assert "latch_dither_band" not in [a.law for a in alternatives_for(CircuitModel(), free, 9)]
