"""Closing the loop (issue 7, must-show 1): one undeclared library effect is named first,
and adding it halves the unseen medium-ramp error.

For each case of ``MUST_SHOW_CASES``: the short discovery stand with that effect switched on
(the only physics the base model lacks), the base model fitted on the fast and slow ramps,
``discover`` run with at most one effect. The effect named first must be the one on the
stand, and the RMSE of the dither-period-mean pressure on the medium ramp — never used for
any decision — must drop by at least half. Slow: a few minutes per effect on 2 quiet cores.
Each test prints its measured row as one ``MUST_SHOW_ROW {json}`` line (``pytest -s``);
``python benchmarks/bench_discover.py`` runs the same cases and prints them as a table.

The second test runs the effects that pass at the one outcome-blind size of every library
effect (``effect_size.calibrate_effect_size``: 0.10 bar RMS change of the training pressure,
fixed from the stand's truth before any discovery); ``python studies/discover_effect_size.py``
runs all 13 and prints every row, pass or fail.
"""

from __future__ import annotations

import json

import pytest

from clutchlab.validation.discover import DiscoverySettings
from clutchlab.validation.discover.scenarios import (
    MAX_ERROR_RATIO,
    MUST_SHOW_CASES,
    run_must_show,
    run_sized_case,
)

pytestmark = pytest.mark.slow

#: The effects that passed at the outcome-blind size of ``effect_size.calibrate_effect_size``
#: in ``studies/discover_effect_size.py`` (every row is in BENCHMARKS.md). The magnetic
#: hysteresis passes since the profile look (7918097). air_entrainment passes too (6 of 13
#: on session 51's code) but by one point (51 % against the 50 % bar), so it is not pinned
#: here as a regression check.
SIZED_PASSING = (
    "accumulator_spring_nonlinearity",
    "sensor_lag",
    "spool_leakage",
    "supply_droop",
    "vfs_magnetic_hysteresis",
)


@pytest.mark.parametrize("effect", sorted(MUST_SHOW_CASES))
def test_discover_names_the_undeclared_effect_and_halves_the_test_error(effect):
    res, row = run_must_show(effect, settings=DiscoverySettings(progress=False))
    print(res.table())
    print("MUST_SHOW_ROW " + json.dumps(row))
    first = res.iterations[0]
    assert first.effect == effect, [(c.effect, c.statistic, c.share) for c in first.candidates]
    assert not any(name.startswith("medium") for name in res.train)
    assert res.test and all(name.startswith("medium") for name in res.test)
    before, after = row["test_rmse_bar"]
    assert after <= MAX_ERROR_RATIO * before, (before, after)
    assert first.delta_bic < 0


@pytest.mark.parametrize("effect", SIZED_PASSING)
def test_at_the_outcome_blind_size_the_effect_is_named_and_the_test_error_halved(effect):
    res, row = run_sized_case(effect, settings=DiscoverySettings(progress=False))
    print(res.table())
    print("SIZED_ROW " + json.dumps(row))
    assert row["size"]["rms_bar"] == pytest.approx(0.10, rel=0.05)
    assert res.iterations[0].effect == effect
    assert row["passes"]
