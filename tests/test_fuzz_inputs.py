"""Hypothesis fuzz of the manifest, the channel map and the sweep spec (issue 18, must-show 2).

Hostile structures and paths (absolute, ``..``, symlinks out, NUL, very long, unicode, wrong
types): only ``ClutchlabError`` subclasses escape, and no file outside the dataset folder is
opened (``open`` audit events). The saved-model loader has its own fuzz
(``test_model_load_fuzz.py``).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from clutchlab.data import load_dataset, read_log
from clutchlab.data.channel_map import ChannelMap
from clutchlab.errors import ClutchlabError
from clutchlab.physics.design.spec_parse import parse_spec

FUZZ = settings(
    max_examples=120,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

ROOT = Path(tempfile.mkdtemp(prefix="clutchlab-input-fuzz-"))
OUTSIDE = ROOT / "outside"
_OPENED: list[str] = []
_RECORDING = [False]


def _audit(event, args):
    if _RECORDING[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
        _OPENED.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)  # cannot be removed; records only while _RECORDING[0]


@pytest.fixture(scope="module", autouse=True)
def _setup_and_remove_root():
    OUTSIDE.mkdir(parents=True, exist_ok=True)
    (OUTSIDE / "secret.csv").write_text("time_s,clutch_pressure_bar\n0,1\n")
    (OUTSIDE / "secret.toml").write_text('[signals]\ntime_s = "t"\n')
    yield
    shutil.rmtree(ROOT, ignore_errors=True)


GOOD_CSV = "\n".join(
    ["time_s,current_mA,clutch_pressure_bar,dither_freq_Hz"]
    + [f"{k / 1000:.3f},{500 + 100 * np.sin(k / 5):.3f},{5 + k / 1000:.4f},50" for k in range(400)]
)

paths = st.one_of(
    st.sampled_from(
        [
            "exp.csv",
            "map.toml",
            "link.csv",
            "link.toml",
            "../outside/secret.csv",
            "../outside/secret.toml",
            str(OUTSIDE / "secret.csv"),
            "/etc/passwd",
            "sub/../exp.csv",
            "./exp.csv",
            "exp.csv\x00.txt",
            "C:\\\\windows\\\\x.csv",
            "missing.csv",
            "",
            " ",
            ".",
            "a" * 5000,
            "ünï©ødé.csv",
        ]
    ),
    st.text(max_size=30),
)
scalars = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(allow_nan=True), st.text(max_size=20), paths
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=12), inner, max_size=4)
    ),
    max_leaves=12,
)
entries = st.one_of(
    values,
    st.fixed_dictionaries(
        {"file": paths, "ramp": st.one_of(st.sampled_from(["fast", "medium"]), values)},
        optional={
            "channel_map": paths,
            "dither_freq_Hz": values,
            "dither_shape": values,
            "dither_waveform": values,
        },
    ),
)
manifests = st.one_of(
    values,
    st.fixed_dictionaries(
        {"experiments": st.one_of(st.lists(entries, max_size=4), values)},
        optional={"channel_map": paths},
    ),
)

_COUNTER = iter(range(10**9))


def _dataset_folder() -> Path:
    folder = ROOT / f"case{next(_COUNTER)}"
    folder.mkdir()
    (folder / "exp.csv").write_text(GOOD_CSV)
    (folder / "map.toml").write_text('[signals]\ntime_s = "time_s"\n')
    (folder / "link.csv").symlink_to(OUTSIDE / "secret.csv")
    (folder / "link.toml").symlink_to(OUTSIDE / "secret.toml")
    return folder


def _inside(path: str, folder: Path) -> bool:
    real = os.path.realpath(path)
    return not real.startswith(str(OUTSIDE.resolve()))


def _entry(**kw):
    return {"experiments": [{"file": "exp.csv", "ramp": "fast"} | kw]}


@FUZZ
@given(manifests)
@example(_entry(file="../outside/secret.csv"))
@example(_entry(file=str(OUTSIDE / "secret.csv")))
@example(_entry(file="link.csv"))
@example(_entry(channel_map="link.toml"))
@example(_entry(channel_map="../outside/secret.toml"))
@example({"channel_map": str(OUTSIDE / "secret.toml"), **_entry()})
def test_manifest_fuzz(doc):
    folder = _dataset_folder()
    try:
        text = json.dumps(doc)
    except (ValueError, TypeError):
        text = "{not json"
    (folder / "manifest.json").write_text(text)
    _OPENED.clear()
    _RECORDING[0] = True
    try:
        load_dataset(folder)
    except ClutchlabError:
        pass
    finally:
        _RECORDING[0] = False
    outside = [p for p in _OPENED if not _inside(p, folder)]
    assert not outside, outside


channel_specs = st.one_of(
    values,
    st.sampled_from(["time_s", "current_mA", "clutch_pressure_bar", "nope"]),
    st.fixed_dictionaries(
        {},
        optional={
            "channel": st.one_of(st.sampled_from(["time_s", "current_mA", "x"]), values),
            "unit": st.one_of(st.sampled_from(["s", "ms", "A", "kPa", "degF", "furlong"]), values),
            "scale": values,
            "offset": values,
            "group": values,
        },
    ),
)
maps = st.one_of(
    values,
    st.fixed_dictionaries(
        {},
        optional={
            "signals": st.one_of(
                st.dictionaries(
                    st.sampled_from(
                        ["time_s", "current_mA", "clutch_pressure_bar", "oil_temp_C", "bogus"]
                    ),
                    channel_specs,
                    max_size=4,
                ),
                values,
            ),
            "defaults": st.one_of(
                st.dictionaries(st.sampled_from(["dither_freq_Hz", "x"]), values), values
            ),
            "description": values,
        },
    ),
)


@FUZZ
@given(maps)
def test_channel_map_fuzz(doc):
    folder = _dataset_folder()
    _OPENED.clear()
    _RECORDING[0] = True
    try:
        cmap = ChannelMap.from_dict(doc) if isinstance(doc, dict) else doc
        read_log(folder / "exp.csv", channel_map=cmap)
    except ClutchlabError:
        pass
    finally:
        _RECORDING[0] = False
    outside = [p for p in _OPENED if not _inside(p, folder)]
    assert not outside, outside


spec_docs = st.one_of(
    values,
    st.fixed_dictionaries(
        {},
        optional={
            "name": values,
            "model": st.one_of(
                values,
                st.fixed_dictionaries(
                    {},
                    optional={
                        "effects": st.one_of(
                            st.sampled_from(["sensor_lag", "sensor_lag,flow_force", "s"]),
                            st.lists(st.sampled_from(["sensor_lag", "x"]), max_size=3),
                            values,
                        ),
                        "baseline": values,
                        "parameters": st.one_of(
                            st.dictionaries(st.sampled_from(["reg_F_c", "zz"]), values), values
                        ),
                    },
                ),
            ),
            "scenario": values,
            "simulation": values,
            "metrics": values,
            "sampling": st.one_of(
                values,
                st.fixed_dictionaries(
                    {
                        "method": st.sampled_from(["lhs", "grid", "x"]),
                        "n": st.one_of(st.integers(-5, 10**12), values),
                    }
                ),
            ),
            "variables": st.one_of(
                values,
                st.lists(
                    st.fixed_dictionaries(
                        {"name": st.sampled_from(["reg_F_c", "dither_freq_Hz", "bogus"])},
                        optional={
                            "low": values,
                            "high": values,
                            "levels": st.one_of(st.integers(-3, 10**7), values),
                            "values": values,
                            "scale": values,
                        },
                    ),
                    max_size=7,
                ),
            ),
        },
    ),
)


@FUZZ
@given(spec_docs)
def test_sweep_spec_fuzz(doc):
    _OPENED.clear()
    _RECORDING[0] = True
    try:
        parse_spec(doc if isinstance(doc, dict) else {"name": doc})
    except ClutchlabError:
        pass
    finally:
        _RECORDING[0] = False
    assert not [p for p in _OPENED if "outside" in p]
