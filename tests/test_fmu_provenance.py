"""An exported physics FMU says where its parameter values come from.

A fit stopped at its time limit (``fit-physics`` prints "NOT CONVERGED" and writes
``"success": false``) used to export without a word, into an FMU whose description was
the same as that of a converged fit or of a design before any fit: the engineer who
receives the FMU could not tell.
"""

from __future__ import annotations

import dataclasses
import warnings
import xml.etree.ElementTree as ET
import zipfile

import fmpy
import pytest
from fmu_support import TMP, fit_result

from clutchlab.cli import main
from clutchlab.errors import FitWarning
from clutchlab.physics import CircuitModel
from clutchlab.physics.fmu import export_physics_fmu

STATUS = "Solved_To_Acceptable_Level (pre-fit) → Maximum_WallTime_Exceeded (refine)"


def _annotation(fmu) -> dict[str, str]:
    with zipfile.ZipFile(fmu) as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    return dict(root.find("VendorAnnotations/Tool[@name='clutchlab']/Model").attrib)


def _description(fmu) -> str:
    return fmpy.read_model_description(str(fmu)).description


def _unconverged_json(path):
    fit = dataclasses.replace(fit_result(), success=False, status=STATUS)
    fit.to_json(path)
    return path


def test_an_unconverged_fit_exports_with_a_warning_and_says_so_in_the_fmu():
    source = _unconverged_json(TMP / "unconverged.json")
    with pytest.warns(FitWarning, match="did not converge"):
        fmu = export_physics_fmu(source, TMP / "unconverged.fmu")
    text = _description(fmu)
    assert "NOT CONVERGED" in text and STATUS in text, text
    note = _annotation(fmu)
    assert note["source"] == "fit" and note["fit_converged"] == "false"
    assert note["fit_status"] == STATUS


def test_a_converged_fit_and_a_design_are_told_apart():
    with warnings.catch_warnings():
        warnings.simplefilter("error", FitWarning)
        fitted = export_physics_fmu(fit_result(), TMP / "converged.fmu")
    assert "Parameter values: fitted (fit status: synthetic (tests))" in _description(fitted)
    assert _annotation(fitted)["fit_converged"] == "true"
    design = TMP / "design_params.json"
    CircuitModel().params().to_json(design)
    fmu = export_physics_fmu(design, TMP / "design.fmu")
    assert "a design before any fit (parameter file design_params.json)" in _description(fmu)
    note = _annotation(fmu)
    assert note["source"] == "design" and "fit_converged" not in note


def test_export_fmu_cli_warns_about_an_unconverged_fit(tmp_path, capsys):
    source = _unconverged_json(tmp_path / "fit.json")
    assert main(["export-fmu", str(source), "--out", str(tmp_path / "c.fmu")]) == 0
    err = capsys.readouterr().err
    assert "clutchlab export-fmu: warning: the fit did not converge" in err, err
    assert (tmp_path / "c.fmu").is_file()


def test_a_hybrids_physics_is_not_labelled_as_given():
    """The physics inside a hybrid FMU carried ``source="given"`` (the default for a
    model and parameters passed by hand) into the hybrid's vendor annotation."""
    from types import SimpleNamespace

    from clutchlab.physics.fmu.adapters import _physics_program

    hybrid = SimpleNamespace(
        physics_=SimpleNamespace(effects=(), params=dict(fit_result().values), substeps=4)
    )
    program = _physics_program(hybrid, "hybrid")
    assert program.annotations["source"] == "hybrid"
    assert program.description.endswith("Parameter values: those of the trained hybrid's physics")
