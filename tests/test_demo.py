"""``clutchlab demo``, the README's main job, end to end through the console script."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys


def test_demo_end_to_end_writes_report_and_reuses_stand_data(tmp_path):
    out = tmp_path / "demo"
    exe = shutil.which("clutchlab")
    cmd = [exe] if exe else [sys.executable, "-m", "clutchlab.cli"]
    res = subprocess.run(
        [*cmd, "demo", "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=900,
        check=True,
    )
    report = out / "report.html"
    assert res.stdout.strip().endswith(f"report: {report}")
    html = report.read_text()
    assert "data:image/png;base64," in html and "physics_default" in html
    metrics = json.loads((out / "metrics.json").read_text())
    phys = metrics["variants"]["physics_default"]
    for key in ("rmse_bar", "mae_bar", "max_abs_bar", "fit_pct", "fit_s", "predict_s"):
        assert math.isfinite(phys[key]), key
    assert all(t.startswith("medium") for t in metrics["split"]["test"])
    assert not any(t.startswith("medium") for t in metrics["split"]["train"])
    # The report's numbers are the ones in metrics.json.
    assert f"{phys['rmse_bar']:.4g}" in (out / "report.md").read_text()
    assert metrics["stand_data_cached"] is False
    again = subprocess.run(
        [*cmd, "demo", "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=900,
        check=True,
    )
    assert "report:" in again.stdout
    assert json.loads((out / "metrics.json").read_text())["stand_data_cached"] is True
