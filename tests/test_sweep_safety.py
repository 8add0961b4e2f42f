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
from test_sweep_run import _write_toml

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


def short_spec(tmp_path, n=4):
    """A spec whose point takes ~0.05 s (0.6 s ramp, no step)."""
    return _write_toml(tmp_path / "short.toml", n, name="short")


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


def test_user_files_beside_the_results_are_never_replaced_or_deleted(tmp_path):
    """Issue 4: a user's ``tornado.png`` in ``X.parquet.figures/`` was overwritten, and
    ``--overwrite`` deleted ``data.csv`` in ``X.parquet.parts/`` (and ``mine.txt`` in a
    sweep's own parts folder)."""
    spec = short_spec(tmp_path)
    out = tmp_path / "mine.parquet"
    parts, figs = tmp_path / "mine.parquet.parts", tmp_path / "mine.parquet.figures"
    parts.mkdir()
    figs.mkdir()
    (parts / "data.csv").write_text("precious")
    (figs / "tornado.png").write_text("precious")
    for extra in ([], ["--overwrite"]):
        res = sweep(spec, "--out", out, "--quiet", "--workers", "1", *extra, timeout=120)
        assert res.returncode == 2, res.stderr
        assert f"{parts} exists and clutchlab did not create it" in res.stderr
        assert "data.csv" in res.stderr and "Traceback" not in res.stderr
    (parts / "data.csv").unlink()  # an empty folder is fine; the figures folder is not
    res = sweep(spec, "--out", out, "--quiet", "--workers", "1", "--overwrite", timeout=120)
    assert res.returncode == 2 and "its tornado.png would be replaced" in res.stderr
    assert (figs / "tornado.png").read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "mine.parquet.figures",
        "mine.parquet.parts",
        "short.toml",
    ]  # refused before any work: no lock, no results
    assert not any(parts.iterdir())
    (figs / "tornado.png").rename(tmp_path / "tornado.png")

    # In clutchlab's own folders a user's other files are kept, also by --overwrite.
    res = sweep(spec, "--out", out, "--quiet", "--workers", "1", timeout=120)
    assert res.returncode == 0, res.stderr
    (parts / "mine.txt").write_text("precious")
    (figs / "notes.txt").write_text("precious")
    res = sweep(spec, "--out", out, "--quiet", "--workers", "1", "--overwrite", timeout=120)
    assert res.returncode == 0, res.stderr
    assert (parts / "mine.txt").read_text() == "precious"
    assert (figs / "notes.txt").read_text() == "precious"
    assert (figs / "tornado.png").read_bytes()[:4] == b"\x89PNG"

    # A user's file where the lock goes is refused, not truncated and deleted.
    lock = tmp_path / "mine.parquet.lock"
    lock.write_text("my notes about this sweep")
    res = sweep(spec, "--out", out, "--quiet", "--workers", "1", "--overwrite", timeout=120)
    assert res.returncode == 2 and "is not a clutchlab lock file" in res.stderr
    assert lock.read_text() == "my notes about this sweep"


@pytest.mark.parametrize(
    ("address", "needle"),
    [
        ("bogus", "--scheduler 'bogus': not a scheduler address (missing port number"),
        ("tcp://127.0.0.1:1", "--scheduler tcp://127.0.0.1:1: cannot connect to a Dask scheduler"),
    ],
    ids=["no_port", "nobody_listening"],
)
def test_bad_scheduler_is_one_line_error_and_leaves_nothing(tmp_path, address, needle):
    """Issue 12: a raw ValueError / OSError traceback (after 30 s), and a lock and
    ``X.parquet.parts/spec.json`` left behind."""
    out = tmp_path / "x.parquet"
    env = os.environ | {"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"}
    res = subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", "sweep", str(short_spec(tmp_path)), "--out",
         str(out), "--scheduler", address, "--quiet"],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith("clutchlab sweep: error: " + needle), res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]


def test_ctrl_c_keeps_finished_points_with_a_message_and_no_lock(tmp_path):
    """Issue 15: Ctrl-C gave a KeyboardInterrupt traceback, was slow to exit, left a lock."""
    spec = short_spec(tmp_path, n=200)
    out = tmp_path / "r.parquet"
    cmd = [sys.executable, "-m", "clutchlab.cli", "sweep", str(spec), "--out", str(out)]
    cmd += ["--workers", "2", "--flush-s", "0", "--quiet", "--no-figures"]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        # Ctrl-C as in a terminal, even when the test runner was started with SIGINT
        # ignored (``nohup``, a background job), which its children would inherit
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    parts = out.with_name(out.name + ".parts")
    deadline = time.monotonic() + 120
    try:
        while len(list(parts.glob("part-*.parquet"))) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no results within 120 s"
            time.sleep(0.05)
        workers = psutil.Process(proc.pid).children(recursive=True)
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        _, err = proc.communicate(timeout=60)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    m = re.fullmatch(
        rf"clutchlab sweep: interrupted; (\d+) of 200 points kept in {re.escape(str(parts))}; "
        r"run the same command to continue\n",
        err,
    )
    assert m, err
    assert took < 5, f"{took:.1f} s to stop"
    assert not out.with_name(out.name + ".lock").exists()
    _, alive = psutil.wait_procs(workers, timeout=5)
    assert not alive
    kept = int(m.group(1))
    assert 0 < kept < 200
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert f"{200 - kept} run, {kept} already done" in res.stdout


def test_a_stale_lock_of_a_killed_sweep_is_taken_over_with_a_note(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "r.parquet"
    lock = tmp_path / "r.parquet.lock"
    lock.write_text(str(dead.pid))  # what a SIGKILLed sweep leaves
    res = sweep(short_spec(tmp_path), "--out", out, "--quiet", "--workers", "1", "--no-figures")
    assert res.returncode == 0, res.stderr
    assert f"note: {lock} was left by sweep PID {dead.pid}" in res.stderr
    assert "taken over" in res.stderr and "Traceback" not in res.stderr
    assert not lock.exists()


def test_out_in_a_folder_that_does_not_exist_yet_is_created(tmp_path):
    """``--out new/r.parquet`` passed the checks, then crashed creating ``new/r.parquet.lock``."""
    from test_sweep_run import _spec

    from clutchlab.physics.design import run_sweep

    out = tmp_path / "new" / "deeper" / "r.parquet"
    res = run_sweep(_spec(n=2), out, workers=1, progress=False, figures=False)
    assert res.n_run == 2 and res.n_failed == 0 and out.is_file()
    assert {f.name for f in out.parent.iterdir()} == {"r.parquet", "r.parquet.parts"}


@pytest.mark.parametrize(
    "json_name", ["r.parquet", "r.parquet.figures/tornado.png", "r.parquet.parts/x.json"]
)
def test_sweep_json_may_not_be_one_of_its_outputs(tmp_path, capsys, json_name):
    """``--json r.parquet`` replaced the consolidated results with the summary."""
    from clutchlab.cli import main

    spec = short_spec(tmp_path, n=2)
    args = ["sweep", str(spec), "--out", str(tmp_path / "r.parquet"), "--workers", "1"]
    assert main([*args, "--quiet", "--json", str(tmp_path / json_name)]) == 2
    assert "this command writes (--out); write the summary elsewhere" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["short.toml"]  # refused before any work


def test_overwrite_without_figures_removes_the_discarded_results_figures(tmp_path):
    """``--overwrite --no-figures`` replaced the results but left the old study's figures
    beside them, as if they showed the new results; a user's file there stays."""
    from test_sweep_run import _spec

    from clutchlab.physics.design import run_sweep
    from clutchlab.physics.design.figures import FIGURE_FILES

    out = tmp_path / "r.parquet"
    figures = tmp_path / "r.parquet.figures"
    run_sweep(_spec(n=2), out, workers=1, progress=False)
    assert (figures / "tornado.png").is_file()
    run_sweep(_spec(n=2, seed=9), out, workers=1, progress=False, figures=False, overwrite=True)
    assert not figures.exists()
    run_sweep(_spec(n=2), out, workers=1, progress=False, overwrite=True)
    (figures / "notes.txt").write_text("mine")
    run_sweep(_spec(n=2), out, workers=1, progress=False, figures=False, overwrite=True)
    assert sorted(p.name for p in figures.iterdir()) == [".clutchlab-owned.json", "notes.txt"]
    res = run_sweep(_spec(n=2), out, workers=1, progress=False, overwrite=True)
    assert sorted(p.name for p in res.figures) == sorted(FIGURE_FILES)  # drawn beside notes.txt
    assert (figures / "notes.txt").read_text() == "mine"


def test_run_sweep_takes_a_spec_file_and_refuses_anything_else(tmp_path):
    """``run_sweep("spec.toml", out)`` died with AttributeError: 'str' object has no
    attribute 'variable_names'."""
    from clutchlab.physics.design import run_sweep

    spec = short_spec(tmp_path, n=2)
    res = run_sweep(str(spec), tmp_path / "r.parquet", workers=1, progress=False, figures=False)
    assert res.n_run == 2 and res.spec.name == "short"
    with pytest.raises(TypeError, match="spec must be a SweepSpec or a spec file"):
        run_sweep({"name": "x"}, tmp_path / "s.parquet", workers=1)
    assert not (tmp_path / "s.parquet.parts").exists()


def test_new_points_that_succeed_do_not_exit_1_for_an_earlier_runs_failures(
    tmp_path, monkeypatch, capsys
):
    """The exit status compared all failed points (earlier calls' too) with the points of
    this call: 3 old failures + 1 new point that ran fine printed "every point failed (3)"
    and exited 1."""
    from clutchlab.cli import main
    from clutchlab.physics.design.evaluate import DesignEvaluator

    def grid(values):
        spec = _write_toml(tmp_path / "grid.toml", 2, name="grid")
        text = spec.read_text().replace('method = "lhs"\nn = 2\nseed = 5', 'method = "grid"')
        text = text.split("[[variables]]")[0] + (
            f'[[variables]]\nname = "reg_k"\nvalues = {values}\n'
        )
        spec.write_text(text)
        return str(spec)

    args = ["--out", str(tmp_path / "r.parquet"), "--quiet", "--workers", "1", "--no-figures"]
    with monkeypatch.context() as m:
        m.setattr(DesignEvaluator, "_metrics", lambda self, values: 1 / 0)
        assert main(["sweep", grid([10.0, 12.0, 14.0]), *args]) == 1
    assert "every point failed (3)" in capsys.readouterr().err
    assert main(["sweep", grid([10.0, 12.0, 14.0, 16.0]), *args]) == 0
    out = capsys.readouterr()
    assert "1 run, 3 already done; 3 failed" in out.out and "every point failed" not in out.err
    assert "on 1 local worker (" in out.out  # it said "1 local workers"


def test_workers_reported_are_the_workers_run(tmp_path, monkeypatch):
    """``--workers 8`` on a 2-point sweep reported "on 8 local workers"; the default counted
    every CPU of the machine, not those this process may use."""
    from test_sweep_run import _spec

    from clutchlab.physics.design import run_sweep, runner

    res = run_sweep(_spec(n=2), tmp_path / "a.parquet", workers=8, progress=False, figures=False)
    assert res.workers == 2 and res.summary()["workers"] == 2
    monkeypatch.setattr(runner.os, "sched_getaffinity", lambda pid: {0}, raising=False)
    monkeypatch.setattr(runner.os, "cpu_count", lambda: 64)
    res = run_sweep(_spec(n=2), tmp_path / "b.parquet", progress=False, figures=False)
    assert res.workers == 1
