"""Every example script in ``examples/`` runs on a small stand dataset (issue 19, must-show 4).

Each script is executed as a user would, ``python examples/NAME.py ...`` in a subprocess, and
its printed result is checked. Together they must stay under 60 s: that budget is checked by
``benchmarks/bench_examples.py`` (which runs this module and reads the wall time of each
script from ``CLUTCHLAB_EXAMPLE_TIMES``), not by a timed test, whose result would depend on
what else the test workers run at the same time.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from clutchlab.data import save_dataset
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

EXAMPLES = Path(__file__).parents[1] / "examples"
TIMES: dict[str, float] = {}

RENAME = {
    "time_s": "Time",
    "current_mA": "I_VFS",
    "current_cmd_mA": "I_cmd",
    "clutch_pressure_bar": "P_clutch",
    "line_pressure_bar": "P_line",
    "prime_pressure_bar": "P_prime",
    "oil_temp_C": "T_oil",
    "dither_amp_mA": "Dither_amp",
    "dither_freq_Hz": "Dither_freq",
}


def run_example(name: str, *args, timeout: float = 120) -> str:
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    TIMES[name] = time.perf_counter() - t0
    assert res.returncode == 0, res.stderr[-3000:]
    return res.stdout


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Two dither settings × three short ramps: enough to train, score and fit quickly."""
    run = run_stand(
        StandConfig(
            settings=(DitherSetting(30.0, "A"), DitherSetting(70.0, "C")),
            ramps=(
                RampProfile("fast", 0.8, 0.3),
                RampProfile("medium", 1.6, 0.3),
                RampProfile("slow", 3.2, 0.3),
            ),
        ),
        progress=False,
    )
    return save_dataset(run.dataset, tmp_path_factory.mktemp("examples") / "stand")


@pytest.fixture(scope="module")
def exported(small, tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu")
    stdout = run_example("fit_and_export_fmu.py", small, "--out", out, "--max-iter", "3")
    return out, stdout


def test_evaluate_logs_with_channel_map(small, tmp_path):
    from clutchlab.data import load_dataset

    logs = tmp_path / "logs"
    logs.mkdir()
    entries = []
    for trace in load_dataset(small):
        df = trace.to_pandas().rename(columns=RENAME)
        df["Time"] *= 1000.0  # ms
        df["I_VFS"] /= 1000.0  # A
        df["P_clutch"] *= 100.0  # kPa
        df.attrs = {}
        df.to_parquet(logs / f"{trace.name}.parquet")
        entries.append({"file": f"{trace.name}.parquet", **trace.meta})
    (logs / "manifest.json").write_text(json.dumps({"experiments": entries}))
    cmap = tmp_path / "stand_b.toml"
    lines = [f'{k} = "{v}"' for k, v in RENAME.items() if k not in ("time_s", "current_mA")]
    cmap.write_text(
        "[signals]\n"
        'time_s = { channel = "Time", unit = "ms" }\n'
        'current_mA = { channel = "I_VFS", unit = "A" }\n'
        + "\n".join(lines).replace('"P_clutch"', '{ channel = "P_clutch", unit = "kPa" }')
        + "\n"
    )
    out = run_example(
        "evaluate_logs_with_channel_map.py",
        logs,
        cmap,
        "--out",
        tmp_path / "report",
        "--variants",
        "physics_default,gp_base",
    )
    rows = dict(re.findall(r"^(physics_default|gp_base)\s+([\d.]+)", out, flags=re.M))
    assert set(rows) == {"physics_default", "gp_base"}
    assert all(0 < float(v) < 5 for v in rows.values())
    assert (tmp_path / "report" / "report.html").is_file()


def test_fit_and_export_fmu(exported):
    out, stdout = exported
    assert (out / "model.json").is_file() and (out / "clutch.fmu").is_file()
    diff = float(re.search(r"max \|difference\| ([\d.e+-]+) bar", stdout).group(1))
    assert diff < 1e-6


def test_residual_on_vendor_fmu(small, exported):
    out, _ = exported
    stdout = run_example("residual_on_vendor_fmu.py", small, out / "clutch.fmu")
    rows = re.findall(r"^medium_\S+\s+([\d.]+)\s+([\d.]+)$", stdout, flags=re.M)
    assert len(rows) == 2
    alone, hybrid = zip(*((float(a), float(b)) for a, b in rows), strict=True)
    # Never worse than its parts: the form is chosen on the training experiments only.
    assert sum(hybrid) <= 1.02 * sum(alone)
    assert re.search(r"^hybrid form: (residual|standalone|physics) \(", stdout, flags=re.M)


def test_design_sweep(tmp_path):
    spec = (EXAMPLES / "sweep_vfs_design.toml").read_text()
    spec = re.sub(r"(?m)^n = \d+", "n = 3", spec)
    assert "n = 3" in spec
    (tmp_path / "tiny.toml").write_text(spec)
    stdout = run_example(
        "design_sweep.py", tmp_path / "tiny.toml", "--out", tmp_path / "r.parquet", timeout=300
    )
    assert "'n_ok': 3" in stdout
    assert (tmp_path / "r.parquet").is_file()
    # The designs with the smallest hysteresis *width* first: the widths are negative (the
    # rising branch lags), and sorting them by value put the widest first.
    lines = stdout.splitlines()
    header = next(k for k, line in enumerate(lines) if "hysteresis_fast_bar" in line.split())
    column = lines[header].split().index("hysteresis_fast_bar")
    widths = [abs(float(line.split()[column])) for line in lines[header + 1 :] if line.strip()]
    assert len(widths) == 3 and widths == sorted(widths), widths


@pytest.fixture(scope="module", autouse=True)
def _report_times():
    """Write each script's wall time (s) to ``$CLUTCHLAB_EXAMPLE_TIMES`` (the benchmark's)."""
    yield
    target = os.environ.get("CLUTCHLAB_EXAMPLE_TIMES")
    if target:
        Path(target).write_text(json.dumps(TIMES, indent=1), encoding="utf-8")
