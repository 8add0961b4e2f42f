"""Output safety (issue 18, items 2, 3 and 10): nothing a user wrote is overwritten or deleted,
every folder is replaced in one atomic step (kill tests on a real child process killed at the
dangerous point), and a bad output location is refused before any work with a clear error.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from test_validation_report import TINY_RAMPS, Lookup

from clutchlab.data import OWNED_NAME, load_dataset, save_dataset, write_folder_atomic
from clutchlab.data.convert import convert
from clutchlab.errors import ClutchlabError, DataError, OutputError
from clutchlab.physics.stand import (
    DEFAULT_SETTINGS,
    DitherSetting,
    RampProfile,
    StandConfig,
    run_stand,
)
from clutchlab.validation import VariantSpec, evaluate, register_variant, write_report
from clutchlab.validation import report as report_module
from clutchlab.validation import variants as variants_module

#: A location no process can create files in, root included (procfs).
UNWRITABLE = Path("/proc/clutchlab-no-such-dir/out")


def run_cli(*args, env=None):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *map(str, args)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


def run_child(code: str, kill_at: str | None = None) -> subprocess.CompletedProcess:
    """Run ``code`` in a real child Python process, SIGKILLed at the named point if given."""
    env = dict(os.environ)
    if kill_at:
        env["CLUTCHLAB_TEST_KILL_AT"] = kill_at
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


def snapshot(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != OWNED_NAME
    }


@pytest.fixture(scope="module")
def small_ds(tmp_path_factory):
    run = run_stand(
        StandConfig(
            settings=(DitherSetting(50.0, "B"),),
            ramps=(RampProfile("fast", 1.0, 0.2), RampProfile("medium", 2.0, 0.2)),
        ),
        progress=False,
    )
    return save_dataset(run.dataset, tmp_path_factory.mktemp("small") / "ds")


def add_user_files(folder: Path) -> dict[str, bytes]:
    (folder / "sub").mkdir(exist_ok=True)
    (folder / "notes.txt").write_text("my notes")
    (folder / "sub" / "keep.txt").write_text("keep me")
    return {"notes.txt": b"my notes", "sub/keep.txt": b"keep me"}


# ---- item 2: data convert ---------------------------------------------------------------------


def test_convert_overwrite_keeps_every_file_it_did_not_write(small_ds, tmp_path):
    dst = tmp_path / "dst"
    convert(small_ds, dst)
    user = add_user_files(dst)
    convert(small_ds, dst, format="parquet", overwrite=True)
    got = snapshot(dst)
    assert {k: got[k] for k in user} == user
    # the CSVs of the first conversion were clutchlab's: replaced by the Parquet files
    assert not [k for k in got if k.endswith(".csv")]
    assert load_dataset(dst).names == load_dataset(small_ds).names


def test_convert_onto_itself_is_refused_and_keeps_the_source(small_ds, tmp_path):
    src = tmp_path / "src"
    convert(small_ds, src)
    before = snapshot(src)
    for dst in (src, src / "inner", tmp_path):
        with pytest.raises(DataError, match="overlaps the source"):
            convert(src, dst, format="parquet", overwrite=True)
    assert snapshot(src) == before


def test_convert_into_the_current_folder_is_refused_before_reading(small_ds, tmp_path, monkeypatch):
    """``clutchlab data convert SRC . --overwrite`` read the whole dataset, then failed with
    "Device or resource busy" (a folder is written by swapping it whole)."""
    convert_module = sys.modules[convert.__module__]

    def no_reading(*args, **kwargs):
        raise AssertionError("the dataset was read before the destination was checked")

    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    monkeypatch.setattr(convert_module, "load_dataset", no_reading)
    for dst in (".", str(tmp_path)):
        with pytest.raises(OutputError, match="current folder"):
            convert(small_ds, dst, overwrite=True)
    assert list(here.iterdir()) == []


def test_user_file_in_the_way_is_refused_not_overwritten(small_ds, tmp_path):
    dst = tmp_path / "dst"
    dst.mkdir()
    (dst / "manifest.json").write_text('{"mine": true}')
    with pytest.raises(OutputError, match=r"did not write.*manifest\.json"):
        convert(small_ds, dst, overwrite=True)
    assert json.loads((dst / "manifest.json").read_text()) == {"mine": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dst"]  # no temporary left


@pytest.mark.parametrize("point", ["folder-before-swap", "folder-after-swap"])
def test_convert_killed_at_the_swap_leaves_a_whole_dataset(small_ds, tmp_path, point):
    dst = tmp_path / "dst"
    convert(small_ds, dst)
    user = add_user_files(dst)
    old = snapshot(dst)
    res = run_child(
        f"""
        from clutchlab.data.convert import convert
        convert({str(small_ds)!r}, {str(dst)!r}, format="parquet", overwrite=True)
        """,
        kill_at=point,
    )
    assert res.returncode == -signal.SIGKILL, res.stderr
    got = snapshot(dst)
    assert {k: got[k] for k in user} == user  # the user's files survive either way
    if point == "folder-before-swap":
        assert got == old
    else:
        assert not [k for k in got if k.endswith(".csv")]
    assert load_dataset(dst).names == load_dataset(small_ds).names


def test_rename_fallback_killed_between_renames_is_recovered(small_ds, tmp_path):
    """Where no atomic exchange exists, a kill between the two renames loses nothing: the
    next write restores the previous folder first."""
    dst = tmp_path / "dst"
    convert(small_ds, dst)
    old = snapshot(dst)
    res = run_child(
        f"""
        from clutchlab.data import output
        from clutchlab.data.convert import convert
        output._exchange = lambda a, b: False
        convert({str(small_ds)!r}, {str(dst)!r}, format="parquet", overwrite=True)
        """,
        kill_at="folder-between-renames",
    )
    assert res.returncode == -signal.SIGKILL, res.stderr
    assert not dst.exists()
    write_folder_atomic(tmp_path / "dst", {"x.txt": b"new"}, overwrite=True, what="dataset folder")
    got = snapshot(dst)
    assert got["x.txt"] == b"new"
    assert {k: v for k, v in got.items() if k != "x.txt"} == {
        k: v for k, v in old.items() if not k.endswith(".csv") and k != "manifest.json"
    }


# ---- item 3: report folders -------------------------------------------------------------------


@pytest.fixture(scope="module")
def quick_evaluation():
    tiny = run_stand(
        StandConfig(settings=DEFAULT_SETTINGS[:1], ramps=TINY_RAMPS), progress=False
    ).dataset
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(variants_module, "_REGISTRY", dict(variants_module._REGISTRY))
        register_variant(VariantSpec("lookup", "test double with a std", lambda c: Lookup()))
        return evaluate(tiny, ["physics_default", "lookup"], progress=False, command="pytest")


def test_report_refuses_a_users_report_html(quick_evaluation, tmp_path, monkeypatch):
    monkeypatch.setattr(report_module, "_png", lambda fig: b"\x89PNG\r\n\x1a\n")
    out = tmp_path / "rep"
    out.mkdir()
    (out / "report.html").write_text("<p>my own page</p>")
    with pytest.raises(OutputError, match=r"report\.html"):
        write_report(quick_evaluation, out)
    assert (out / "report.html").read_text() == "<p>my own page</p>"
    assert sorted(p.name for p in out.iterdir()) == ["report.html"]


def test_report_rewrite_drops_its_stale_figures_and_keeps_user_files(
    quick_evaluation, tmp_path, monkeypatch
):
    monkeypatch.setattr(report_module, "_png", lambda fig: b"\x89PNG\r\n\x1a\n")
    out = tmp_path / "rep"
    real = report_module.report_figures

    def with_extra(ev):
        figures, missing = real(ev)
        return [
            *figures,
            report_module.FigureSpec("extra", "Extra", "", figures[0].figure),
        ], missing

    monkeypatch.setattr(report_module, "report_figures", with_extra)
    write_report(quick_evaluation, out)
    assert (out / "figures" / "extra.png").is_file()
    (out / "figures" / "mine.png").write_bytes(b"user figure")
    monkeypatch.setattr(report_module, "report_figures", real)
    files = write_report(quick_evaluation, out)
    assert not (out / "figures" / "extra.png").exists()
    assert (out / "figures" / "mine.png").read_bytes() == b"user figure"
    drawn = {f"figures/{k}.png" for k in files.doc["figures"]["drawn"]}
    on_disk = {p.relative_to(out).as_posix() for p in (out / "figures").iterdir()}
    assert on_disk == drawn | {"figures/mine.png"}


@pytest.mark.parametrize("point", ["folder-before-swap", "folder-after-swap"])
def test_report_killed_mid_write_is_old_or_new_never_mixed(tmp_path, point):
    out = tmp_path / "rep"
    code = f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_validation_report import TINY_RAMPS
        from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand
        from clutchlab.validation import evaluate, write_report
        tiny = run_stand(StandConfig(settings=DEFAULT_SETTINGS[:1], ramps=TINY_RAMPS),
                         progress=False).dataset
        ev = evaluate(tiny, ["physics_default"], progress=False, command="{{}}")
        write_report(ev, {str(out)!r})
        """
    first = run_child(code.replace("{}", "first"))
    assert first.returncode == 0, first.stderr
    old = snapshot(out)
    res = run_child(code.replace("{}", "second"), kill_at=point)
    assert res.returncode == -signal.SIGKILL, res.stderr
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["command"] == ("first" if point == "folder-before-swap" else "second")
    if point == "folder-before-swap":
        assert snapshot(out) == old
    drawn = {f"figures/{k}.png" for k in doc["figures"]["drawn"]}
    assert {p.relative_to(out).as_posix() for p in (out / "figures").iterdir()} == drawn


# ---- item 10: output locations checked before the work ----------------------------------------


def test_evaluate_out_naming_a_file_is_refused_before_any_work(small_ds, tmp_path):
    target = tmp_path / "result.txt"
    target.write_text("a user's file")
    res = run_cli("evaluate", small_ds, "--out", target, "--variants", "physics_default")
    assert res.returncode == 2, res.stderr
    assert "exists and is not a folder" in res.stderr and "Traceback" not in res.stderr
    assert target.read_text() == "a user's file"


@pytest.mark.parametrize(
    "args",
    [
        ("evaluate", "{ds}", "--out", UNWRITABLE, "--variants", "physics_default"),
        ("data", "convert", "{ds}", UNWRITABLE),
        ("stand", "--out", UNWRITABLE, "--settings", "1"),
        ("evaluate", "{ds}", "--out", "{tmp}/rep", "--json", UNWRITABLE / "m.json"),
    ],
    ids=["evaluate", "convert", "stand", "json"],
)
def test_unwritable_output_is_a_clear_error_before_any_work(small_ds, tmp_path, args):
    args = [str(a).format(ds=small_ds, tmp=tmp_path) for a in args]
    res = run_cli(*args)
    assert res.returncode == 2, res.stderr
    assert "cannot write into" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "rep").exists()  # nothing was computed and written first


def test_output_error_is_a_clutchlab_and_an_os_error():
    assert issubclass(OutputError, ClutchlabError) and issubclass(OutputError, OSError)


# ---- the data layer's public writers --------------------------------------------------------

_WRITERS = ["write_csv", "write_parquet", "write_mf4", "write_mat", "write_mat73"]


def _writer(name):
    import clutchlab.data as data

    return getattr(data, name)


def _small_trace(temp_C=40.0):
    from synthetic import make_trace

    return make_trace([0.0, 0.05], [0.0, 500.0], temp_C=temp_C, name="fast_50Hz_B")


@pytest.mark.parametrize("name", _WRITERS)
def test_public_writer_failing_at_the_rename_keeps_the_earlier_file(name, tmp_path, monkeypatch):
    """A public writer called directly replaces a file only once the new one is complete."""
    import clutchlab.data.output as output

    dst = tmp_path / f"trace.{name.split('_')[1][:3]}"
    _writer(name)(_small_trace(), dst)
    before = dst.read_bytes()

    def no_rename(src, dst_):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(output.os, "replace", no_rename)
    with pytest.raises(OutputError, match="No space left"):
        _writer(name)(_small_trace(temp_C=80.0), dst)
    assert dst.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [dst.name]  # no temporary left


@pytest.mark.parametrize("name", _WRITERS)
def test_public_writer_replaces_a_file_and_refuses_a_folder(name, tmp_path):
    dst = tmp_path / "out"
    dst.write_bytes(b"old")
    assert _writer(name)(_small_trace(), dst) == dst
    assert dst.read_bytes() != b"old"
    (tmp_path / "folder").mkdir()
    with pytest.raises(OutputError, match="is a folder"):
        _writer(name)(_small_trace(), tmp_path / "folder")


# ---- --json never replaces an input or a file that is not JSON --------------------------------


def _check_json(path, json_path):
    from clutchlab.cli import main

    return main(["data", "check", str(path), "--json", str(json_path)])


def test_json_output_refuses_the_checked_log_and_the_manifest(small_ds, tmp_path, capsys):
    import shutil

    ds = tmp_path / "ds"
    shutil.copytree(small_ds, ds)
    log = next(p for p in ds.iterdir() if p.suffix == ".csv")
    before = snapshot(ds)
    assert _check_json(log, log) == 2
    assert "is this command's input" in capsys.readouterr().err
    assert _check_json(ds, ds / "manifest.json") == 2
    assert "is the manifest of this command's input" in capsys.readouterr().err
    assert snapshot(ds) == before


def test_json_output_replaces_a_json_result_but_not_another_file(small_ds, tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    assert _check_json(small_ds, notes) == 2
    assert "is not a JSON document" in capsys.readouterr().err
    assert notes.read_text() == "my notes"
    result = tmp_path / "check.json"
    result.write_text('{"earlier": true}')
    assert _check_json(small_ds, result) == 0
    assert "earlier" not in result.read_text()


def test_a_summary_never_replaces_a_model_nor_an_out_a_model_of_another_kind(
    small_ds, tmp_path, capsys
):
    """`export-fmu design.json --json fit.json` replaced the fit result the user had just
    exported (a JSON document, so it counted as replaceable)."""
    from fit_support import synthetic_fit

    from clutchlab.cli import main

    fit = tmp_path / "fit.json"
    synthetic_fit({"reg_F0": 1.0}).to_json(fit)
    design = tmp_path / "design.json"
    assert main(["params", "--out", str(design)]) == 0
    kept = {fit: fit.read_bytes(), design: design.read_bytes()}
    for path, kind in (
        (fit, "a fitted physics model (clutchlab fit-physics)"),
        (design, "a design's parameter file (clutchlab params --out)"),
    ):
        assert _check_json(small_ds, path) == 2
        err = capsys.readouterr().err
        assert f"--json {path}: holds {kind}, which a summary would replace" in err
    assert main(["params", "--out", str(fit)]) == 2  # a design over a fit
    err = capsys.readouterr().err
    assert "holds a fitted physics model (clutchlab fit-physics), which this command's" in err
    assert all(path.read_bytes() == content for path, content in kept.items())
    assert main(["params", "--out", str(design)]) == 0  # its own kind: replaced


# ---- a report never goes into a dataset folder clutchlab wrote (it would remove the data) ---


def test_report_out_naming_the_input_dataset_is_refused_before_any_work(tmp_path):
    from clutchlab.cli import main

    run = run_stand(
        StandConfig(
            settings=(DitherSetting(50.0, "B"),),
            ramps=(
                RampProfile("fast", 1.0, 0.2),
                RampProfile("medium", 1.5, 0.2),
                RampProfile("slow", 2.0, 0.2),
            ),
        ),
        progress=False,
    )
    ds = save_dataset(run.dataset, tmp_path / "ds")
    before = snapshot(ds)
    assert main(["evaluate", str(ds), "--out", str(ds), "--variants", "physics_default"]) == 2
    assert snapshot(ds) == before


def test_a_folder_of_another_kind_is_not_rewritten_legacy_record_included(tmp_path):
    folder = tmp_path / "ds"
    write_folder_atomic(folder, {"manifest.json": b"{}", "a.csv": b"1"}, what="dataset folder")
    with pytest.raises(OutputError, match="holds a dataset folder clutchlab wrote"):
        write_folder_atomic(folder, {"report.md": b"# r"}, overwrite=True, what="report folder")
    record = json.loads((folder / OWNED_NAME).read_text())
    del record["kind"]  # written before the kind was recorded
    (folder / OWNED_NAME).write_text(json.dumps(record))
    with pytest.raises(OutputError, match="holds a dataset folder"):
        write_folder_atomic(folder, {"report.md": b"# r"}, overwrite=True, what="report folder")
    assert sorted(p.name for p in folder.iterdir()) == [OWNED_NAME, "a.csv", "manifest.json"]
    write_folder_atomic(folder, {"manifest.json": b"{}"}, overwrite=True, what="dataset folder")
    assert not (folder / "a.csv").exists()  # the same kind still replaces its stale files


def test_model_outputs_never_replace_an_input_or_a_foreign_file(small_ds, tmp_path, capsys):
    """fit-physics --out / train --out are checked before any work (a fit takes minutes)."""
    import shutil

    from clutchlab.cli import main

    ds = tmp_path / "ds"
    shutil.copytree(small_ds, ds)
    log = next(p for p in ds.iterdir() if p.suffix == ".csv")
    before = snapshot(ds)
    assert main(["fit-physics", str(ds), "--out", str(ds / "manifest.json")]) == 2
    assert "is the manifest of this command's input" in capsys.readouterr().err
    assert main(["fit-physics", str(ds), "--out", str(log)]) == 2
    assert "is not a JSON document" in capsys.readouterr().err
    assert main(["fit-physics", str(ds), "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert main(["train", str(ds), "--variant", "gp_didt", "--out", str(log)]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    assert snapshot(ds) == before
