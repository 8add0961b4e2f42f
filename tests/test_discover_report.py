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
        time_limited=False,
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


def _model_state(rmse_train, rmse_test, experiments=("fast_30Hz_A", "slow_30Hz_A")):
    import numpy as np

    n = 50
    cur = np.tile(np.linspace(0.0, 1100.0, n), len(experiments))
    residual = SimpleNamespace(
        experiments=list(experiments),
        slices=[(k * n, (k + 1) * n) for k in range(len(experiments))],
        signals={"current_mA": cur},
        r=0.01 * np.sin(cur / 100.0),
        keep=np.ones(cur.size, bool),
    )
    test = {"medium_30Hz_A": (np.linspace(0.0, 1100.0, n), 0.02 * np.cos(np.arange(n)))}
    return SimpleNamespace(
        residual=residual,
        train={"rmse_bar": rmse_train},
        test={"rmse_bar": rmse_test},
        test_residual=test,
    )


def _figure_iteration(effect=None):
    it = _iteration(
        MATCHED,
        [_candidate("sensor_lag", True, 273.8, 0.4), _candidate("stribeck_friction", False)],
        effect=effect,
    )
    it.before, it.after = _model_state(0.0226, 0.0348), _model_state(0.0226, 0.0348)
    it.threshold_p = 0.005
    for c in it.candidates:
        c.k, c.p_value, c.novelty, c.status, c.n_tests = 1, 0.5, 0.3, "scored", 1
    return it


def _drawn(fig):
    import io

    fig.savefig(io.BytesIO(), format="png", dpi=100)  # lays the figure out
    return fig


def test_residual_figure_titles_fit_and_say_what_was_added_and_which_experiment_is_which():
    from clutchlab.validation.discover.report import plot_residuals

    fig = _drawn(plot_residuals(_figure_iteration()))
    width = fig.bbox.width
    for ax in fig.axes:
        box = ax.title.get_window_extent()
        assert box.x0 >= 0 and box.x1 <= width, ax.get_title()  # not cut at the edge
        assert "unchanged" not in ax.get_title()
    titles = [ax.get_title() for ax in fig.axes]
    assert any("no effect added" in t for t in titles)
    labels = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().texts]
    assert {"fast_30Hz_A", "slow_30Hz_A", "medium_30Hz_A"} <= set(labels)
    assert "model − measured" in fig.get_suptitle()


def test_diagnostics_title_is_wrapped_not_cut():
    from clutchlab.validation.discover.report import plot_diagnostics

    summary = "RMS 0.0173 bar, not white; follows " + ", ".join(
        f"signal_{k} (η² 0.1{k}, r +0.3{k})" for k in range(8)
    )
    it = _figure_iteration()
    it.diagnostics = SimpleNamespace(
        associations=[{"signal": "didt_mA_s", "eta2": 0.14}],
        cross_correlation={"didt_mA_s": {"lags_s": [-0.1, 0.0, 0.1], "values": [0.2, 0.3, 0.2]}},
        spectrum={"freq_Hz": [0.0, 1.0, 2.0], "psd_bar2_Hz": [1e-4, 1e-5, 1e-6]},
        summary=lambda: summary,
    )
    fig = _drawn(plot_diagnostics(it))
    assert " ".join(fig.get_suptitle().split()).endswith("signal_7 (η² 0.17, r +0.37)")
    box = fig._suptitle.get_window_extent()
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width


def test_evidence_figure_explains_its_colours_and_states_a_zero_statistic():
    from clutchlab.validation.discover.report import plot_evidence

    fig = _drawn(plot_evidence(_figure_iteration()))
    ax = fig.axes[0]
    legend = [t.get_text() for t in ax.get_legend().texts]
    assert legend == ["significant, not added", "not significant"]
    notes = [t.get_text() for t in ax.texts]
    assert " 0, share 0.00" in notes and " 274, share 0.40" in notes


def test_interactive_figures_say_what_was_added_and_keep_the_whole_summary():
    from clutchlab.validation.discover.interactive import (
        iplot_diagnostics,
        iplot_evidence,
        iplot_residuals,
    )

    it = _figure_iteration()
    titles = [a.text for a in iplot_residuals(it).layout.annotations]
    assert titles and not any("unchanged" in t for t in titles)
    assert any("after (no effect added)" in t for t in titles)
    summary = "RMS 0.0173 bar, not white; follows " + ", ".join(
        f"signal_{k} (η² 0.1{k}, r +0.3{k})" for k in range(8)
    )
    it.diagnostics = SimpleNamespace(
        associations=[{"signal": "didt_mA_s", "eta2": 0.14, "unit": "mA/s"}],
        cross_correlation={"didt_mA_s": {"lags_s": [-0.1, 0.0, 0.1], "values": [0.2, 0.3, 0.2]}},
        spectrum={"freq_Hz": [0.0, 1.0, 2.0], "psd_bar2_Hz": [1e-4, 1e-5, 1e-6]},
        summary=lambda: summary,
    )
    title = iplot_diagnostics(it).layout.title.text
    assert title.replace("<br>", " ").endswith("signal_7 (η² 0.17, r +0.37)")
    assert "grey: not significant" in iplot_evidence(it).layout.title.text


def test_interactive_residuals_without_test_experiments_have_no_empty_test_row():
    from clutchlab.validation.discover.interactive import iplot_residuals

    it = _figure_iteration()
    for state in (it.before, it.after):
        state.test_residual = {}
        state.test = {"rmse_bar": float("nan")}
    titles = [a.text for a in iplot_residuals(it).layout.annotations]
    assert len(titles) == 2 and not any("nan" in t or "test" in t for t in titles)


def test_the_console_table_shows_a_dash_without_test_experiments():
    from clutchlab.validation.discover.result import DiscoveryResult

    it = _iteration("no significant effect", [_candidate("supply_droop", False)])
    it.before = it.after = _state(0.4221, float("nan"))
    result = DiscoveryResult([it], it.before, it.after, True, [], "", [], [], 1.0)
    row = result.table().splitlines()[1]
    assert "nan" not in row and "0.4221 →  0.4221         – →       –" in row


def test_the_parameter_table_writes_newton_per_ampere_not_n_slash_a():
    """'N/A' in a table of parameters reads as 'not applicable' (vfs_K_m's unit)."""
    from clutchlab.validation.discover.report import _parameter_rows

    rows = _parameter_rows(
        [
            {"name": "vfs_K_m", "value": 14.42, "std_error": 0.0033, "unit": "N/A"},
            {"name": "vfs_i_knee", "value": 201.1, "std_error": 0.34, "unit": "mA"},
        ]
    )
    assert [r[-1] for r in rows] == ["N·A⁻¹", "mA"]


def test_the_parameter_table_marks_a_parameter_the_fit_could_not_identify():
    """reg_F_c on the stand with sensor_lag: 'not identifiable' in fit-physics, a plain
    0.011156 ± 0.0158 N in the discovery's parameter table."""
    from clutchlab.validation.discover.report import _parameter_rows

    rows = _parameter_rows(
        [
            {
                "name": "reg_F_c",
                "value": 0.0112,
                "std_error": 0.0158,
                "unit": "N",
                "identifiable": False,
            },
            {
                "name": "latch_k",
                "value": 2.02,
                "std_error": 3e-4,
                "unit": "N/mm",
                "identifiable": True,
            },
        ]
    )
    assert [r[0] for r in rows] == ["reg_F_c (not identifiable)", "latch_k"]


def test_a_p_value_below_the_level_beside_not_significant_says_which_test_failed():
    """flow_force on the stand with sensor_lag: p 5.8e-07 under a stated level 0.00077 and
    'significant: no', because its share 0.073 is below min_share 0.10; the report said
    only 'Significance level per candidate: p < 0.00077'."""
    from clutchlab.validation.discover.report import (
        _CAND_HEAD,
        _candidate_rows,
        _significance_text,
    )

    it = _figure_iteration()
    it.threshold_p = 7.7e-4
    flow = SimpleNamespace(
        effect="flow_force", k=1, statistic=25.0, p_value=5.8e-7, share=0.073, novelty=0.12,
        probe="zero", n_tests=1, significant=False, status="scored", refit={}, diverged=[],
    )  # fmt: skip
    lag = SimpleNamespace(
        effect="sensor_lag", k=1, statistic=235.5, p_value=3.7e-53, share=0.32, novelty=0.36,
        probe="zero", n_tests=6, significant=True, status="scored", refit={}, diverged=[],
    )  # fmt: skip
    weak = SimpleNamespace(
        effect="air_entrainment", k=1, statistic=5.4, p_value=0.021, share=0.025, novelty=0.67,
        probe="zero", n_tests=1, significant=False, status="scored", refit={}, diverged=[],
    )  # fmt: skip
    it.candidates = [lag, flow, weak]
    column = _CAND_HEAD.index("significant")
    cells = [row[column] for row in _candidate_rows(it, 0.1)]
    assert cells == ["yes", "no (share < 0.10)", "no"]
    rule = _significance_text(7.7e-4, 0.1)
    assert "p < 0.00077" in rule and "share is at least 0.10" in rule
    assert "number of tests" in rule


def test_a_discovery_stopped_at_its_budget_says_what_it_had_done_and_how_to_finish():
    """Stand + sensor_lag, --budget 240: the summary said only that it stopped during
    transport_delay's screening refit, not that sensor_lag's refit had lowered the BIC
    by 137 without being compared with a flexible law, nor what to run next."""
    from clutchlab.validation.discover.result import DiscoveryResult

    lag = _candidate("sensor_lag", True, 235.5, 0.32)
    lag.refit = {"subset": "4 of 6 experiments", "delta_bic": -137.4}
    delay = _candidate("transport_delay", True, 203.4, 0.29)
    delay.refit = {}
    flow = _candidate("flow_force", False, 25.0, 0.07)
    flow.refit = {}
    it = _iteration("stopped: the discovery's time budget (240 s) was spent", [lag, delay, flow])
    it.time_limited = True
    args = ([it], _state(), _state(), False, [], "", [], [], 237.7)
    result = DiscoveryResult(*args, settings={"time_limit_s": 240.0}, time_limited=True)
    note = result.stop_note()
    assert "2 significant candidate(s): sensor_lag (share 0.32), transport_delay" in note
    assert "sensor_lag's refit on 4 of 6 experiments: ΔBIC -137.4" in note
    assert "not yet compared with a flexible law" in note and "flow_force" not in note
    assert "--budget larger than 240 s" in note and "--physics-model" in note
    assert DiscoveryResult(*args, settings={"time_limit_s": 240.0}).stop_note() == ""


def test_the_evidence_figure_says_why_a_bar_past_the_dashed_line_is_not_significant():
    """flow_force on the stand with sensor_lag: statistic 25 past the dashed line labelled
    'significance threshold', drawn grey 'not significant' (its share 0.07 < 0.10), and the
    line was the level for one test, not the one of a candidate with six."""
    from clutchlab.validation.discover.interactive import iplot_evidence
    from clutchlab.validation.discover.report import plot_evidence

    it = _figure_iteration()
    it.threshold_p = 7.7e-4
    flow = it.candidates[1]
    flow.effect, flow.statistic, flow.share, flow.p_value = "flow_force", 25.0, 0.07, 5.8e-7
    fig = _drawn(plot_evidence(it, 0.1))
    ax = fig.axes[0]
    label = ax.get_xlabel()
    assert "significance threshold" not in label
    assert "one test" in label and "share ≥ 0.10" in label and "/ tests" in label
    notes = [t.get_text() for t in ax.texts]
    assert " 25, share 0.07 < 0.10" in notes
    assert " 274, share 0.40" in notes  # a significant one is not marked
    assert " k=1 " in notes
    title = iplot_evidence(it, 0.1).layout.xaxis.title.text
    assert "share ≥ 0.10" in title and "one test" in title


def test_the_fit_state_explains_a_limit_and_names_the_option_that_raises_it():
    """Stand + sensor_lag: 'Solved_To_Acceptable_Level (pre-fit) → Maximum_Iterations_Exceeded
    (refine), converged' read as a contradiction; zoo plant: 'Maximum_Iterations_Exceeded
    (pre-fit), NOT converged' said nothing of --max-iter."""
    from clutchlab.validation.discover.report import fit_state_text

    staged = "Solved_To_Acceptable_Level (pre-fit) → Maximum_Iterations_Exceeded (refine)"
    text = fit_state_text(staged, True)
    assert text.startswith(f"fit after: {staged}, converged (")
    assert "refinement stopping at its iteration limit ends a staged fit" in text
    text = fit_state_text("Maximum_Iterations_Exceeded (pre-fit)", False)
    assert "NOT converged" in text and "(--max-iter) may improve it" in text
    assert "--time-limit" not in text
    assert "--time-limit" in fit_state_text("Maximum_WallTime_Exceeded", False)
    given = "Cost_Plateau (pre-fit) → Not_Started_Short_Of_Time (refine)"
    text = fit_state_text(given, False, baseline=True)
    assert "(--time-limit) may improve it" in text
    assert "given with --physics-model: the same option of `clutchlab fit-physics`" in text
    assert "fit-physics" not in fit_state_text(given, False)
    assert fit_state_text("Solve_Succeeded", True) == "fit after: Solve_Succeeded, converged"


def test_the_diagnostics_figure_shows_both_eta2_its_threshold_and_what_a_lag_means():
    """The η² panel drew only η² on the residual, while the signature also reads η² beyond
    the current map against a threshold the panel did not show (zoo plant, warming oil:
    oil_temp_C 0.075 on the residual, 'follows no single signal (η² < 0.10 …)'); the lag
    axis did not say which sign means the residual comes later; τ had no unit."""
    from clutchlab.validation.discover.diagnostics import Diagnostics
    from clutchlab.validation.discover.interactive import iplot_diagnostics
    from clutchlab.validation.discover.report import plot_diagnostics

    it = _figure_iteration()
    it.diagnostics = Diagnostics(
        rms_bar=0.2334,
        n=1000,
        n_eff=50.0,
        tau_samples=51.7,
        associations=[
            {"signal": "didt_mA_s", "eta2": 0.088, "corr": 0.3, "eta2_beyond_current": None},
            {"signal": "oil_temp_C", "eta2": 0.075, "corr": 0.2, "eta2_beyond_current": 0.31},
        ],
        cross_correlation={
            "didt_mA_s": {
                "lag_s": -0.03,
                "corr": 0.33,
                "lags_s": [-0.1, 0.0, 0.1],
                "values": [0.2, 0.3, 0.2],
            },
        },
        spectrum={"freq_Hz": [0.0, 1.0, 2.0], "psd_bar2_Hz": [1e-4, 1e-5, 1e-6]},
        whiteness={"white": False, "p_value": 0.0},
    )
    assert "autocorrelation time τ 51.7 samples" in it.diagnostics.summary()
    fig = _drawn(plot_diagnostics(it))
    eta_ax, lag_ax = fig.axes[0], fig.axes[1]
    widths = sorted(round(p.get_width(), 3) for p in eta_ax.patches)
    assert widths == [0.0, 0.075, 0.088, 0.31]  # both η² of oil_temp_C are drawn
    assert [ln.get_xdata()[0] for ln in eta_ax.lines] == [0.1]
    assert "> 0: the residual follows the signal later" in lag_ax.get_xlabel()
    boxes = [ax.xaxis.label.get_window_extent() for ax in (eta_ax, lag_ax)]
    assert boxes[0].x1 <= boxes[1].x0  # the two axis labels do not run into each other
    ifig = iplot_diagnostics(it)
    assert len([t for t in ifig.data if t.type == "bar"]) == 2
    assert ifig.layout.xaxis.title.text.endswith("signature threshold")
    assert "follows the signal later" in ifig.layout.xaxis2.title.text


def test_the_console_table_says_what_its_evidence_column_and_star_mean():
    """'sensor_lag 225.5/0.48*' under 'evidence (statistic, share)': the star was not
    explained anywhere in the terminal output."""
    from clutchlab.validation.discover.result import DiscoveryResult

    it = _iteration(MATCHED, [_candidate("sensor_lag", True, 225.5, 0.48)])
    result = DiscoveryResult([it], _state(), _state(), True, [], "", [], [], 1.0)
    head, row, *_ = result.table().splitlines()
    assert "sensor_lag 225.5/0.48*" in row
    assert "statistic/share (*: significant)" in head


def test_an_unexplained_verdict_says_what_to_do_next():
    """'unexplained residual: … it follows didt_mA_s, didt_sign' named no command that goes
    on from there."""
    from clutchlab.validation.discover.result import DiscoveryResult

    it = _iteration("no significant candidate", [_candidate("sensor_lag", False)])
    sig = ["didt_mA_s", "didt_sign"]
    result = DiscoveryResult([it], _state(), _state(), True, sig, "", [], [], 1.0)
    text = result.next_steps()
    assert "follows didt_mA_s, didt_sign" in text
    assert "clutchlab select-structure" in text and "`hybrid` variant" in text
    assert "clutchlab effects" in text
    explained = DiscoveryResult([it], _state(), _state(), False, [], "", [], [], 1.0)
    assert explained.next_steps() == ""


def test_the_sparse_regression_line_says_its_terms_are_standardized():
    """'r/σ ≈ -0.20 current_mA oil_temp_C +0.18 didt_mA_s …' read as coefficients in bar
    per mA; the terms are standardized signals and r/σ the residual over its SD."""
    from clutchlab.validation.discover.report import sparse_text

    text = sparse_text(0.19)
    assert text.startswith("Sparse regression (pysindy STLSQ, R² 0.19;")
    assert "standard deviation" in text and "(signal − mean) / SD" in text
    assert "dimensionless" in text


def test_the_evidence_table_explains_its_columns_and_status_names():
    """latch_threshold_drift's status 'confounded', and the share / novelty columns, were
    not explained anywhere in the report."""
    from clutchlab.validation.discover.report import _CAND_HEAD, candidate_columns_note
    from clutchlab.validation.discover.scoring import MIN_NOVELTY

    note = candidate_columns_note(MIN_NOVELTY)
    assert f"confounded (novelty below {MIN_NOVELTY:g}" in note
    for column in ("statistic", "p", "share", "novelty", "ΔBIC", "status"):
        assert column in _CAND_HEAD
        assert f" {column} =" in note or f" {column}:" in note, column
    assert "linearized at =" in note


def test_the_split_line_says_what_its_seconds_are():
    """'Training: 6 experiments (…); test, only scored: 3 (…); 237.7 s.' left the number
    unnamed."""
    from clutchlab.validation.discover.report import _split_text

    result = SimpleNamespace(train=["fast_30Hz_A"], test=["medium_30Hz_A"], wall_s=237.7)
    assert _split_text(result).endswith("; wall time of the discovery 237.7 s.")


def test_the_json_result_carries_the_stop_note_and_the_next_steps():
    """--json / discovery.json had the summary but not what a stopped discovery had done nor
    what to do after an 'unexplained' verdict."""
    from clutchlab.validation.discover.result import DiscoveryResult

    base = SimpleNamespace(
        fit=SimpleNamespace(effects=[], free=[], values={}, std_errors={}, units={}),
        train={"rmse_bar": 0.02},
        test={"rmse_bar": 0.03},
    )
    result = DiscoveryResult(
        [], base, base, True, ["didt_mA_s"], "s", [], [], 1.0, settings={}, time_limited=False
    )
    doc = result.to_dict()
    assert doc["next_steps"] == result.next_steps() and "select-structure" in doc["next_steps"]
    assert doc["stop_note"] == ""


def test_an_added_effect_that_worsens_the_test_ramp_says_so():
    """Stand + sensor_lag, --candidates sensor_lag: 'added sensor_lag (ΔBIC -25.3): training
    RMSE 0.0294 → 0.0231 bar, test-ramp RMSE 0.0222 → 0.0247 bar' with a refit stopped at its
    iteration limit, and nothing said that the unseen ramp got worse."""
    it = _iteration("added", [_candidate("sensor_lag", True, 225.3, 0.31)], effect="sensor_lag")
    it.delta_bic = -25.3
    it.before, it.after = _state(0.0294, 0.0222), _state(0.0231, 0.0247)
    it.after.fit = SimpleNamespace(success=False)
    last = _iteration("no candidates left", [], index=1)
    text = _summary([it, last], False, _diag(()), 2)
    assert "test-ramp RMSE 0.0222 → 0.0247 bar (worse on the unseen test ramp by 11 %" in text
    assert "stopped at a limit" in text
    it.after = _state(0.0231, 0.0200)
    it.after.fit = SimpleNamespace(success=True)
    assert "worse" not in _summary([it, last], False, _diag(()), 2)
