"""Build an FMU from an :class:`FmuProgram`: CasADi C, the FMI wrapper, gcc, zip.

Layout of the archive::

    modelDescription.xml
    binaries/<platform>/<id>.so        (compiled here, -O3, only FMI symbols exported)
    sources/<id>_casadi.c / .h         (CasADi code generation of the program's functions)
    sources/<id>_fmu.c                 (FMI 2.0 co-simulation wrapper)
    sources/fmi2*.h                    (FMI 2.0 headers, from FMPy)
    resources/<id>_constants.bin       (large arrays of ML models, float64, if any)

The sources are complete: ``gcc -shared -fPIC -O3 sources/*.c -lm`` rebuilds the binary
on another platform (a HIL target), which then goes into ``binaries/<its platform>/``.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path

import casadi as ca
import fmpy

from ... import __version__
from ...data import write_file_atomic
from ..integrator import cache_dir
from .csource import wrapper_source
from .description import model_description_xml
from .errors import FmuError
from .program import FmuProgram

__all__ = ["build_fmu", "fmi_headers_dir"]

_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")


def fmi_headers_dir() -> Path:
    """Folder of the FMI 2.0 C headers shipped with FMPy."""
    return Path(fmpy.__file__).parent / "c-code"


def _compiler() -> str:
    cc = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")
    if cc is None:
        raise FmuError("cannot build an FMU: no C compiler found (set CC or install gcc)")
    return cc


def _generate_casadi(program: FmuProgram, folder: Path) -> tuple[str, str]:
    stem = f"{program.name}_casadi"
    cg = ca.CodeGenerator(f"{stem}.c", {"with_header": True, "with_export": False})
    for fn in program.functions().values():
        cg.add(fn)
    cg.generate(str(folder) + os.sep)
    return f"{stem}.c", f"{stem}.h"


def _guid(program: FmuProgram, code: bytes) -> str:
    h = hashlib.sha1(code)
    for var in (*program.inputs, *program.outputs, *program.parameters):
        h.update(repr((var.name, var.unit, var.start, var.min, var.max)).encode())
    h.update(repr(sorted(program.annotations.items())).encode())
    h.update(program.constants_blob())
    return "{" + str(uuid.UUID(h.hexdigest()[:32])) + "}"


def _compile(sources: Path, names: list[str], out: Path, opt: str) -> None:
    """Compile (cached by the sources' hash) into ``out``."""
    h = hashlib.sha1(opt.encode() + ca.__version__.encode())
    for n in sorted(names):
        h.update((sources / n).read_bytes())
    cached = cache_dir() / "fmu" / f"{out.stem}_{h.hexdigest()[:16]}{out.suffix}"
    if not cached.exists():
        cached.parent.mkdir(parents=True, exist_ok=True)
        part = cached.with_suffix(f".{os.getpid()}.part")
        cmd = [
            _compiler(),
            opt,
            "-shared",
            "-fPIC",
            "-fvisibility=hidden",
            "-I",
            str(sources),
            "-o",
            str(part),
            *(str(sources / n) for n in names if n.endswith(".c")),
            "-lm",
        ]
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0:
            raise FmuError(
                f"compiling the FMU binary failed ({' '.join(cmd[:2])} …)",
                res.stderr.strip().splitlines()[-20:],
            )
        part.replace(cached)
    shutil.copyfile(cached, out)


def build_fmu(
    program: FmuProgram, path: str | Path, opt: str = "-O3", validate: bool = True
) -> Path:
    """Generate, compile and package ``program`` as an FMI 2.0 co-simulation FMU.

    Parameters
    ----------
    program : FmuProgram
        What the FMU computes.
    path : path-like
        The ``.fmu`` file to write (replaced atomically).
    opt : str
        gcc optimization flag.
    validate : bool
        Check the result with :func:`fmpy.validation.validate_fmu` and raise on any problem.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    FmuError
        No C compiler, a compilation error, or a validation problem (all listed).
    """
    path = Path(path)
    if path.suffix.lower() != ".fmu":
        raise FmuError(f"{path}: the file name must end in .fmu")
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        src = root / "sources"
        src.mkdir()
        c_name, h_name = _generate_casadi(program, src)
        guid = _guid(program, (src / c_name).read_bytes())
        wrapper = f"{program.name}_fmu.c"
        (src / wrapper).write_text(wrapper_source(program, guid, __version__), encoding="utf-8")
        for header in _HEADERS:
            shutil.copyfile(fmi_headers_dir() / header, src / header)
        names = [c_name, h_name, wrapper, *_HEADERS]
        binaries = root / "binaries" / fmpy.platform
        binaries.mkdir(parents=True)
        _compile(src, names, binaries / f"{program.name}{fmpy.sharedLibraryExtension}", opt)
        if program.constants:
            (root / "resources").mkdir()
            (root / "resources" / f"{program.name}_constants.bin").write_bytes(
                program.constants_blob()
            )
        xml = model_description_xml(program, guid, (wrapper, c_name))
        (root / "modelDescription.xml").write_text(xml, encoding="utf-8")

        def package(part: Path) -> None:
            # the archive is validated under its temporary name: an FMU that does not
            # validate never replaces ``path``
            with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
                for file in sorted(root.rglob("*")):
                    if file.is_file():
                        zf.write(file, file.relative_to(root).as_posix())
            if validate:
                from fmpy.validation import validate_fmu

                problems = validate_fmu(str(part))
                if problems:
                    raise FmuError(f"{path}: the exported FMU does not validate", problems)

        write_file_atomic(path, package, overwrite=True)
    return path
