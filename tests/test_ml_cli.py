"""``clutchlab classifiers`` and ``clutchlab train`` through the console entry point."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np

from clutchlab.data import save_dataset
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.residual_ml import load_model


def _run(*args, check=True):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=check,
    )


def test_classifiers_and_train_cli(tmp_path):
    config = StandConfig(
        settings=(DitherSetting(50.0, "A"), DitherSetting(70.0, "C")),
        ramps=(RampProfile("fast", 0.8, 0.2), RampProfile("slow", 2.0, 0.2)),
        substeps=2,
        seed=2,
    )
    data = tmp_path / "stand"
    save_dataset(run_stand(config, progress=False).dataset, data)

    out, js = tmp_path / "clf", tmp_path / "clf.json"
    res = _run(
        "classifiers",
        str(data),
        "--out",
        str(out),
        "--json",
        str(js),
        "--classifiers",
        "linear_svc,rbf_svc",
        "--quiet",
    )
    assert "Nonlinear (RBF) SVC" in res.stdout and "LOEO accuracy" in res.stdout
    assert (out / "classifiers.csv").exists() and (out / "classifiers.png").stat().st_size > 0
    doc = json.loads(js.read_text())
    assert list(doc["classifiers"]) == ["linear_svc", "rbf_svc"]
    assert all(0 <= c["accuracy"] <= 1 for c in doc["classifiers"].values())

    model_dir, mj = tmp_path / "model", tmp_path / "train.json"
    res = _run(
        "train",
        str(data),
        "--variant",
        "gp_base",
        "--kernel",
        "rbf",
        "--out",
        str(model_dir),
        "--json",
        str(mj),
        "--quiet",
    )
    assert "all training" in res.stdout and "model written to" in res.stdout
    assert "GP gp: rbf, length scales [" in res.stdout  # the fit summary
    doc = json.loads(mj.read_text())
    parts = doc["gp_hyperparameters"]
    assert set(parts) == {"gp", "variance_floor"}  # the mean's GP and its variance floor
    names = ["current_mA", "dither_amp_mA", "dither_freq_Hz"]  # a length scale names its input
    said = doc["hyperparameters_at_bounds"]
    raw = [(part, e) for part in parts for e in parts[part]["at_bounds"]]
    assert len(said) == len(raw)
    for text, (part, e) in zip(said, raw, strict=True):
        head = re.sub(r"^length_scale\[(\d)\]", lambda m: f"{m[0]} = {names[int(m[1])]}", e)
        assert text.startswith(f"{part}: " + head.split(" (")[0]), text
        # in the feature's unit and in bar², not "input units" / "target units²"
        assert "input units" not in text and "target units" not in text, text
    assert doc["variant"] == "gp_base" and set(doc["training"]["per_experiment"]) == {
        "fast_50Hz_A",
        "fast_70Hz_C",
        "slow_50Hz_A",
        "slow_70Hz_C",
    }
    assert doc["training"]["overall"]["fit_pct"] > 50  # explains most of the pressure
    model = load_model(model_dir / "model.json")
    assert model.feature_names_ == ["current_mA", "dither_amp_mA", "dither_freq_Hz"]
    assert np.isfinite(doc["fit_s"])
    assert doc["latch_decision"] is None and "latch decision" not in res.stdout

    res = _run("train", str(data), "--variant", "paper_svc_gp", "--out", str(tmp_path / "p"))
    assert "latch decision: local latch-event law" in res.stdout  # the default says so

    # the hybrid's --kernel sets the kernel of its default residual model and of the
    # standalone form made from it, nothing else (before session 66 the CLI gave the hybrid
    # an SVCPartitionedGP with the standalone pipeline's defaults as its residual: a latch
    # law that never sees the physics; on the default stand with the RQ kernel the hybrid
    # then fell back to its standalone form, 0.2525 bar on the medium ramp against 0.0653)
    _run("train", str(data), "--variant", "hybrid", "--kernel", "rq", "--out", str(tmp_path / "h"))
    hybrid = load_model(tmp_path / "h" / "model.json")
    assert hybrid.kernel == "rq" and hybrid.residual is None
    assert hybrid.residual_.kernel == "rq"  # the fitted form's GPs

    bad = _run(
        "train",
        str(data),
        "--variant",
        "gp_base",
        "--out",
        str(model_dir),
        "--train",
        "medium",
        check=False,
    )
    assert bad.returncode == 2 and "unknown ramp label" in bad.stderr


def test_hyperparameters_at_bounds_speak_the_features_units():
    """The notes said "… standardized = 4.71e+04 in input units" and "target units²", and a
    length scale on its upper bound (a feature that does not vary, e.g. one dither
    amplitude) read like a fault."""
    from types import SimpleNamespace

    from clutchlab.residual_ml.base import TraceEstimator

    fake = SimpleNamespace(
        feature_names_=["current_mA", "dither_amp_mA"],
        gp_hyperparameters=lambda: {
            "gp": {
                "at_bounds": [
                    "length_scale[1] (upper bound 1e+03 standardized = 4.71e+04 in input units)",
                    "noise_var (lower bound 1e-06 standardized = 2.5e-05 in target units²)",
                ]
            }
        },
    )
    said = TraceEstimator.hyperparameters_at_bounds(fake)
    assert said[0].startswith("gp: length_scale[1] = dither_amp_mA (upper bound 1e+03 ")
    assert "= 4.71e+04 mA)" in said[0] and "hardly changes along this feature" in said[0]
    assert said[1] == "gp: noise_var (lower bound 1e-06 standardized = 2.5e-05 in bar²)"
