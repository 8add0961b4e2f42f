"""Running sweeps: results and figures, restart after a kill, failed points, Dask = local."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from clutchlab.physics.design import (
    SweepSpec,
    design_points,
    evaluate_batch,
    read_results,
    run_sweep,
)

#: A short ramp (0.6 s ramps, 0.2 s holds) and a short step keep a point at ~0.1 s.
SHORT = {
    "scenario": {
        "ramps": [{"label": "short", "ramp_s": 0.6, "hold_s": 0.2}],
        "step": {"from_mA": 300.0, "to_mA": 700.0, "hold_s": 0.1, "duration_s": 0.25},
    },
    "simulation": {"settle_s": 0.2},
    "metrics": {"hysteresis_mA": [400.0, 700.0]},  # this fast a ramp latches from ~650 mA
}


def _spec(n=4, seed=0, **extra) -> SweepSpec:
    doc = dict(SHORT) | {
        "name": "short",
        "sampling": {"method": "lhs", "n": n, "seed": seed},
        "variables": [
            {"name": "vfs_d_orf", "low": 0.35, "high": 0.6},
            {"name": "dither_amp_scale", "low": 0.4, "high": 1.0},
            {"name": "dither_freq_Hz", "low": 40.0, "high": 70.0},
        ],
    }
    return SweepSpec.from_dict(doc | extra)


def _write_toml(path: Path, n: int, name: str = "kill") -> Path:
    """A spec whose point takes ~0.05 s (0.6 s ramp, no step), ``n`` LHS points."""
    path.write_text(
        f"""name = "{name}"
[scenario]
ramps = [{{label = "short", ramp_s = 0.6, hold_s = 0.2}}]
step = false
[simulation]
settle_s = 0.2
[sampling]
method = "lhs"
n = {n}
seed = 5
[[variables]]
name = "vfs_d_orf"
low = 0.35
high = 0.6
[[variables]]
name = "reg_k"
low = 10.0
high = 20.0
""",
        encoding="utf-8",
    )
    return path


def _numbers(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=["wall_s", "cpu_s"]).reset_index(drop=True)


def test_local_sweep_writes_results_figures_and_skips_finished_points(tmp_path):
    spec = _spec(n=4)
    out = tmp_path / "res.parquet"
    res = run_sweep(spec, out, workers=1, progress=False, flush_s=0.0)
    assert (res.n_points, res.n_run, res.n_failed) == (4, 4, 0)
    df = read_results(out)
    assert list(df["index"]) == [0, 1, 2, 3]
    assert set(df["status"]) == {"ok"}
    for name in res.metric_names:  # the short ramp latches during the peak hold, not on it
        assert np.isfinite(df[name]).all() or name == "latch_on_mA", name
    for f in res.figures:
        assert f.stat().st_size > 0
    assert {f.name for f in res.figures} == {
        "tornado.png",
        "metrics_vs_variables.png",
        "sensitivity.csv",
        "sweep.html",
    }
    # written atomically as one folder with clutchlab's ownership record; no temporary left
    names = {f.name for f in res.figures} | {".clutchlab-owned.json"}
    assert {f.name for f in res.figures[0].parent.iterdir()} == names
    assert {f.name for f in tmp_path.iterdir()} == {
        "res.parquet",
        "res.parquet.parts",
        "res.parquet.figures",
    }
    assert all(f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for f in res.figures[:2])
    # The same numbers as evaluating the points directly.
    direct = pd.DataFrame(evaluate_batch(spec, design_points(spec)))[df.columns]
    pd.testing.assert_frame_equal(_numbers(df), _numbers(direct))
    # A second run finds everything done; a bigger design of the same core reuses points.
    again = run_sweep(spec, out, workers=1, progress=False, figures=False)
    assert again.n_run == 0 and again.n_skipped == 4
    pd.testing.assert_frame_equal(_numbers(again.table), _numbers(df))
    # Another model core in the same place is refused, not mixed in.
    other = _spec(n=4, simulation={"settle_s": 0.3})
    with pytest.raises(ValueError, match="holds results of another spec") as err:
        run_sweep(other, out, workers=1, progress=False)
    assert "invalid sweep spec" not in str(err.value)  # the spec is valid; --out is taken


def test_dask_local_cluster_gives_the_same_numbers_as_the_local_run(tmp_path):
    from distributed import Client, LocalCluster

    spec = _spec(n=6, seed=2)
    local = run_sweep(spec, tmp_path / "local.parquet", workers=1, progress=False, figures=False)
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        dask = run_sweep(
            spec, tmp_path / "dask.parquet", scheduler=client, progress=False, figures=False
        )
        workers_used = set(client.run(os.getpid).values())
    assert dask.backend == "dask" and dask.workers == 2 and len(workers_used) == 2
    assert dask.n_run == 6 and dask.n_failed == 0
    assert os.getpid() not in workers_used
    pd.testing.assert_frame_equal(_numbers(dask.table), _numbers(local.table), check_exact=True)


def _parts_rows(out: Path) -> int:
    parts = out.with_name(out.name + ".parts")
    return sum(pq.read_metadata(f).num_rows for f in parts.glob("part-*.parquet"))


def _kill_midway_then_restart(tmp_path: Path, workers: int, n: int) -> None:
    spec_path = _write_toml(tmp_path / "kill.toml", n)
    out = tmp_path / "kill.parquet"
    cmd = [sys.executable, "-m", "clutchlab.cli", "sweep", str(spec_path), "--out", str(out)]
    cmd += ["--workers", str(workers), "--flush-s", "0", "--quiet", "--no-figures"]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True
    )
    parts = out.with_name(out.name + ".parts")
    deadline = time.monotonic() + 300
    try:
        while len(list(parts.glob("part-*.parquet"))) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no results within 300 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its worker processes
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists()  # killed before it could consolidate
    done_before = _parts_rows(out)
    assert 0 < done_before < n
    res = subprocess.run(
        [*cmd, "--json", str(tmp_path / "summary.json")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["n_skipped"] == done_before and summary["n_run"] == n - done_before
    df = pd.read_parquet(out)
    from clutchlab.physics.design import load_spec

    ids = [p.point_id for p in design_points(load_spec(spec_path))]
    assert list(df["point_id"]) == ids  # every point exactly once, design order
    assert set(df["status"]) == {"ok"}
    assert _parts_rows(out) == n  # nothing evaluated twice on disk


def test_sweep_killed_midway_and_restarted_has_every_point_once(tmp_path):
    _kill_midway_then_restart(tmp_path, workers=1, n=40)


@pytest.mark.slow
def test_sweep_with_worker_processes_killed_and_restarted(tmp_path):
    _kill_midway_then_restart(tmp_path, workers=2, n=60)


def test_read_results_of_an_extended_sweep_killed_before_consolidating_reads_its_parts(
    tmp_path, monkeypatch
):
    """A complete sweep, then a bigger design of the same spec on the same --out stopped
    before it consolidated: the consolidated file is the old run's, so read_results reads the
    parts (with a warning) rather than the stale table."""
    import warnings

    from clutchlab.physics.design import ResultStore, UnfinishedSweepWarning
    from clutchlab.physics.design.runner import SweepInterrupted

    out = tmp_path / "res.parquet"
    small, big = _spec(n=2, seed=3), _spec(n=4, seed=3)
    run_sweep(small, out, workers=1, progress=False, figures=False, flush_s=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a finished sweep reads without a warning
        assert len(read_results(out)) == 2

    def killed(self, point_ids):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(ResultStore, "consolidate", killed)
        with pytest.raises(SweepInterrupted):
            run_sweep(big, out, workers=1, progress=False, figures=False, flush_s=0.0)
    with pytest.warns(UnfinishedSweepWarning, match=r"older than \d+ part files? of an unfinished"):
        df = read_results(out)
    big_ids = {p.point_id for p in design_points(big)}
    assert big_ids <= set(df["point_id"])  # the new points are there, not only the old two
    assert df["point_id"].is_unique
    # Running it again finishes and consolidates: the file is current again.
    run_sweep(big, out, workers=1, progress=False, figures=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        df = read_results(out)
    assert set(df["point_id"]) == big_ids


def _part_name(ns: int, seq: int = 1) -> str:
    return f"part-{ns:020d}-4242-{seq:06d}.parquet"


def test_read_results_compares_parts_with_a_consolidated_file_of_an_earlier_version(tmp_path):
    """A consolidated file without the record of its newest part (written before it existed):
    a part counts as newer if its name's time is clearly after the file's mtime."""
    import warnings

    from clutchlab.physics.design import UnfinishedSweepWarning

    out = tmp_path / "old.parquet"
    parts = out.with_name(out.name + ".parts")
    parts.mkdir()
    row = {"point_id": "a", "index": 0, "status": "ok", "error": "", "x": 1.0}
    pd.DataFrame([row]).to_parquet(parts / _part_name(1_000_000_000_000_000_000))
    pd.DataFrame([row]).to_parquet(out, index=False)
    t_file = 1_000_000_000_500_000_000  # the consolidated file: 0.5 s after the part
    os.utime(out, ns=(t_file, t_file))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert list(read_results(out)["x"]) == [1.0]
    # A later run's parts: point a again (newer row) and a new point b, minutes later.
    later = t_file + 60_000_000_000
    pd.DataFrame([row | {"x": 2.0}]).to_parquet(parts / _part_name(later, 1))
    pd.DataFrame([row | {"point_id": "b", "index": 1, "x": 3.0}]).to_parquet(
        parts / _part_name(later, 2)
    )
    with pytest.warns(UnfinishedSweepWarning, match="older than 2 part files"):
        df = read_results(out)
    assert list(df["point_id"]) == ["a", "b"] and list(df["x"]) == [2.0, 3.0]


def test_read_results_of_a_first_run_stopped_before_consolidating_warns(tmp_path):
    """No consolidated file, only parts: the rows are those of an unfinished run, which a
    user was not told (the warning came only when an older consolidated file lay beside)."""
    from clutchlab.physics.design import UnfinishedSweepWarning

    out = tmp_path / "first.parquet"
    parts = out.with_name(out.name + ".parts")
    parts.mkdir()
    row = {"point_id": "a", "index": 0, "status": "ok", "error": "", "x": 1.0}
    pd.DataFrame([row]).to_parquet(parts / _part_name(1_000_000_000_000_000_000))
    with pytest.warns(UnfinishedSweepWarning, match=r"does not exist: the sweep was stopped"):
        df = read_results(out)
    assert list(df["x"]) == [1.0]


def test_read_results_of_a_folder_or_a_non_parquet_file_names_it(tmp_path):
    """The parts folder or another file passed by mistake: one error naming it and what to
    pass, not pyarrow's 'Parquet magic bytes not found' about a file inside the folder."""
    from clutchlab.errors import DataError

    out = tmp_path / "res.parquet"
    parts = out.with_name(out.name + ".parts")
    parts.mkdir()
    (parts / "spec.json").write_text("{}")
    with pytest.raises(
        DataError, match=r"res\.parquet\.parts: is a folder.*--out file .*res\.parquet\)"
    ):
        read_results(parts)
    spec = tmp_path / "spec.toml"
    spec.write_text('name = "x"\n')
    with pytest.raises(DataError, match=r"spec\.toml: not a sweep's results file"):
        read_results(spec)


def test_one_level_variable_gives_an_undefined_sensitivity_without_numpy_warnings(tmp_path):
    """Issue 17: ``values = [12.0]`` printed 6 RuntimeWarnings and wrote n = 0 for 1 ok point."""
    import warnings

    doc = dict(SHORT) | {
        "name": "one_level",
        "sampling": {"method": "grid"},
        "variables": [{"name": "reg_k", "values": [12.0]}],
    }
    spec = SweepSpec.from_dict(doc)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = run_sweep(spec, tmp_path / "one.parquet", workers=1, progress=False)
    assert res.n_failed == 0 and len(res.table) == 1
    sens = pd.read_csv(tmp_path / "one.parquet.figures" / "sensitivity.csv")
    gain = sens[sens["metric"] == "regulated_gain_bar_per_A"].iloc[0]
    assert gain["n"] == 1  # the one ok point, not 0
    assert np.isnan(gain["effect"]) and "one level (12): no range" in gain["note"]
    # Next to a variable with a range, the one-level one is left out of the fit.
    two = SweepSpec.from_dict(
        doc | {"variables": [*doc["variables"], {"name": "vfs_d_orf", "values": [0.35, 0.45, 0.6]}]}
    )
    from clutchlab.physics.design import sensitivity_table

    table = pd.DataFrame(evaluate_batch(two, design_points(two)))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        s = sensitivity_table(table, two, ("regulated_gain_bar_per_A",)).set_index("variable")
    assert np.isnan(s.loc["reg_k", "effect"]) and s.loc["reg_k", "note"].startswith("one level")
    assert np.isfinite(s.loc["vfs_d_orf", "effect"]) and s.loc["vfs_d_orf", "note"] == ""
    assert (s["n"] == 3).all()
