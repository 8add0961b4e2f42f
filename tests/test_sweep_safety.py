"""Sweep safety (issue 18, items 1, 7 and the sweep part of 10): a user's file is never
replaced, sizes are bounded before any allocation, a run where every point fails exits
non-zero, two sweeps on one output are locked out, and a killed sweep leaves no process."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from clutchlab.errors import OutputError
from clutchlab.physics.design.runner import output_lock
from clutchlab.physics.design.spec import SpecError
from clutchlab.physics.design.spec_parse import parse_spec

EXAMPLE = Path(__file__).parents[1] / "examples" / "sweep_vfs_design.toml"


def sweep(*args, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", "sweep", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def tiny_spec(tmp_path, n=2, extra=""):
    text = re.sub(r"(?m)^n = \d+", f"n = {n}", EXAMPLE.read_text()) + extra
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path


def base_doc(**over):
    doc = {
        "name": "x",
        "variables": [{"name": "reg_F_c", "low": 0.5, "high": 1.5}],
        "sampling": {"method": "lhs", "n": 2},
    }
    return doc | over


def test_existing_user_file_is_never_replaced(tmp_path):
    customers = tmp_path / "customers.csv"
    customers.write_text("name,email\n")
    res = sweep(tiny_spec(tmp_path), "--out", customers, "--quiet")
    assert res.returncode == 2 and "*.parquet" in res.stderr
    theirs = tmp_path / "theirs.parquet"
    theirs.write_bytes(b"PAR1 user data")
    res = sweep(tiny_spec(tmp_path), "--out", theirs, "--quiet")
    assert res.returncode == 2 and "exists (pass --overwrite" in res.stderr
    assert customers.read_text() == "name,email\n"
    assert theirs.read_bytes() == b"PAR1 user data"


def test_out_is_checked_before_the_sweep(tmp_path):
    folder = tmp_path / "results.parquet"
    folder.mkdir()
    t0 = time.perf_counter()
    res = sweep(tiny_spec(tmp_path, n=50), "--out", folder, "--quiet")
    assert res.returncode == 2 and "is a folder" in res.stderr
    res = sweep(tiny_spec(tmp_path), "--out", "/proc/clutchlab-no-dir/r.parquet", "--quiet")
    assert res.returncode == 2 and "cannot write into" in res.stderr
    assert time.perf_counter() - t0 < 60
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize(
    ("doc", "needle"),
    [
        (base_doc(sampling={"method": "lhs", "n": 10**9}), "1000000000 design points"),
        (
            base_doc(
                sampling={"method": "grid"},
                variables=[
                    {"name": n, "low": 0.5, "high": 1.5, "levels": 1000}
                    for n in ("reg_F_c", "vfs_F_pre", "cacc_k", "reg_F0", "vfs_K_m", "latch_F0")
                ],
            ),
            "design points, more than the limit",
        ),
        (
            base_doc(scenario={"ramps": [{"label": "x", "ramp_s": 1e7}]}),
            "s simulated per design point",
        ),
    ],
    ids=["lhs_1e9", "grid_1000^6", "ramp_1e7_s"],
)
def test_sizes_are_bounded_before_any_allocation(doc, needle):
    t0 = time.perf_counter()
    with pytest.raises(SpecError) as exc:
        parse_spec(doc)
    assert time.perf_counter() - t0 < 5
    assert needle in str(exc.value) and "CLUTCHLAB_SWEEP_MAX" in str(exc.value)


def test_a_second_sweep_on_the_same_out_is_locked_out(tmp_path):
    out = tmp_path / "r.parquet"
    with output_lock(out):
        res = sweep(tiny_spec(tmp_path), "--out", out, "--quiet")
    assert res.returncode == 2
    assert f"another sweep (PID {os.getpid()})" in res.stderr
    with pytest.raises(OutputError), output_lock(out), output_lock(out):
        pass


def test_a_sweep_where_every_point_fails_exits_non_zero(tmp_path, monkeypatch, capsys):
    from clutchlab.cli import main
    from clutchlab.physics.design.evaluate import DesignEvaluator

    def out_of_memory(self, values):
        raise MemoryError("cannot allocate 44.7 GiB")

    monkeypatch.setattr(DesignEvaluator, "_metrics", out_of_memory)
    out = tmp_path / "r.parquet"
    code = main(["sweep", str(tiny_spec(tmp_path)), "--out", str(out), "--quiet", "--workers", "1"])
    assert code == 1
    assert "every point failed (2)" in capsys.readouterr().err


def test_a_killed_sweep_leaves_no_process(tmp_path):
    spec = tiny_spec(tmp_path, n=400)
    out = tmp_path / "r.parquet"
    proc = subprocess.Popen(
        [sys.executable, "-m", "clutchlab.cli", "sweep", spec, "--out", out, "--workers", "2",
         "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    parts = out.with_name(out.name + ".parts")
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(parts.glob("part-*.parquet")):
        time.sleep(0.2)
    assert proc.poll() is None, "the sweep ended before it could be killed"
    descendants = psutil.Process(proc.pid).children(recursive=True)
    assert len(descendants) >= 2  # fork server and workers
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    _, alive = psutil.wait_procs(descendants, timeout=10)
    assert not alive, [p.cmdline() for p in alive]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--workers", "0"], "argument --workers: must be ≥ 1"),
        (["--workers", "-1"], "argument --workers: must be ≥ 1"),
        (["--flush-s", "-1"], "argument --flush-s: must be ≥ 0 s"),
        (["--flush-s", "nan"], "argument --flush-s: must be ≥ 0 s"),
    ],
    ids=["workers_0", "workers_-1", "flush_-1", "flush_nan"],
)
def test_out_of_range_workers_and_flush_are_refused_before_any_work(tmp_path, args, needle):
    """Issue 17: ``--workers 0 / -1`` and ``--flush-s -1`` were silently accepted."""
    out = tmp_path / "r.parquet"
    res = sweep(tiny_spec(tmp_path), "--out", out, "--quiet", *args, timeout=60)
    assert res.returncode == 2 and needle in res.stderr, res.stderr
    assert "Traceback" not in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.toml"]  # nothing created


def test_run_sweep_refuses_out_of_range_settings_before_any_work(tmp_path):
    from clutchlab.physics.design import load_spec, run_sweep

    spec = load_spec(tiny_spec(tmp_path))
    out = tmp_path / "r.parquet"
    with pytest.raises(ValueError, match=r"workers must be an integer ≥ 1, not 0.*flush_s"):
        run_sweep(spec, out, workers=0, flush_s=-1.0, progress=False)
    with pytest.raises(ValueError, match="batch_size must be an integer ≥ 1"):
        run_sweep(spec, out, workers=1, batch_size=0, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.toml"]
