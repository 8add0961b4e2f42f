"""``clutchlab fit-physics`` through the console entry point."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

from clutchlab.cli_fit import _worse_than_start, limit_hint, plateau_note
from clutchlab.data import save_dataset
from clutchlab.physics.fit import FitResult
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

#: Datasheet values except the three parameters the CLI fits: the model is then exact.
TRUTH = {
    "reg_F_c": 1.0,
    "vfs_d_orf": 0.45,
    "latch_F0": 27.7,
    "cacc_k": 40.0,
    "fluid_beta": 1.5,
    "vfs_K_m": 14.4,
    "vfs_F_pre": 1.1,
    "reg_F0": -1.6,
}


def test_fit_physics_cli_writes_model_and_json(tmp_path):
    config = StandConfig(
        builtin_effects=False,
        settings=(DitherSetting(50.0, "A"),),
        ramps=(RampProfile("fast", 1.5, 0.3), RampProfile("medium", 2.0, 0.3)),
        seed=4,
        substeps=2,
        overrides=TRUTH,
    )
    data = tmp_path / "stand"
    save_dataset(run_stand(config, progress=False).dataset, data)
    out, js = tmp_path / "model.json", tmp_path / "fit.json"
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "clutchlab.cli",
            "fit-physics",
            str(data),
            "--out",
            str(out),
            "--train",
            "fast",
            "--free",
            "vfs_K_m,vfs_F_pre,reg_F0",
            "--quiet",
            "--substeps",
            "3",
            "--json",
            str(js),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    assert "model written to" in res.stdout and "vfs_K_m" in res.stdout
    fit = FitResult.from_json(out)
    assert fit.free == ["vfs_K_m", "vfs_F_pre", "reg_F0"]
    assert fit.train == ["fast_50Hz_A"]  # the medium ramp is never fitted on
    assert json.loads(js.read_text())["values"] == fit.values
    assert fit.settings["substeps"] == 3
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "clutchlab.cli",
            "fit-physics",
            str(data),
            "--out",
            str(out),
            "--train",
            "fast",
            "--free",
            "nope",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert bad.returncode == 2 and "unknown parameter(s) nope" in bad.stderr
    fresh = tmp_path / "never.json"
    cmd = [sys.executable, "-m", "clutchlab.cli", "fit-physics", str(data), "--out", str(fresh)]
    bad = subprocess.run(
        [*cmd, "--train", "fast", "--substeps", "0", "--quiet"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert bad.returncode == 2 and "substeps must be 1..16" in bad.stderr
    assert not fresh.exists()

    # --start: go on from the fit just written, an effect added, at the fit's values
    more = tmp_path / "more.json"
    for start, target, why in (
        (out, out, "is this command's input"),
        (tmp_path / "none.json", more, "cannot read"),
    ):
        bad = subprocess.run(
            [*cmd[:-1], str(target), "--train", "fast", "--quiet", "--start", str(start)],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert bad.returncode == 2 and why in bad.stderr, bad.stderr
    assert not more.exists()
    base = [*cmd[:-1], str(more), "--train", "fast", "--substeps", "3", "--quiet"]
    res = subprocess.run(
        [*base, "--start", str(out), "--effects", "sensor_lag", "--free", "slag_tau"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert f"starting from {out}" in res.stdout and "added sensor_lag" in res.stdout
    assert res.returncode == 0, res.stderr
    again = FitResult.from_json(more)
    assert "sensor_lag" in again.effects and again.free == ["slag_tau"]
    assert all(again.values[k] == v for k, v in fit.values.items())  # the start's values
    assert (
        again.per_experiment["fast_50Hz_A"]["rmse_bar"]
        <= fit.per_experiment["fast_50Hz_A"]["rmse_bar"]
    )


def test_fit_stopped_at_its_limit_writes_the_best_iterate_as_the_model(
    tmp_path, monkeypatch, capsys
):
    """Issue 16 item 3: exit 0 with a warning and the model marked not converged; --strict
    keeps the old behaviour (exit 1, the best iterate beside as .best-iterate.json).

    The wall-time limit is reached after the solver's third iteration whatever the
    machine's load (the deadline's clock is the iteration count here): a real 2 s limit
    left no iteration finished on a loaded machine, and the fit then rightly exits 1."""
    import clutchlab.physics.fit.nlp as nlp
    from clutchlab.cli import main

    config = StandConfig(
        settings=(DitherSetting(50.0, "A"),),
        ramps=(RampProfile("fast", 1.5, 0.3), RampProfile("medium", 2.0, 0.3)),
        seed=5,
        substeps=2,
    )
    data = tmp_path / "stand"
    save_dataset(run_stand(config, progress=False).dataset, data)
    base = [sys.executable, "-m", "clutchlab.cli", "fit-physics", str(data), "--train", "fast"]
    base += ["--time-limit", "600", "--quiet"]

    calls = {"n": 0}

    def after_three_iterations(self):
        calls["n"] += 1  # the first call ends IPOPT's initialization
        self.stopped = calls["n"] > 3
        return self.stopped

    monkeypatch.setattr(nlp.IterationDeadline, "should_stop", after_three_iterations)
    out = tmp_path / "model.json"
    code = main([*base[3:], "--out", str(out)])
    res = SimpleNamespace(returncode=code, stderr=capsys.readouterr().err)
    monkeypatch.undo()
    assert res.returncode == 0, res.stderr
    assert "NOT CONVERGED" in res.stderr
    doc = json.loads(out.read_text())
    assert doc["success"] is False and "Exceeded" in doc["status"]
    assert FitResult.from_json(out).cost_history
    hint = limit_hint(doc["status"])  # a limit was hit ("Exceeded"): the warning names it
    assert hint and hint in res.stderr, (doc["status"], res.stderr)
    # an iteration limit is named as such: more time would not help it
    few = tmp_path / "few.json"
    res = subprocess.run(
        [*base[:-1], "--max-iter", "1", "--quiet", "--out", str(few)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    doc = json.loads(few.read_text())
    assert doc["status"].startswith("Maximum_Iterations_Exceeded"), doc["status"]
    assert "more iterations (--max-iter)" in res.stderr and "--time-limit" not in res.stderr
    bad = subprocess.run(
        [*base, "--out", str(tmp_path / "bad.json"), "--max-iter", "0"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert bad.returncode == 2 and "max_iter" in bad.stderr
    assert not (tmp_path / "bad.json").exists()
    strict = tmp_path / "strict.json"
    res = subprocess.run(
        [*base, "--out", str(strict), "--strict", "--max-iter", "1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 1 and "did not converge" in res.stderr
    assert not strict.exists() and (tmp_path / "strict.best-iterate.json").is_file()


def test_the_warning_names_the_limit_each_stage_hit():
    assert limit_hint("Maximum_Iterations_Exceeded (pre-fit)") == (
        "more iterations (--max-iter) may improve it"
    )
    assert limit_hint(
        "Solved_To_Acceptable_Level (pre-fit) → Maximum_WallTime_Exceeded (refine)"
    ) == ("more time (--time-limit) may improve it")
    both = limit_hint("Maximum_Iterations_Exceeded (pre-fit) → Not_Started_Short_Of_Time (refine)")
    assert "--max-iter" in both and "--time-limit" in both
    # a solver that stopped for another reason gets no promise
    assert limit_hint("Search_Direction_Becomes_Too_Small (pre-fit)") == ""
    assert limit_hint("Error_In_Step_Computation (pre-fit)") == ""


def test_a_cost_plateau_is_explained_in_the_fit_s_numbers():
    from clutchlab.physics.fit import FitSettings

    status = "Cost_Plateau (pre-fit) → Maximum_Iterations_Exceeded (refine)"
    note = plateau_note(status, FitSettings(prefit_plateau_iter=4, prefit_obj_change_tol=2e-3))
    assert "0.2 %" in note and "last 4 iterations" in note
    assert plateau_note("Solved_To_Acceptable_Level (pre-fit)", FitSettings()) == ""


def test_a_fit_from_a_start_that_ends_worse_there_says_so():
    """A pre-fit on a subset can end where every training experiment is worse off."""

    def fitter(start_rmse, fit_rmse):
        rows = {"a": {"rmse_bar": fit_rmse}, "b": {"rmse_bar": fit_rmse}}
        return SimpleNamespace(
            training_metrics=lambda data, start: {k: {"rmse_bar": start_rmse} for k in rows},
            result_=SimpleNamespace(per_experiment=rows),
        )

    why = _worse_than_start(fitter(0.1, 0.2), None, None)
    assert "did not improve on its start: training RMSE 0.2000 bar against 0.1000" in why
    assert _worse_than_start(fitter(0.2, 0.1), None, None) == ""
    assert _worse_than_start(fitter(0.1, 0.1), None, None) == ""
