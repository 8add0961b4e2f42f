"""Closing the loop (issue 7, must-show 1): one undeclared library effect is named first,
and adding it halves the unseen medium-ramp error.

For each case of ``MUST_SHOW_CASES``: the short discovery stand with that effect switched on
(the only physics the base model lacks), the base model fitted on the fast and slow ramps,
``discover`` run with at most one effect. The effect named first must be the one on the
stand, and the RMSE of the dither-period-mean pressure on the medium ramp — never used for
any decision — must drop by at least half. Slow: a few minutes per effect on 2 quiet cores.
Each test prints its measured row as one ``MUST_SHOW_ROW {json}`` line (``pytest -s``);
``python benchmarks/bench_discover.py`` runs the same cases and prints them as a table.
"""

from __future__ import annotations

import json

import pytest

from clutchlab.validation.discover import DiscoverySettings
from clutchlab.validation.discover.scenarios import MUST_SHOW_CASES, run_must_show

pytestmark = pytest.mark.slow

#: The issue's bar: the medium-ramp RMSE after augmentation is at most half of before.
MAX_ERROR_RATIO = 0.5


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
