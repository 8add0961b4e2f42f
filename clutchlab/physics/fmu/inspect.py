"""Read an FMU's interface and check that clutchlab can run it as a physics model.

Every problem is collected and reported in one :class:`FmuError` naming the FMU: a file
that is not a zip, a zip without ``modelDescription.xml``, an FMI version other than 2.0,
no co-simulation interface, no binary for this platform, no Real output for the pressure,
no input for the solenoid current, inputs that cannot be fed from a trace.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import fmpy

from ...data.signals import SIGNALS
from .errors import FmuError
from .units import FmiUnit, convertible, lookup

__all__ = [
    "CURRENT_SIGNALS",
    "FmuInterface",
    "FmuLimits",
    "FmuPort",
    "check_archive",
    "inspect_fmu",
    "read_member",
]

#: Canonical signals of which an FMU must take one (the solenoid current).
CURRENT_SIGNALS: tuple[str, ...] = ("current_mA", "current_cmd_mA")


@dataclass(frozen=True)
class FmuPort:
    """An FMU input or output and the canonical signal it is connected to.

    Attributes
    ----------
    name : str
        FMU variable name.
    value_reference : int
        Its value reference.
    signal : str
        Canonical signal name (``current_cmd_mA``, ``clutch_pressure_bar`` …).
    unit : FmiUnit or None
        The variable's unit as declared in the FMU (None: dimensionless or undeclared,
        taken to be the signal's unit).
    signal_unit : FmiUnit or None
        The canonical signal's unit.
    start : float or None
        Declared start value (in ``unit``).
    """

    name: str
    value_reference: int
    signal: str
    unit: FmiUnit | None
    signal_unit: FmiUnit | None
    start: float | None

    def to_fmu(self, values):
        """Values of the signal (canonical unit) in the FMU variable's unit."""
        if self.unit is None or self.signal_unit is None or self.unit == self.signal_unit:
            return values
        return (values * self.signal_unit.factor + self.signal_unit.offset - self.unit.offset) / (
            self.unit.factor
        )

    def from_fmu(self, values):
        """Values of the FMU variable in the canonical signal's unit."""
        if self.unit is None or self.signal_unit is None or self.unit == self.signal_unit:
            return values
        return (values * self.unit.factor + self.unit.offset - self.signal_unit.offset) / (
            self.signal_unit.factor
        )


@dataclass(frozen=True)
class FmuInterface:
    """What clutchlab needs to know to run an FMU on a trace.

    Attributes
    ----------
    path : Path
        The ``.fmu`` file.
    model_description : fmpy.model_description.ModelDescription
        As read by FMPy.
    inputs : tuple of FmuPort
        Every Real input, with its source signal.
    output : FmuPort
        The clutch-pressure output.
    outputs : dict
        Every Real output: name → value reference.
    parameters : dict
        Every parameter: name → value reference.
    clutchlab : bool
        Exported by clutchlab (its trace-dependent parameters are set from the trace).
    can_interpolate_inputs : bool
        The FMU accepts input derivatives (inputs linear over a step instead of held).
    unfed : dict
        Inputs clutchlab does not feed (not Real, or not mapped to a signal): name → text
        with type and start value. They keep their start values.
    """

    path: Path
    model_description: object
    inputs: tuple[FmuPort, ...]
    output: FmuPort
    outputs: dict[str, int] = field(default_factory=dict)
    parameters: dict[str, int] = field(default_factory=dict)
    clutchlab: bool = False
    can_interpolate_inputs: bool = False
    unfed: dict[str, str] = field(default_factory=dict)

    @property
    def current_signal(self) -> str:
        """The current signal the FMU takes (``current_mA`` or ``current_cmd_mA``)."""
        return next(p.signal for p in self.inputs if p.signal in CURRENT_SIGNALS)


def _declared_units(md) -> dict[str, FmiUnit]:
    out = {}
    for unit in getattr(md, "unitDefinitions", []) or []:
        base = unit.baseUnit
        if base is None:
            out[unit.name] = FmiUnit(unit.name)
            continue
        exps = tuple(
            sorted(
                (k, int(getattr(base, k)))
                for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
                if int(getattr(base, k) or 0)
            )
        )
        out[unit.name] = FmiUnit(
            unit.name, exps, float(base.factor or 1.0), float(base.offset or 0.0)
        )
    return out


@dataclass(frozen=True)
class FmuLimits:
    """Resource limits of FMU import: an archive beyond them is refused before extraction.

    Each is raised by its environment variable (an integer), for an FMU that is genuinely
    that large.

    Attributes
    ----------
    max_total_bytes : int
        Uncompressed size of all members (``CLUTCHLAB_FMU_MAX_TOTAL_BYTES``; 2 GiB).
    max_members : int
        Number of members (``CLUTCHLAB_FMU_MAX_MEMBERS``; 20 000).
    max_ratio : int
        Largest compression ratio of a member over 1 MiB (``CLUTCHLAB_FMU_MAX_RATIO``; 200):
        real binaries and sources compress 2–20×, a zip bomb 1000×.
    max_description_bytes : int
        Size of ``modelDescription.xml`` (``CLUTCHLAB_FMU_MAX_DESCRIPTION_BYTES``; 64 MiB).
    """

    max_total_bytes: int = 2 << 30
    max_members: int = 20_000
    max_ratio: int = 200
    max_description_bytes: int = 64 << 20

    @classmethod
    def from_env(cls) -> FmuLimits:
        """The limits, each raised by its environment variable when set."""
        kw = {}
        for name in ("max_total_bytes", "max_members", "max_ratio", "max_description_bytes"):
            env = f"CLUTCHLAB_FMU_{name.upper()}"
            if os.environ.get(env, "").strip().isdigit():
                kw[name] = int(os.environ[env])
        return cls(**kw)


def _member_problem(name: str) -> str | None:
    parts = name.replace("\\", "/").split("/")
    if name.startswith(("/", "\\")) or (parts and len(parts[0]) == 2 and parts[0][1] == ":"):
        return f"member {name!r} has an absolute path"
    if ".." in parts:
        return f"member {name!r} leads out of the archive ('..')"
    if "\0" in name:
        return f"member {name!r} contains a NUL character"
    return None


def check_archive(path: Path, zf: zipfile.ZipFile, limits: FmuLimits) -> list[zipfile.ZipInfo]:
    """Refuse an archive beyond :class:`FmuLimits` or with unsafe member names (FmuError)."""
    infos = zf.infolist()
    problems = [p for p in (_member_problem(i.filename) for i in infos) if p]
    hint = " (raise it with CLUTCHLAB_FMU_{} if the FMU is genuine)"
    if len(infos) > limits.max_members:
        problems.append(
            f"{len(infos)} members, more than {limits.max_members}" + hint.format("MAX_MEMBERS")
        )
    total = sum(i.file_size for i in infos)
    if total > limits.max_total_bytes:
        problems.append(
            f"{total} bytes uncompressed, more than {limits.max_total_bytes}"
            + hint.format("MAX_TOTAL_BYTES")
        )
    for i in infos:
        if i.file_size > (1 << 20) and i.file_size > limits.max_ratio * max(i.compress_size, 1):
            problems.append(
                f"member {i.filename!r} expands {i.file_size / max(i.compress_size, 1):.0f}× "
                f"(limit {limits.max_ratio}×: a zip bomb?)" + hint.format("MAX_RATIO")
            )
    if problems:
        raise FmuError(f"{path}: refused before extraction", problems)
    return infos


def read_member(zf: zipfile.ZipFile, name: str, limit: int, source: Path) -> bytes:
    """A member's bytes, reading at most ``limit`` + 1 whatever its header claims."""
    with zf.open(name) as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise FmuError(
            f"{source}: {name} is larger than {limit} bytes (raise "
            "CLUTCHLAB_FMU_MAX_DESCRIPTION_BYTES if the FMU is genuine)"
        )
    return data


def _read_description(path: Path, problems: list[str]):
    if not path.is_file():
        raise FmuError(f"{path}: no such file")
    if not zipfile.is_zipfile(path):
        raise FmuError(f"{path}: not an FMU — the file is not a zip archive")
    limits = FmuLimits.from_env()
    try:
        with zipfile.ZipFile(path) as zf:
            check_archive(path, zf, limits)
            names = set(zf.namelist())
            if "modelDescription.xml" not in names:
                listing = ", ".join(sorted(names)[:8]) or "nothing"
                raise FmuError(
                    f"{path}: not an FMU — the zip archive has no modelDescription.xml "
                    f"(it holds {listing})"
                )
            text = read_member(zf, "modelDescription.xml", limits.max_description_bytes, path)
    except (zipfile.BadZipFile, NotImplementedError, OSError, EOFError) as exc:
        raise FmuError(f"{path}: damaged zip archive: {exc}") from None
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise FmuError(f"{path}: modelDescription.xml is not valid XML: {exc}") from exc
    version = root.get("fmiVersion")
    if root.tag != "fmiModelDescription" or version is None:
        raise FmuError(
            f"{path}: not an FMU — modelDescription.xml has no <fmiModelDescription "
            "fmiVersion=...> root"
        )
    if version != "2.0":
        raise FmuError(
            f"{path}: cannot use this FMU",
            [
                f"FMI version {version}: clutchlab runs FMI 2.0 co-simulation FMUs "
                "(export the model as FMI 2.0)"
            ],
        )
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as exc:
        raise FmuError(f"{path}: modelDescription.xml cannot be read: {exc}") from exc
    if md.coSimulation is None:
        problems.append(
            "no co-simulation interface (a model-exchange-only FMU): clutchlab needs "
            "<CoSimulation> (export with a co-simulation solver)"
        )
        return md, names
    binary = (
        f"binaries/{fmpy.platform}/{md.coSimulation.modelIdentifier}{fmpy.sharedLibraryExtension}"
    )
    if binary not in names:
        have = sorted(
            {n.split("/")[1] for n in names if n.startswith("binaries/") and "/" in n[9:]}
        )
        problems.append(
            f"no binary for this platform: {binary} is missing "
            f"(binaries for: {', '.join(have) or 'none'})"
        )
    return md, names


def inspect_fmu(
    path: str | Path,
    input_map: dict[str, str] | None = None,
    output: str | None = None,
) -> FmuInterface:
    """Read and check an FMU's interface for use as a physics model.

    Parameters
    ----------
    path : path-like
        The ``.fmu`` file.
    input_map : dict, optional
        FMU input name → canonical signal name, for FMUs whose inputs are not named after
        the canonical signals (an Amesim export: ``{"I_cmd": "current_cmd_mA"}``).
        Units are converted through the FMU's unit definitions.
    output : str, optional
        FMU output holding the clutch pressure; default ``clutch_pressure_bar``, else the
        only Real output.

    Returns
    -------
    FmuInterface

    Raises
    ------
    FmuError
        Listing every problem found.
    """
    path = Path(path)
    input_map = dict(input_map or {})
    problems: list[str] = []
    md, _ = _read_description(path, problems)
    if problems:
        raise FmuError(f"{path}: cannot use this FMU", problems)
    declared = _declared_units(md)
    variables = md.modelVariables
    unknown = sorted(set(input_map.values()) - set(SIGNALS))
    if unknown:
        problems.append(
            f"input_map names unknown signal(s) {', '.join(unknown)}; canonical signals: "
            f"{', '.join(SIGNALS)}"
        )
    fmu_inputs = [v for v in variables if v.causality == "input"]
    names = {v.name for v in fmu_inputs}
    missing_keys = sorted(set(input_map) - names)
    if missing_keys:
        problems.append(
            f"input_map names FMU input(s) {', '.join(missing_keys)} the FMU does not have "
            f"(its inputs: {', '.join(sorted(names)) or 'none'})"
        )
    ports, unfed = [], {}
    for var in fmu_inputs:
        signal = input_map.get(var.name, var.name)
        start_text = f"start value {var.start}" if var.start is not None else "no start value"
        if var.type != "Real":  # vendor FMUs carry Integer / Boolean / String switches
            unfed[var.name] = f"{var.type}, kept at its {start_text}"
            continue
        if signal not in SIGNALS or signal == "time_s":
            if var.name in input_map or var.start is None:
                problems.append(
                    f"input {var.name!r} has no source: it is not a canonical signal name "
                    f"and has no start value; map it with input_map={{{var.name!r}: "
                    f"'<signal>'}} (clutchlab evaluate: --fmu-input {var.name}=SIGNAL; signals: "
                    f"{', '.join(s for s in SIGNALS if s != 'time_s')})"
                )
            else:
                unfed[var.name] = f"Real, not mapped to a signal, kept at its {start_text}"
            continue
        unit = lookup(var.unit or (var.declaredType.unit if var.declaredType else None), declared)
        sig_unit = lookup(SIGNALS[signal].unit)
        if unit is not None and not convertible(unit, sig_unit):
            problems.append(
                f"input {var.name!r} is in {unit.name!r}, which cannot take {signal} "
                f"({SIGNALS[signal].unit})"
            )
            continue
        start = float(var.start) if var.start is not None else None
        ports.append(FmuPort(var.name, var.valueReference, signal, unit, sig_unit, start))
    if fmu_inputs and not any(p.signal in CURRENT_SIGNALS for p in ports):
        problems.append(
            "missing input: no FMU input takes the solenoid current (current_mA or "
            f"current_cmd_mA); its inputs are {', '.join(sorted(names))}"
            + (
                ""
                if input_map
                else " — map one with input_map (clutchlab evaluate: --fmu-input NAME=SIGNAL)"
            )
            + (f" (left at their start values: {', '.join(unfed)})" if unfed else "")
        )
    elif not fmu_inputs:
        problems.append("missing inputs: the FMU has no inputs, so no current can drive it")
    outs = {v.name: v for v in variables if v.causality == "output" and v.type == "Real"}
    if output is None:
        output = (
            "clutch_pressure_bar"
            if "clutch_pressure_bar" in outs
            else (next(iter(outs)) if len(outs) == 1 else None)
        )
    out_port = None
    if output is None or output not in outs:
        problems.append(
            f"no output {output or 'clutch_pressure_bar'!r} for the clutch pressure; "
            f"Real outputs: {', '.join(outs) or 'none'} (choose one with output=..., "
            "clutchlab evaluate: --fmu-output NAME)"
        )
    else:
        var = outs[output]
        unit = lookup(var.unit or (var.declaredType.unit if var.declaredType else None), declared)
        bar = lookup("bar")
        if unit is not None and not convertible(unit, bar):
            problems.append(f"output {output!r} is in {unit.name!r}, not a pressure")
        out_port = FmuPort(output, var.valueReference, "clutch_pressure_bar", unit, bar, None)
    if problems:
        raise FmuError(f"{path}: cannot use this FMU as the physics model", problems)
    return FmuInterface(
        path=path,
        model_description=md,
        inputs=tuple(ports),
        output=out_port,
        outputs={n: v.valueReference for n, v in outs.items()},
        parameters={v.name: v.valueReference for v in variables if v.causality == "parameter"},
        clutchlab=str(md.generationTool or "").startswith("clutchlab"),
        can_interpolate_inputs=bool(md.coSimulation.canInterpolateInputs),
        unfed=unfed,
    )
