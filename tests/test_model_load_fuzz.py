"""Fuzzing the saved-model loader (issue 18, must-show 2).

A valid saved model (JSON + NPZ) is damaged at random: JSON keys dropped, retyped or
replaced (with hostile values among them: outside paths, huge and non-finite numbers,
foreign class names), NPZ arrays reshaped, poisoned with NaN / inf / zero, retyped
(integers, complex, text, pickled objects), dropped, added, renamed, the NPZ truncated or
its bytes flipped. Whatever the damage, ``load_model`` returns a model that predicts finite
numbers or raises a ``ClutchlabError``; nothing else escapes, and no file outside the
model's folder is opened (an audit hook records every ``open``; a decoy model sits next to
the folder and the mutations point at it).
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clutchlab.errors import ClutchlabError
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.residual_ml import GPBaseline, SVCPartitionedGP, load_model, save_model

# Deterministic examples, so that the suite is reproducible (~7 s in all). Randomized
# campaigns (derandomize=False) of 3000 examples per model test, then 2000 per test with the
# fit result (22 000 in all) let nothing but ClutchlabError through, after the first had
# found the finite-but-impossible values the GP check now refuses.
FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

ROOT = Path(tempfile.mkdtemp(prefix="clutchlab-model-fuzz-"))
DECOY = ROOT / "outside"  # a valid model outside every fuzzed folder: never to be opened


@pytest.fixture(scope="module", autouse=True)
def _remove_root():
    """The fuzz writes hundreds of case folders: remove them all when the module is done."""
    yield
    shutil.rmtree(ROOT, ignore_errors=True)


_OPENED: list[str] = []
_RECORDING = [False]


def _audit(event: str, args) -> None:
    if _RECORDING[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
        _OPENED.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)  # cannot be removed; records only while _RECORDING[0]


def _saved(model, name: str) -> tuple[dict, dict[str, np.ndarray]]:
    save_model(model, DECOY / f"{name}.json")
    doc = json.loads((DECOY / f"{name}.json").read_text())
    with np.load(DECOY / f"{name}.npz", allow_pickle=False) as f:
        return doc, {k: f[k] for k in f.files}


@pytest.fixture(scope="module")
def valid():
    """Two valid saved models (document, arrays): a GP baseline and an SVC-partitioned GP
    with its RBF classifier (most arrays); also written to the decoy folder."""
    config = StandConfig(
        settings=(DitherSetting(30.0, "A"),),
        ramps=(RampProfile("fast", 1.0, 0.3),),
        substeps=2,
        seed=1,
    )
    trace = run_stand(config, progress=False).dataset[0]
    DECOY.mkdir(exist_ok=True)
    small = {"n_hyper": 100, "max_points": 40}
    return {
        "gp": _saved(GPBaseline(**small).fit([trace]), "gp"),
        # (latched GP on the pressure: the fuzzed model is then checked on feature arrays)
        "svc": _saved(SVCPartitionedGP(latched_reference="none", **small).fit([trace]), "svc"),
    }


# -- mutations -----------------------------------------------------------------------------

HOSTILE_STR = st.sampled_from(
    [
        "../outside/svc.npz",
        str(DECOY / "svc.npz"),
        str(DECOY / "svc.json"),
        "/etc/passwd",
        "..",
        "",
        "m.npz\x00.json",
        "os.system",
        "LocalGPRegressor",
        "HybridModel",
        "rbf_svc",
        "linear",
        "rq",
        "auto",
        "current_mA",
        "PhysicsPredictor",
        "sensor_lag",
    ]
)
NUMBER = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, -1, 0.0, -0.0, 1e308, -1e308, 5e-324, 2**63, 10**400]),
)
SCALAR = st.one_of(st.none(), st.booleans(), NUMBER, HOSTILE_STR, st.text(max_size=8))
JSON = st.recursive(
    SCALAR,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(st.one_of(HOSTILE_STR, st.text(max_size=6)), inner, max_size=3),
    ),
    max_leaves=6,
)


def _paths(node, prefix=()):
    """Every (path, value) of a JSON document."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


def _parent(doc, path):
    for k in path[:-1]:
        doc = doc[k]
    return doc


@st.composite
def json_mutation(draw, doc):
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p, _ in _paths(doc) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _parent(doc, path), path[-1]
        op = draw(st.sampled_from(["drop", "replace", "retype", "add", "nest"]))
        value = parent[key]
        if op == "drop":
            del parent[key]
        elif op == "replace":
            parent[key] = draw(JSON)
        elif op == "retype":
            parent[key] = draw(
                st.sampled_from([str(value), [value], {"v": value}, None, True, 0.0])
            )
        elif op == "add" and isinstance(value, dict):
            value[draw(st.one_of(HOSTILE_STR, st.text(max_size=6)))] = draw(JSON)
        elif op == "nest":
            parent[key] = {"__estimator__": {"class": draw(HOSTILE_STR), "params": value}}
    return doc


@st.composite
def array_mutation(draw, arrays):
    arrays = dict(arrays)
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.sampled_from(sorted(arrays) or ["x"]))
        a = np.array(arrays.get(name, np.zeros(3)))
        op = draw(
            st.sampled_from(
                ["reshape", "poison", "dtype", "drop", "extra", "rename", "truncate", "empty"]
            )
        )
        if op == "reshape":
            arrays[name] = draw(
                st.sampled_from([a.T, a.ravel(), a[None], a[..., None], a[:-1], a[1:], a[:0]])
            )
        elif op == "poison" and a.size:
            a = a.astype(float)
            a.flat[draw(st.integers(0, a.size - 1))] = draw(
                st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -1.0, 1e308, -1e308, 1e-320])
            )
            arrays[name] = a
        elif op == "dtype":
            kind = draw(st.sampled_from(["i1", "u8", "c16", "U3", "?", "f2", "object"]))
            try:
                with np.errstate(invalid="ignore", over="ignore"):
                    arrays[name] = a.astype(kind)
            except (ValueError, OverflowError):  # text that is not a number, say
                arrays[name] = np.zeros(a.shape, dtype=kind)
        elif op == "drop":
            arrays.pop(name, None)
        elif op == "extra":
            arrays[draw(st.sampled_from(["gp9.theta", "clf.extra", "../x", "gp.x_mean"]))] = a
        elif op == "rename":
            arrays[name + "_"] = arrays.pop(name, a)
        elif op == "empty":
            arrays[name] = np.zeros((0,) * max(a.ndim, 1))
    return arrays


def _write(folder: Path, doc, arrays, npz_bytes=None) -> Path:
    folder.mkdir(parents=True)
    np.savez(folder / "m.npz", **arrays)  # object arrays are pickled: the loader refuses them
    if npz_bytes is not None:
        (folder / "m.npz").write_bytes(npz_bytes((folder / "m.npz").read_bytes()))
    (folder / "m.json").write_text(json.dumps(doc, allow_nan=True), encoding="utf-8")
    return folder / "m.json"


_COUNTER = iter(range(10**9))


def _load_only_clutchlab_errors(path: Path, d: int) -> None:
    """Load ``path``: a ClutchlabError, or a model that predicts finite numbers; nothing
    outside the model's folder (but Python's own modules) is opened."""
    folder = path.parent.resolve()
    _OPENED.clear()
    _RECORDING[0] = True
    try:
        model = load_model(path)
    except ClutchlabError:
        model = None
    finally:
        _RECORDING[0] = False
    outside = [
        p
        for p in _OPENED
        if Path(p).resolve().parent != folder and not p.endswith((".py", ".pyc", ".so"))
    ]
    assert outside == [], f"opened outside the model folder: {outside}"
    assert not any(str(DECOY) in p for p in _OPENED)
    if model is None:
        return
    X = np.random.default_rng(0).uniform(0.0, 800.0, size=(7, d))
    mean, std = model.predict(X, return_std=True)
    assert np.isfinite(mean).all() and np.isfinite(std).all()


def _folder() -> Path:
    return ROOT / f"case{next(_COUNTER)}"


@pytest.mark.parametrize("name", ["gp", "svc"])
def test_fuzz_model_json(valid, name):
    doc, arrays = valid[name]
    d = len(doc["state"]["feature_names"])

    @FUZZ
    @given(json_mutation({**doc, "arrays": "m.npz"}))
    def run(mutated):
        _load_only_clutchlab_errors(_write(_folder(), mutated, arrays), d)

    run()


@pytest.mark.parametrize("name", ["gp", "svc"])
def test_fuzz_model_npz(valid, name):
    doc, arrays = valid[name]
    d = len(doc["state"]["feature_names"])
    doc = {**doc, "arrays": "m.npz"}

    def damage(op, at, byte):
        def f(data: bytes) -> bytes:
            i = int(at * (len(data) - 1))
            if op == "truncate":
                return data[:i]
            return data[:i] + bytes([data[i] ^ byte]) + data[i + 1 :]

        return f

    @FUZZ
    @given(
        array_mutation(arrays),
        st.one_of(
            st.none(),
            st.builds(
                damage,
                st.sampled_from(["truncate", "flip"]),
                st.floats(0.0, 1.0),
                st.integers(1, 255),
            ),
        ),
    )
    def run(mutated, npz_bytes):
        _load_only_clutchlab_errors(_write(_folder(), doc, mutated, npz_bytes), d)

    run()


def test_hostile_array_file_names_and_links_are_refused_without_opening(valid):
    """The document names a file outside the folder, or the NPZ beside it is a link out of
    it: refused, and the outside file is never opened."""
    doc, arrays = valid["svc"]
    for name in ("../outside/svc.npz", str(DECOY / "svc.npz"), "..", "sub/m.npz", "m.json"):
        path = _write(_folder(), {**doc, "arrays": name}, arrays)
        _OPENED.clear()
        _RECORDING[0] = True
        try:
            with pytest.raises(ClutchlabError):
                load_model(path)
        finally:
            _RECORDING[0] = False
        assert not any(str(DECOY) in p for p in _OPENED), name
    folder = _folder()
    folder.mkdir()
    (folder / "m.json").write_text(json.dumps({**doc, "arrays": "m.npz"}))
    os.symlink(DECOY / "svc.npz", folder / "m.npz")
    _OPENED.clear()
    _RECORDING[0] = True
    try:
        with pytest.raises(ClutchlabError, match="links outside the model's folder"):
            load_model(folder / "m.json")
    finally:
        _RECORDING[0] = False
    assert [p for p in _OPENED if "npz" in p] == []


def test_fuzz_fit_result_json(tmp_path):
    """The physics fit-result loader (``FitResult.from_json``, what ``export-fmu`` and
    ``PhysicsFitter.load`` read): only ClutchlabError escapes, and a result that loads
    rebuilds its model and parameter values."""
    from fmu_support import fit_result

    from clutchlab.physics.fit import FitResult

    doc = json.loads(fit_result(("sensor_lag",)).to_json())

    @FUZZ
    @given(json_mutation(doc))
    def run(mutated):
        path = _folder()
        path.mkdir()
        (path / "fit.json").write_text(json.dumps(mutated, allow_nan=True), encoding="utf-8")
        try:
            result = FitResult.from_json(path / "fit.json")
        except ClutchlabError:
            return
        params = result.params()
        assert all(np.isfinite(params[n]) for n in params)

    run()
