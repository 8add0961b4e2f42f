"""FMU import hardening (issue 18, items 5, 6 and 11; must-show 3, FMU half).

The Modelica Reference FMU ``Feedthrough`` (``../shared/third_party``) is used in place: as a
physics model with an input map it reproduces its input exactly, its Integer / Boolean /
String / Enumeration inputs keep their start values and are listed. Rebuilt from its own
sources with a crash or an endless loop in its step, it gives a clear error and this
process survives. Zip bombs, oversized descriptions and unsafe member names are refused
before anything is extracted.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from clutchlab.errors import ClutchlabError, SimulationError
from clutchlab.physics.fmu import FmuError, FmuPhysics, importer
from clutchlab.physics.fmu.build import fmi_headers_dir
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

THIRD_PARTY = Path(__file__).resolve().parents[1].parent / "shared" / "third_party"
FEEDTHROUGH = THIRD_PARTY / "Feedthrough.fmu"
MAP = {"input_map": {"Float64_continuous_input": "current_mA"}}
OUT = {"output": "Float64_continuous_output"}


@pytest.fixture(scope="module")
def feedthrough() -> Path:
    assert FEEDTHROUGH.is_file(), (
        f"{FEEDTHROUGH} is missing: the third-party conformance files must sit in "
        "../shared/third_party beside the project (see its README)"
    )
    return FEEDTHROUGH


@pytest.fixture(scope="module")
def trace():
    config = StandConfig(
        settings=(DitherSetting(50.0, "B"),), ramps=(RampProfile("fast", 1.0, 0.2),)
    )
    return run_stand(config, progress=False).dataset[0]


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CLUTCHLAB_CACHE", str(tmp_path / "cache"))


def test_feedthrough_reproduces_its_input_and_lists_inputs_left_at_start(feedthrough, trace):
    physics = FmuPhysics(feedthrough, **MAP, **OUT)
    pressure = physics.predict(trace)
    np.testing.assert_allclose(pressure, trace.get("current_mA"), rtol=0, atol=1e-9)
    unfed = physics.interface_.unfed
    for name, kind in [
        ("Int32_input", "Integer"),
        ("Boolean_input", "Boolean"),
        ("String_input", "String"),
        ("Enumeration_input", "Enumeration"),
        ("Float64_discrete_input", "Real"),
    ]:
        assert unfed[name].startswith(kind) and "start value" in unfed[name], name
    sim = physics.simulate(trace)
    assert any("Int32_input" in m for m in sim.messages)


def rebuilt(src: Path, dst: Path, inject: str) -> Path:
    """``src`` rebuilt from its own sources with C code injected at the top of its step."""
    work = dst.with_suffix(".d")
    with zipfile.ZipFile(src) as zf:
        zf.extractall(work)
    model = work / "sources" / "model.c"
    text = model.read_text()
    head = "Status calculateValues(ModelInstance *comp) {"
    model.write_text(text.replace(head, head + "\n    " + inject + "\n", 1))
    so = work / "binaries" / "linux64" / "Feedthrough.so"
    subprocess.run(
        ["gcc", "-shared", "-fPIC", "-O1", "-I", str(fmi_headers_dir()), "-I",
         str(work / "sources"), str(work / "sources" / "all.c"), "-o", str(so)],
        check=True, capture_output=True,
    )  # fmt: skip
    with zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(work.rglob("*")):
            if p.is_file():
                zf.write(p, p.relative_to(work).as_posix())
    shutil.rmtree(work)
    return dst


def test_a_crashing_fmu_is_an_error_and_clutchlab_survives(feedthrough, trace, tmp_path):
    fmu = rebuilt(
        feedthrough,
        tmp_path / "crash.fmu",
        "if (comp->time > 0.05) { volatile int *p = 0; *p = 1; }",
    )
    physics = FmuPhysics(fmu, **MAP, **OUT)  # isolation is the default
    with pytest.raises(SimulationError, match=r"the FMU process died \(exit code -11\)"):
        physics.predict(trace)


def test_a_hanging_fmu_step_stops_at_the_timeout(feedthrough, trace, tmp_path):
    fmu = rebuilt(feedthrough, tmp_path / "hang.fmu", "if (comp->time > 0.05) { for (;;) {} }")
    physics = FmuPhysics(fmu, timeout_s=2.0, **MAP, **OUT)
    t0 = time.perf_counter()
    with pytest.raises(ClutchlabError, match="timeout after 2 s"):
        physics.predict(trace)
    # killed at the limit once stepping, not after the start-up allowance as well
    assert time.perf_counter() - t0 < 2.0 + importer.SPAWN_ALLOWANCE_S / 2


def with_member(src: Path, dst: Path, name: str, data: bytes, **kw) -> Path:
    shutil.copyfile(src, dst)
    with zipfile.ZipFile(dst, "a", zipfile.ZIP_DEFLATED, **kw) as zf:
        zf.writestr(zipfile.ZipInfo(name), data, compress_type=zipfile.ZIP_DEFLATED)
    return dst


@pytest.mark.parametrize("name", ["/etc/clutchlab-evil", "../evil.so", "binaries/../../evil"])
def test_unsafe_member_names_are_refused_on_open(feedthrough, tmp_path, name):
    fmu = with_member(feedthrough, tmp_path / "evil.fmu", name, b"x")
    with pytest.raises(FmuError, match="refused before extraction"):
        FmuPhysics(fmu, **MAP, **OUT)


def test_a_zip_bomb_is_refused_before_extraction(feedthrough, tmp_path):
    fmu = with_member(feedthrough, tmp_path / "bomb.fmu", "resources/zeros.bin", bytes(64 << 20))
    assert fmu.stat().st_size < 1 << 20
    with pytest.raises(FmuError, match=r"expands \d+× \(limit 200×"):
        FmuPhysics(fmu, **MAP, **OUT)
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").rglob("*.bin"))


def test_an_oversized_description_is_read_no_further_than_the_limit(
    feedthrough, tmp_path, monkeypatch
):
    src = tmp_path / "big.fmu"
    with zipfile.ZipFile(feedthrough) as zin, zipfile.ZipFile(src, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "modelDescription.xml":
                data = data.replace(b"<ModelVariables>", b"<ModelVariables>" + b" " * (80 << 20))
            zout.writestr(info, data, compress_type=zipfile.ZIP_DEFLATED)
    monkeypatch.setenv("CLUTCHLAB_FMU_MAX_RATIO", "1000000")  # let it past the bomb check
    with pytest.raises(FmuError, match=r"modelDescription.xml is larger than 67108864 bytes"):
        FmuPhysics(src, **MAP, **OUT)
    monkeypatch.setenv("CLUTCHLAB_FMU_MAX_DESCRIPTION_BYTES", str(128 << 20))
    with pytest.raises(FmuError) as exc:  # raised limit: read, then refused by the XML parser
        FmuPhysics(src, **MAP, **OUT)
    assert "larger than" not in str(exc.value)


def test_limits_are_raised_by_their_environment_variables(feedthrough, tmp_path, monkeypatch):
    fmu = with_member(feedthrough, tmp_path / "big.fmu", "resources/zeros.bin", bytes(4 << 20))
    with pytest.raises(FmuError, match="CLUTCHLAB_FMU_MAX_RATIO"):
        FmuPhysics(fmu, **MAP, **OUT)
    monkeypatch.setenv("CLUTCHLAB_FMU_MAX_RATIO", "100000")
    physics = FmuPhysics(fmu, **MAP, **OUT)
    assert physics.interface_.output.name == "Float64_continuous_output"
    assert os.environ["CLUTCHLAB_FMU_MAX_RATIO"] == "100000"


class _Stop(BaseException):
    """Ends a command at the evaluation (neither an error nor Ctrl-C to the command line)."""


def test_evaluate_maps_a_vendor_fmus_input_and_output_from_the_command_line(
    feedthrough, trace, tmp_path, monkeypatch, capsys
):
    """``clutchlab evaluate --physics-fmu`` on an FMU with other port names: before
    ``--fmu-input`` / ``--fmu-output`` it could not be used from the command line at all, and
    the error pointed at ``input_map`` / ``output=``, which exist in Python only."""
    import clutchlab.validation as validation
    from clutchlab.cli import main
    from clutchlab.data import Dataset, save_dataset

    save_dataset(Dataset([trace]), tmp_path / "data")
    seen = {}

    def capture(*args, physics_fmu=None, **kwargs):
        seen["fmu"] = physics_fmu
        raise _Stop  # before any fit

    monkeypatch.setattr(validation, "evaluate", capture)
    argv = ["evaluate", str(tmp_path / "data"), "--out", str(tmp_path / "r"), "--quiet"]
    argv += ["--physics-fmu", str(feedthrough)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--fmu-input NAME=SIGNAL" in err and "--fmu-output NAME" in err
    ports = ["--fmu-input", "Float64_continuous_input=current_mA"]
    ports += ["--fmu-output", "Float64_continuous_output"]
    with pytest.raises(_Stop):
        main([*argv, *ports])
    interface = seen["fmu"].interface_
    assert [(p.name, p.signal) for p in interface.inputs] == [
        ("Float64_continuous_input", "current_mA")
    ]
    assert interface.output.name == "Float64_continuous_output"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--fmu-input", "I_cmd", "--physics-fmu", "x.fmu"], "expected FMU_INPUT=SIGNAL"),
        (["--fmu-input", "I_cmd=current_cmd_mA"], "no --physics-fmu was given"),
        (["--fmu-output", "p_out"], "no --physics-fmu was given"),
    ],
)
def test_a_bad_fmu_port_option_is_a_usage_error(tmp_path, capsys, extra, message):
    from clutchlab.cli import main

    out = tmp_path / "report"
    code = main(["evaluate", str(tmp_path / "no-data"), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("clutchlab evaluate: error: --fmu-") and message in err
    assert not out.exists()
