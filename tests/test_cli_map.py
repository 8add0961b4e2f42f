"""``--map``: every command that reads a dataset folder reads it through a channel map.

Fast: the logs use the logger's own channel names (and kPa), so they load only through the
map; the command's expensive work is replaced by a stub that records the data it was given
and stops the command there.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from synthetic import make_trace

import clutchlab.residual_ml as residual_ml
import clutchlab.validation as validation
import clutchlab.validation.discover as discover_pkg
from clutchlab.cli import main
from clutchlab.cli_types import MAP_HELP
from clutchlab.data import Dataset, save_dataset
from clutchlab.physics.fit import PhysicsFitter, StructureSelector

#: Canonical signal → (logger channel, scale from canonical to the logger's unit).
LOGGER = {
    "time_s": ("Zeit", 1.0),
    "current_cmd_mA": ("I_soll", 1.0),
    "dither_amp_mA": ("I_dith", 1.0),
    "dither_freq_Hz": ("f_dith", 1.0),
    "clutch_pressure_bar": ("P_K", 100.0),  # kPa
    "line_pressure_bar": ("P_L", 100.0),  # kPa
    "oil_temp_C": ("T_oel", 1.0),
}

MAP_TOML = """\
[signals]
time_s = "Zeit"
current_cmd_mA = "I_soll"
dither_amp_mA = "I_dith"
dither_freq_Hz = "f_dith"
clutch_pressure_bar = { channel = "P_K", unit = "kPa" }
line_pressure_bar = { channel = "P_L", unit = "kPa" }
oil_temp_C = "T_oel"
"""

#: Each command, its options (with {out} for its output), and where its long work starts.
COMMANDS = {
    "evaluate": ["--out", "{out}", "--quiet"],
    "fit-physics": ["--out", "{out}.json", "--quiet"],
    "select-structure": ["--quiet"],
    "discover": ["--out", "{out}", "--quiet"],
    "classifiers": ["--out", "{out}", "--quiet"],
    "train": ["--variant", "gp_base", "--out", "{out}", "--quiet"],
}


class Reached(Exception):
    """The command reached its long work with these experiments."""

    def __init__(self, data):
        super().__init__("reached the long work")
        self.traces = list(data)


@pytest.fixture
def long_work(monkeypatch):
    """Replace each command's long work by a stub raising :class:`Reached` with its data."""

    def stop(data, *args, **kwargs):
        raise Reached(data)

    class Variant:
        def fit(self, data):
            raise Reached(data)

    monkeypatch.setattr(validation, "evaluate", stop)
    monkeypatch.setattr(PhysicsFitter, "fit", lambda self, data: stop(data))
    monkeypatch.setattr(StructureSelector, "fit", lambda self, data: stop(data))
    monkeypatch.setattr(discover_pkg, "discover", stop)
    monkeypatch.setattr(residual_ml, "compare_classifiers", stop)
    monkeypatch.setattr(residual_ml, "make_variant", lambda *a, **k: Variant())


@pytest.fixture(scope="module")
def logger_dataset(tmp_path_factory):
    """Three 2 s experiments (fast / medium / slow) logged under the logger's channel names,
    pressures in kPa; returns (folder, the experiments in canonical names and units)."""
    traces = [
        make_trace([0, 0.5, 1.5, 2.0], [0, 0, 1100, 0], name=f"{ramp}_50Hz", ramp=ramp)
        for ramp in ("fast", "medium", "slow")
    ]
    for k, tr in enumerate(traces):  # a pressure that is not zero, different per experiment
        traces[k] = tr.with_signals(clutch_pressure_bar=np.linspace(0.0, 5.0 + k, len(tr)))
    root = tmp_path_factory.mktemp("cli_map") / "logs"
    save_dataset(Dataset(traces), root)
    for tr in traces:
        path = root / f"{tr.name}.csv"
        df = pd.read_csv(path)
        df = pd.DataFrame({LOGGER[c][0]: df[c] * LOGGER[c][1] for c in df.columns})
        df.to_csv(path, index=False)
    return root, traces


def _argv(command, root, tmp_path, *extra):
    options = [o.format(out=tmp_path / "out") for o in COMMANDS[command]]
    return [command, str(root), *options, *extra]


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_dataset_command_reads_the_logs_through_map(
    command, logger_dataset, tmp_path, capsys, long_work
):
    root, truth = logger_dataset
    cmap = tmp_path / "logger.toml"
    cmap.write_text(MAP_TOML, encoding="utf-8")
    # Without the map the logs' channels are unknown: refused, naming a missing signal.
    assert main(_argv(command, root, tmp_path)) == 2
    assert "clutch_pressure_bar" in capsys.readouterr().err
    with pytest.raises(Reached) as reached:
        main(_argv(command, root, tmp_path, "--map", str(cmap)))
    got = {t.name: t for t in reached.value.traces}
    assert got, command
    for tr in truth:
        if tr.name not in got:  # a command given the training experiments only
            continue
        mapped = got[tr.name]  # renamed, and converted from kPa
        want = tr.get("clutch_pressure_bar")
        np.testing.assert_allclose(mapped.get("clutch_pressure_bar"), want, rtol=1e-8, atol=1e-9)
        np.testing.assert_allclose(mapped.get("line_pressure_bar"), 17.7, rtol=1e-8)


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "not found"),
        ("[signals\n", "invalid TOML"),
        ('[signals]\nclutch_pressure_bar = { channel = "P_K", unit = "furlong" }\n', "furlong"),
    ],
)
def test_a_missing_or_malformed_map_is_an_error_before_any_work(
    command, content, message, logger_dataset, tmp_path, capsys, long_work
):
    root, _ = logger_dataset
    cmap = tmp_path / "logger.toml"
    if content is not None:
        cmap.write_text(content, encoding="utf-8")
    assert main(_argv(command, root, tmp_path, "--map", str(cmap))) == 2  # Reached not raised
    err = capsys.readouterr().err
    assert err.startswith(f"clutchlab {command}: error: ") and str(cmap) in err
    assert message in err
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.json").exists()


def test_data_and_evaluate_and_fit_share_one_map_help(capsys):
    """One helper adds --map everywhere: the same help on every command."""
    for argv in (["data", "check"], ["data", "convert"], *([c] for c in COMMANDS)):
        with pytest.raises(SystemExit):
            main([*argv, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert f"--map MAP.toml {MAP_HELP}" in text, argv


def test_train_json_records_the_channel_map(logger_dataset, tmp_path, capsys):
    """``train --json`` said which dataset was read but not through which map (session 41)."""
    import json

    root, _ = logger_dataset
    cmap = tmp_path / "logger.toml"
    cmap.write_text(MAP_TOML, encoding="utf-8")
    js = tmp_path / "train.json"
    argv = _argv("train", root, tmp_path, "--map", str(cmap), "--json", str(js))
    assert main(argv) == 0
    assert json.loads(js.read_text(encoding="utf-8"))["channel_maps"] == [str(cmap)]
