"""Keys of generated model code by the source that generates it.

The compile cache (:mod:`~clutchlab.physics.integrator`) names a library by the hash of its
generated C code, which is exact but needs the code first: the symbolic model, the ROS2 step
and (for a fit) their forward sensitivities are built and the C written out before the hash
says the library is already there. For a discovery that is ~0.5 s per candidate model, every
time, although nothing changed.

A *source key* names the same code by what produces it: the Python source of
``clutchlab.physics`` (every ``.py`` file under the package, all of them, so an edit anywhere
in it counts; read when the package is imported, so it is the source this process runs),
the loaded code of the model's component and effect classes that live outside the package
(a user's own: the byte code of their methods and of the functions of their module, so
what this process runs, not a file edited since), the model's structure, the CasADi
version, the function's name, its cache tag and the compiler options. Equal keys mean the
same generator ran on the same input, so the code hash recorded under a key the first time
is the one the code would hash to again. Changed code gives a new key, and the code is
built and hashed as before: a source key can miss a library that is there, never load a
stale one.
"""

from __future__ import annotations

import hashlib
import marshal
import sys
import types
from pathlib import Path

import casadi as ca

from .model import CircuitModel

__all__ = ["code_source_key", "package_source_digest"]

_PACKAGE = Path(__file__).resolve().parent


def _package_digest() -> str:
    h = hashlib.sha1(ca.__version__.encode())
    for path in sorted(_PACKAGE.rglob("*.py")):
        h.update(path.relative_to(_PACKAGE).as_posix().encode())
        h.update(hashlib.sha1(path.read_bytes()).digest())
    return h.hexdigest()


#: Read once, when the package is imported (:func:`package_source_digest`).
_PACKAGE_DIGEST = _package_digest()


def package_source_digest() -> str:
    """SHA-1 (hex) over the path and content of every ``.py`` file of ``clutchlab.physics``
    as this process imported it, and the CasADi version."""
    return _PACKAGE_DIGEST


def _outside(cls: type) -> bool:
    """``cls`` is not the package's (nor built in): its code must go into the key."""
    if cls.__module__ == "builtins":
        return False
    path = getattr(sys.modules.get(cls.__module__), "__file__", None)
    return path is None or _PACKAGE not in Path(path).resolve().parents


def _loaded_code(h, cls: type) -> None:
    """Fold the loaded byte code of ``cls`` (its classes outside the package) into ``h``:
    their methods and attributes, and the functions defined in their modules."""
    seen = set()
    for klass in cls.__mro__:
        if not _outside(klass):
            continue
        module = sys.modules.get(klass.__module__)
        spaces = [(vars(klass), True)] + ([(vars(module), False)] if module is not None else [])
        for space, own in spaces:
            for name, obj in sorted(space.items()):
                if isinstance(obj, (staticmethod, classmethod)):
                    obj = obj.__func__
                if isinstance(obj, types.FunctionType):
                    if id(obj) not in seen and obj.__module__ == klass.__module__:
                        seen.add(id(obj))
                        h.update(name.encode() + marshal.dumps(obj.__code__))
                elif own and not name.startswith("__"):
                    h.update(f"{name}={obj!r}".encode())


def code_source_key(model: CircuitModel, name: str, tag: str, opt: str) -> str:
    """Key of the code of function ``name`` generated for ``model`` (16 hex digits).

    Parameters
    ----------
    model : CircuitModel
        The model the code is generated from.
    name : str
        Name of the generated function (it carries, e.g., the chunk length).
    tag : str
        The compile cache's tag (model structure, drive mode, substeps, directions).
    opt : str
        Compiler optimization flag.
    """
    h = hashlib.sha1(package_source_digest().encode())
    for obj in (*model.components, *model.effects):
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__}".encode())
        _loaded_code(h, type(obj))
    h.update("\0".join((model.key, name, tag, opt)).encode())
    return h.hexdigest()[:16]
