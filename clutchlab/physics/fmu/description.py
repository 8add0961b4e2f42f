"""``modelDescription.xml`` (FMI 2.0, co-simulation) of an :class:`FmuProgram`.

Value references: inputs ``0 … nv−1``, outputs ``nv … nv+ny−1``, parameters after them —
the layout the C wrapper (:mod:`.csource`) is generated with.
"""

from __future__ import annotations

import datetime as _dt
from xml.sax.saxutils import quoteattr

from ... import __version__
from .program import FmuProgram, FmuVariable
from .units import fmi_unit

__all__ = ["model_description_xml", "value_references"]


def value_references(program: FmuProgram) -> dict[str, int]:
    """Variable name → value reference."""
    names = [v.name for v in (*program.inputs, *program.outputs, *program.parameters)]
    return {n: k for k, n in enumerate(names)}


def _num(x: float) -> str:
    return repr(float(x))


def _real(var: FmuVariable, start: bool, bounds: bool) -> str:
    attrs = []
    unit = fmi_unit(var.unit)
    if unit is not None:
        attrs.append(f"unit={quoteattr(unit.name)}")
    if bounds and var.min is not None:
        attrs.append(f'min="{_num(var.min)}"')
    if bounds and var.max is not None:
        attrs.append(f'max="{_num(var.max)}"')
    if start:
        attrs.append(f'start="{_num(var.start)}"')
    return "<Real " + " ".join(attrs) + "/>"


def _units(program: FmuProgram) -> list[str]:
    seen: dict[str, str] = {}
    for var in (*program.inputs, *program.outputs, *program.parameters):
        unit = fmi_unit(var.unit)
        if unit is None or unit.name in seen:
            continue
        base = " ".join(f'{k}="{e}"' for k, e in unit.exponents)
        if unit.factor != 1.0:
            base += f' factor="{_num(unit.factor)}"'
        if unit.offset != 0.0:
            base += f' offset="{_num(unit.offset)}"'
        seen[unit.name] = f"    <Unit name={quoteattr(unit.name)}><BaseUnit {base}/></Unit>"
    return list(seen.values())


def model_description_xml(
    program: FmuProgram, guid: str, source_files: tuple[str, ...] = ()
) -> str:
    """The ``modelDescription.xml`` text.

    Parameters
    ----------
    program : FmuProgram
        What the FMU computes.
    guid : str
        The FMU's GUID (also compiled into the binary, which checks it).
    source_files : tuple of str
        C files under ``sources/`` that build the binary (listed for re-compilation).
    """
    vr = value_references(program)
    now = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<fmiModelDescription",
        '  fmiVersion="2.0"',
        f"  modelName={quoteattr(program.name)}",
        f"  guid={quoteattr(guid)}",
        f"  description={quoteattr(program.description)}",
        f'  generationTool="clutchlab {__version__}"',
        f'  generationDateAndTime="{now}"',
        '  variableNamingConvention="flat"',
        '  numberOfEventIndicators="0">',
        f"  <CoSimulation modelIdentifier={quoteattr(program.name)}",
        '    canHandleVariableCommunicationStepSize="true"',
        '    canInterpolateInputs="true"',
        '    maxOutputDerivativeOrder="0"',
        '    canRunAsynchronuously="false"',
        '    canBeInstantiatedOnlyOncePerProcess="false"',
        '    canNotUseMemoryManagementFunctions="true"',
        '    canGetAndSetFMUstate="true"',
        '    canSerializeFMUstate="true"',
        '    providesDirectionalDerivative="false">',
    ]
    if source_files:
        lines.append("    <SourceFiles>")
        lines += [f"      <File name={quoteattr(f)}/>" for f in source_files]
        lines.append("    </SourceFiles>")
    lines.append("  </CoSimulation>")
    units = _units(program)
    if units:
        lines += ["  <UnitDefinitions>", *units, "  </UnitDefinitions>"]
    lines += [
        "  <LogCategories>",
        '    <Category name="logStatusError" description="errors (non-finite state, misuse)"/>',
        '    <Category name="logAll" description="every call"/>',
        "  </LogCategories>",
        f'  <DefaultExperiment startTime="0.0" stopTime="{_num(program.stop_time_s)}" '
        f'stepSize="{_num(program.step_s)}"/>',
        "  <VendorAnnotations>",
        '    <Tool name="clutchlab">',
        "      <Model "
        + " ".join(f"{k}={quoteattr(str(v))}" for k, v in sorted(program.annotations.items()))
        + "/>",
        "    </Tool>",
        "  </VendorAnnotations>",
        "  <ModelVariables>",
    ]

    def scalar(var: FmuVariable, attrs: str, real: str) -> None:
        lines.append(
            f'    <ScalarVariable name={quoteattr(var.name)} valueReference="{vr[var.name]}" '
            f"{attrs} description={quoteattr(var.description)}>"
        )
        lines.append(f"      {real}")
        lines.append("    </ScalarVariable>")

    for var in program.inputs:
        scalar(var, 'causality="input" variability="continuous"', _real(var, True, True))
    for var in program.outputs:
        scalar(
            var,
            'causality="output" variability="continuous" initial="calculated"',
            _real(var, False, False),
        )
    for var in program.parameters:
        scalar(
            var,
            'causality="parameter" variability="fixed" initial="exact"',
            _real(var, True, True),
        )
    # ModelStructure indices are 1-based positions in ModelVariables.
    out_idx = [len(program.inputs) + k + 1 for k in range(len(program.outputs))]
    lines += [
        "  </ModelVariables>",
        "  <ModelStructure>",
        "    <Outputs>",
        # no direct feedthrough: the outputs are those at the end of the last step
        # (fmi2DoStep), not recomputed when an input is set, so that a master closing a
        # loop through the FMU (a pressure controller) sees no algebraic loop
        *(f'      <Unknown index="{i}" dependencies=""/>' for i in out_idx),
        "    </Outputs>",
        "    <InitialUnknowns>",
        *(f'      <Unknown index="{i}"/>' for i in out_idx),
        "    </InitialUnknowns>",
        "  </ModelStructure>",
        "</fmiModelDescription>",
    ]
    return "\n".join(lines) + "\n"
