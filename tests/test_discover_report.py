"""What a discovery tells its reader: the summary, the console table and the figures.

Fast: the records are stand-ins with the attributes the summary, table and figures read.
"""

from __future__ import annotations

from types import SimpleNamespace

from clutchlab.validation.discover.loop import _summary

MATCHED = (
    "a flexible law of at most the same size predicted the left-out experiments as well "
    "(sensor_lag by reg_pilot_lag; all training experiments): no effect claimed"
)


def _state(train=0.0226, test=0.0348):
    return SimpleNamespace(train={"rmse_bar": train}, test={"rmse_bar": test})


def _candidate(effect, significant, statistic=0.0, share=0.0):
    return SimpleNamespace(
        effect=effect, significant=significant, statistic=statistic, share=share, diverged=[]
    )


def _iteration(decision, candidates, effect=None, index=0):
    return SimpleNamespace(
        index=index,
        effect=effect,
        decision=decision,
        candidates=candidates,
        before=_state(),
        after=_state(),
        delta_bic=None,
    )


def _diag(signature=("didt_mA_s", "didt_sign")):
    return SimpleNamespace(
        signature=list(signature), whiteness={"white": False}, ramp_note=lambda: ""
    )


def test_a_significant_effect_matched_by_a_flexible_law_is_not_called_insignificant():
    it = _iteration(
        MATCHED, [_candidate("sensor_lag", True, 273.8, 0.4), _candidate("stribeck", False)]
    )
    text = _summary([it], True, _diag(), 2)
    assert "no library effect explains a significant share" not in text
    assert "sensor_lag explains a significant share of it, but no effect is claimed" in text
    assert "reg_pilot_lag" in text and "it follows didt_mA_s, didt_sign" in text


def test_an_unexplained_residual_without_a_significant_effect_says_so():
    it = _iteration("no significant candidate", [_candidate("sensor_lag", False)])
    text = _summary([it], True, _diag(), 2)
    assert "no library effect explains a significant share of it" in text


def test_an_effect_limit_of_zero_does_not_claim_that_nothing_was_found():
    it = _iteration("effect limit reached", [])
    text = _summary([it], False, _diag(()), 2)
    assert "no missing effect found" not in text
    assert "no effect was looked for (the effect limit is 0)" in text


def test_the_console_table_keeps_its_columns_when_no_effect_is_added():
    from clutchlab.validation.discover.result import DiscoveryResult

    it = _iteration(MATCHED, [_candidate("sensor_lag", True, 273.8, 0.4)])
    result = DiscoveryResult([it], _state(), _state(), True, [], "", [], [], 1.0)
    head, row, *notes = result.table().splitlines()
    assert head.index("evidence") == row.index("sensor_lag")  # the columns line up
    assert MATCHED not in row and row.split()[1] == "—"
    assert notes == [f"iteration 0: no effect added: {MATCHED}"]
