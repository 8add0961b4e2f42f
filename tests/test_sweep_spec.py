"""Sweep specs: validation with every problem listed, grid / Latin-hypercube designs, point ids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clutchlab.errors import ModelError
from clutchlab.physics.design import SpecError, SweepSpec, design_points, load_spec, point_id

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "sweep_vfs_design.toml"


def _spec(**parts) -> SweepSpec:
    doc = {
        "scenario": {"ramps": ["fast"]},
        "sampling": {"method": "lhs", "n": 20, "seed": 3},
        "variables": [
            {"name": "vfs_d_orf", "low": 0.3, "high": 0.6},
            {"name": "vacc_V", "low": 1.0, "high": 4.0, "scale": "log"},
        ],
    }
    doc.update(parts)
    return SweepSpec.from_dict(doc)


def test_example_spec_loads_with_1000_lhs_points():
    spec = load_spec(EXAMPLE)
    assert spec.sampling.method == "lhs" and spec.sampling.n == 1000
    assert "dither_amp_scale" in spec.variable_names and "vfs_d_orf" in spec.variable_names
    points = design_points(spec)
    assert len(points) == 1000
    assert len({p.point_id for p in points}) == 1000
    assert [p.index for p in points] == list(range(1000))


def test_unknown_parameter_lists_known_ones_and_all_problems_at_once():
    doc = {
        "sampling": {"n": 10, "mehtod": "lhs"},
        "variables": [
            {"name": "vfs_d_orifice", "low": 0.3, "high": 0.6},
            {"name": "reg_k", "low": 0.5, "high": 20.0},
            {"name": "vfs_k", "low": 3.0, "high": 2.0},
        ],
        "scenario": {"ramps": ["fastest"]},
    }
    with pytest.raises(SpecError) as err:
        SweepSpec.from_dict(doc, "my.toml")
    msg = str(err.value)
    assert msg.startswith("my.toml: invalid sweep spec")
    assert "unknown parameter 'vfs_d_orifice'" in msg
    assert "vfs_d_orf" in msg and "dither_amp_scale" in msg  # the known names are listed
    assert "reg_k: 0.5 N/mm outside the bounds [1, 50] N/mm" in msg
    assert "low (3) must be below high (2)" in msg
    assert "unknown key 'mehtod'" in msg
    assert "unknown ramp 'fastest'" in msg
    assert len(err.value.problems) == 5
    assert isinstance(err.value, ModelError) and isinstance(err.value, ValueError)


@pytest.mark.parametrize(
    ("parts", "needle"),
    [
        ({"model": {"effects": ["sensor_lagg"]}}, "unknown effect 'sensor_lagg'"),
        ({"model": {"parameters": {"reg_F_c": 99.0}}}, "reg_F_c = 99.0 N outside bounds"),
        ({"sampling": {"method": "lhs"}}, "n must be a positive integer"),
        ({"simulation": {"substeps": 0}}, "substeps must be an integer in 1..64"),
        ({"scenario": {"dither": {"freq_Hz": 400.0}}}, "is not resolved at 1000 Hz"),
        ({"scenario": {"dither": {"shape": "Z"}}}, "unknown shape 'Z'"),
        ({"metrics": {"gain_mA": [700, 250]}}, "gain_mA must be [low, high]"),
        ({"scenario": {"step": {"from_mA": 500, "to_mA": 500}}}, "from_mA ≠ to_mA"),
        ({"colour": 1}, "unknown top-level key 'colour'"),
        # these four raised a ValueError / TypeError traceback instead of a SpecError
        ({"metrics": {"hysteresis_mA": ["a", "b"]}}, "hysteresis_mA must be [low, high]"),
        ({"metrics": {"ripple_mA": ["a", 1]}}, "ripple_mA must be [low, high]"),
        ({"scenario": {"dither": {"shape": ["A"]}}}, "unknown shape ['A']"),
        ({"scenario": {"ramps": [{"label": ["x"], "ramp_s": 1}]}}, "label must be a non-empty"),
        # these were accepted and gave NaN metrics or a physically impossible circuit
        ({"metrics": {"gain_mA": [250, float("inf")]}}, "0 ≤ low < high ≤ 1100 (mA)"),
        ({"metrics": {"hysteresis_mA": [1200, 1500]}}, "0 ≤ low < high ≤ 1100 (mA)"),
        ({"scenario": {"line_pressure_bar": -5.0}}, "line_pressure_bar -5 bar not in (0, 60]"),
        ({"scenario": {"prime_pressure_bar": 20.0}}, "below line_pressure_bar (17.7 bar)"),
        ({"scenario": {"oil_temp_C": -300.0}}, "oil_temp_C -300 °C not in -40–180 °C"),
        (
            {"variables": [{"name": "dither_amp_scale", "low": 0.5, "high": 1.5}]},
            "high 1.5 × shape B (peak 225 mA) exceeds the 225 mA dither range",
        ),
    ],
)
def test_invalid_entries_have_clear_messages(parts, needle):
    with pytest.raises(SpecError, match="invalid sweep spec") as err:
        _spec(**parts)
    assert needle in str(err.value)


def test_variable_fixed_and_swept_is_refused():
    with pytest.raises(SpecError, match="also fixed in"):
        _spec(model={"parameters": {"vfs_d_orf": 0.4}})


def test_load_spec_reports_bad_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[sampling\nn = 3\n")
    with pytest.raises(SpecError, match="not valid TOML"):
        load_spec(bad)
    with pytest.raises(SpecError, match="file not found"):
        load_spec(tmp_path / "none.toml")


def test_latin_hypercube_has_one_point_per_stratum_and_log_spacing():
    spec = _spec()
    pts = design_points(spec)
    x = np.array([p.values["vfs_d_orf"] for p in pts])
    strata = np.floor((x - 0.3) / 0.3 * 20).astype(int)
    assert sorted(strata) == list(range(20))
    v = np.array([p.values["vacc_V"] for p in pts])
    u = np.log(v / 1.0) / np.log(4.0)
    assert sorted(np.floor(u * 20).astype(int)) == list(range(20))
    again = design_points(_spec())
    assert [p.point_id for p in again] == [p.point_id for p in pts]
    other_seed = design_points(_spec(sampling={"method": "lhs", "n": 20, "seed": 4}))
    assert other_seed[0].values != pts[0].values


def test_grid_is_the_full_factorial_product():
    spec = _spec(
        sampling={"method": "grid"},
        variables=[
            {"name": "reg_k", "low": 10.0, "high": 20.0, "levels": 3},
            {"name": "vacc_V", "low": 1.0, "high": 4.0, "levels": 3, "scale": "log"},
            {"name": "dither_freq_Hz", "values": [30.0, 70.0]},
        ],
    )
    pts = design_points(spec)
    assert len(pts) == 18
    assert sorted({p.values["vacc_V"] for p in pts}) == pytest.approx([1.0, 2.0, 4.0])
    assert sorted({p.values["reg_k"] for p in pts}) == [10.0, 15.0, 20.0]
    assert pts[0].values == {"reg_k": 10.0, "vacc_V": 1.0, "dither_freq_Hz": 30.0}
    assert pts[1].values["dither_freq_Hz"] == 70.0  # last variable fastest


def test_point_id_depends_on_the_design_vector_and_the_spec_core_only():
    a = _spec()
    b = _spec(sampling={"method": "lhs", "n": 50, "seed": 9})  # sampling is not the core
    c = _spec(simulation={"substeps": 8})
    assert a.core_hash == b.core_hash != c.core_hash
    x = {"vfs_d_orf": 0.4, "vacc_V": 2.0}
    assert point_id(a.core_hash, x) == point_id(b.core_hash, dict(reversed(x.items())))
    assert point_id(a.core_hash, x) != point_id(c.core_hash, x)
    assert point_id(a.core_hash, x) != point_id(a.core_hash, x | {"vacc_V": 2.0000000001})


def test_cli_dry_run_and_spec_error(tmp_path, capsys):
    from clutchlab.cli import main

    assert main(["sweep", str(EXAMPLE), "--out", str(tmp_path / "r.parquet"), "--dry-run"]) == 0
    assert "vfs_design: 1000 points (lhs)" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text('[sampling]\nn = 3\n[[variables]]\nname = "vfs_dorf"\nlow = 0.3\nhigh = 0.5\n')
    assert main(["sweep", str(bad), "--out", str(tmp_path / "r.parquet")]) == 2
    err = capsys.readouterr().err
    assert "clutchlab sweep: error:" in err and "unknown parameter 'vfs_dorf'" in err
    assert "vfs_d_orf" in err
    assert not (tmp_path / "r.parquet.parts").exists()  # nothing written for a bad spec


def test_a_step_spec_built_in_code_is_checked_too():
    """load_spec checked the step; StepSpec(...) and ramp_trace(rate 0) failed deep inside."""
    from clutchlab.errors import ModelError
    from clutchlab.physics.design.scenario import ramp_trace
    from clutchlab.physics.design.spec import ScenarioSpec, SpecError, StepSpec

    for kw in ({"duration_s": -0.2}, {"from_mA": -300.0}, {"hold_s": float("nan")}):
        with pytest.raises(SpecError, match=r"\[scenario\.step\]"):
            StepSpec(**kw)
    scenario = ScenarioSpec()
    with pytest.raises(ModelError, match="sample_rate_Hz must be > 0"):
        ramp_trace(scenario.ramps[0], None, scenario, 0.0)


def test_load_spec_reports_a_folder_and_a_binary_file_without_a_traceback(tmp_path, capsys):
    """A folder or a non-UTF-8 file given as the spec raised IsADirectoryError /
    UnicodeDecodeError with a traceback."""
    folder = tmp_path / "spec.toml"
    folder.mkdir()
    with pytest.raises(SpecError, match="is a folder; give the spec file"):
        load_spec(folder)
    binary = tmp_path / "spec.xlsx"
    binary.write_bytes(b"PK\x03\x04\xff\xfe\x00")
    with pytest.raises(SpecError, match="not a text file in UTF-8"):
        load_spec(binary)
    from clutchlab.cli import main

    out = str(tmp_path / "r.parquet")
    assert main(["sweep", str(binary), "--out", out, "--dry-run"]) == 2
    assert "spec.xlsx: invalid sweep spec" in capsys.readouterr().err


def test_cli_dry_run_writes_its_count_to_json_and_scheduler_with_workers_exits_2(tmp_path, capsys):
    """``--dry-run --json X`` wrote nothing; ``--scheduler A --workers N`` exited 1 with a bare
    message, after the output checks."""
    import json

    from clutchlab.cli import main

    summary = tmp_path / "count.json"
    args = ["sweep", str(EXAMPLE), "--out", str(tmp_path / "r.parquet")]
    assert main([*args, "--dry-run", "--json", str(summary)]) == 0
    doc = json.loads(summary.read_text())
    assert doc["n_points"] == 1000 and doc["dry_run"] is True and "vfs_d_orf" in doc["variables"]
    with pytest.raises(SystemExit) as exc:
        main([*args, "--scheduler", "tcp://127.0.0.1:8786", "--workers", "2"])
    assert exc.value.code == 2
    assert "clutchlab sweep: error: --workers is for local runs" in capsys.readouterr().err


def test_load_spec_reads_a_file_saved_with_a_byte_order_mark(tmp_path):
    """Notepad's "UTF-8" (with BOM, CRLF) gave "not valid TOML: Invalid statement (at line 1,
    column 1)" for a spec that is valid."""
    spec = tmp_path / "notepad.toml"
    text = EXAMPLE.read_text(encoding="utf-8").replace("\n", "\r\n")
    spec.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    assert load_spec(spec).sampling.n == 1000


def test_run_sweep_checks_a_spec_changed_in_code_before_any_work(tmp_path):
    """The dataclasses check nothing: ``dataclasses.replace`` with a negative line pressure
    was simulated, and an unknown dither shape failed every point one by one."""
    import dataclasses

    from clutchlab.physics.design import run_sweep
    from clutchlab.physics.design.spec_parse import parse_spec, spec_to_doc

    spec = load_spec(EXAMPLE)
    assert parse_spec(spec_to_doc(spec), spec.source) == spec  # the round trip is exact
    bad = dataclasses.replace(
        spec,
        scenario=dataclasses.replace(spec.scenario, line_pressure_bar=-5.0, dither_shape="Z"),
    )
    with pytest.raises(SpecError) as err:
        run_sweep(bad, tmp_path / "r.parquet", workers=1, progress=False)
    assert "line_pressure_bar -5 bar not in (0, 60]" in str(err.value)
    assert "unknown shape 'Z'" in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_design_evaluator_and_evaluate_batch_check_a_spec_changed_in_code():
    """Called without run_sweep, the evaluator simulated a negative line pressure."""
    import dataclasses

    from clutchlab.physics.design import STATUS_FAILED, DesignEvaluator, evaluate_batch
    from clutchlab.physics.design.sampling import DesignPoint

    spec = load_spec(EXAMPLE)
    bad = dataclasses.replace(
        spec, scenario=dataclasses.replace(spec.scenario, line_pressure_bar=-5.0)
    )
    with pytest.raises(SpecError, match="line_pressure_bar -5 bar not in"):
        DesignEvaluator(bad)
    values = {v.name: v.values[0] if v.values else v.low for v in spec.variables}
    point = DesignPoint(index=0, point_id="p0", values=values)
    (row,) = evaluate_batch(bad, [point])
    assert row["status"] == STATUS_FAILED and "line_pressure_bar -5 bar not in" in row["error"]


def test_scenario_dither_frequency_is_not_checked_when_a_variable_sets_it():
    """With dither_freq_Hz a design variable, [scenario.dither] freq_Hz is used by no point,
    yet 400 Hz there was refused as "not resolved at 1000 Hz sampling"."""
    spec = _spec(
        scenario={"ramps": ["fast"], "dither": {"freq_Hz": 400.0}},
        variables=[{"name": "dither_freq_Hz", "low": 30.0, "high": 70.0}],
    )
    assert spec.variable_names == ("dither_freq_Hz",)
    with pytest.raises(SpecError, match="up to 300 Hz is not resolved"):
        _spec(variables=[{"name": "dither_freq_Hz", "low": 30.0, "high": 300.0}])


def test_a_parameter_of_an_effect_the_model_lacks_names_the_effect():
    """A design variable or fixed value of an effect not in ``[model] effects`` was refused
    as 'unknown parameter' with the list of ~60 base names, which does not hold it; the
    problem now names the effect to switch on."""
    with pytest.raises(SpecError) as err:
        _spec(
            model={"parameters": {"jet_kappa": 0.3}},
            variables=[{"name": "slag_tau", "low": 1.0, "high": 10.0}],
        )
    msg = str(err.value)
    assert "parameter 'slag_tau' belongs to the effect 'sensor_lag'" in msg
    assert "parameter 'jet_kappa' belongs to the effect 'flow_force'" in msg
    assert "add it to [model] effects" in msg
