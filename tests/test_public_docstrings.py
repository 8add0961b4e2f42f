"""Every field of the public settings and result dataclasses, and every constructor
argument of the estimators, is documented (numpydoc Attributes / Parameters)."""

from __future__ import annotations

import dataclasses
import inspect
import re

import pytest

from clutchlab.physics import OutputSpec, SimulationResult, SimulationSettings
from clutchlab.physics.fit import FitResult, FitSettings
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, StandRun
from clutchlab.residual_ml import GPBaseline, GPWithDerivative, HybridModel, SVCPartitionedGP


def _documented(doc: str, sections: tuple[str, ...]) -> set[str]:
    """Names listed in the numpydoc ``sections`` of ``doc`` (``a, b : type`` lines, and
    name lists continued on the next line)."""
    lines = inspect.cleandoc(doc or "").splitlines()
    names: set[str] = set()
    section = None
    continued = False
    for i, line in enumerate(lines):
        if i + 1 < len(lines) and re.fullmatch(r"-{3,}", lines[i + 1].strip()) and line.strip():
            section = line.strip()
            continued = False
            continue
        if section not in sections or re.fullmatch(r"-{3,}", line.strip()) or not line.strip():
            continue
        if not line.startswith(" ") or continued:
            head = line.split(" : ")[0]
            names |= {n.strip().lstrip("*") for n in head.split(",") if n.strip()}
            continued = head.rstrip().endswith(",")
    return names


@pytest.mark.parametrize(
    "cls",
    [
        OutputSpec,
        SimulationResult,
        SimulationSettings,
        FitResult,
        FitSettings,
        DitherSetting,
        RampProfile,
        StandConfig,
        StandRun,
    ],
)
def test_every_dataclass_field_is_documented(cls):
    fields = [f.name for f in dataclasses.fields(cls)]
    missing = [f for f in fields if f not in _documented(cls.__doc__, ("Attributes",))]
    assert not missing, f"{cls.__name__}: fields without an Attributes entry: {missing}"


@pytest.mark.parametrize("cls", [GPBaseline, SVCPartitionedGP, HybridModel])
def test_every_estimator_argument_is_documented(cls):
    args = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    missing = [a for a in args if a not in _documented(cls.__doc__, ("Parameters",))]
    assert not missing, f"{cls.__name__}: arguments without a Parameters entry: {missing}"


@pytest.mark.parametrize("cls", [GPBaseline, GPWithDerivative, SVCPartitionedGP])
def test_the_documented_default_features_are_the_defaults(cls):
    """GPWithDerivative's and SVCPartitionedGP's docstrings gave the nominal current
    (``current_mA``; "I, A_d, f_d, dI/dt") where the default is the lagged current."""
    names = ", ".join(f'"{f}"' for f in cls._default_features)
    assert f"``({names})``" in " ".join(inspect.getdoc(cls).split()), cls.__name__
