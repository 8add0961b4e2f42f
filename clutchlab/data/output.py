"""Safe output: every file and folder clutchlab writes goes through here.

Three guarantees, for every command that uses these helpers:

1. **Atomic.** A file is written to a temporary sibling and renamed into place; a folder is
   built complete in a temporary sibling and swapped in with one atomic exchange
   (``renameat2(RENAME_EXCHANGE)`` on Linux). A run killed at any point leaves either the old
   output or the new one, never a mixture and never nothing.
2. **Only what we wrote is replaced or deleted.** A folder clutchlab writes carries an
   ownership record (:data:`OWNED_NAME`) listing the files it wrote. When the folder is
   written again, files it does not list (a user's ``notes.txt``, a ``sub/keep.txt``) are
   carried over into the new folder untouched (hard links, so not even copied); a user's file
   in the way of one clutchlab would write is refused with its name, never overwritten.
   Files clutchlab wrote before and no longer writes (stale figures) go.
3. **Checked before the work.** :func:`check_output` tells at once, before an expensive run,
   that an output exists, is a folder where a file is expected (or the reverse), or lies in a
   folder that cannot be written.

Errors are :class:`~clutchlab.errors.OutputError` (an ``OSError``) naming the path.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import functools
import json
import os
import shutil
import signal
import stat
import tempfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import OutputError

__all__ = [
    "OWNED_NAME",
    "atomic_file_writer",
    "check_folder_files",
    "check_folder_kind",
    "check_output",
    "check_report_out",
    "has_ownership_record",
    "owned_files",
    "ownership_record",
    "write_file_atomic",
    "write_folder_atomic",
]

#: Name of the ownership record inside every folder clutchlab writes.
OWNED_NAME = ".clutchlab-owned.json"

#: A file's content: bytes, or a function that writes the file at the path it is given.
Content = bytes | Callable[[Path], None]

_KILL_ENV = "CLUTCHLAB_TEST_KILL_AT"


def _killpoint(name: str) -> None:
    """Fault injection for the kill tests: SIGKILL this process at a named point.

    Active only when the environment variable ``CLUTCHLAB_TEST_KILL_AT`` equals ``name``;
    the tests use it to kill a real child process at the dangerous moment.
    """
    if os.environ.get(_KILL_ENV) == name:
        os.kill(os.getpid(), signal.SIGKILL)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output(
    path: str | Path,
    *,
    kind: str = "file",
    overwrite: bool = False,
    what: str = "output",
    whole: bool = False,
) -> Path:
    """Check an output location before any work is done.

    Parameters
    ----------
    path : path-like
        The file or folder to be written.
    kind : {"file", "folder"}
        What will be written there.
    overwrite : bool
        Whether an existing file may be replaced, or a non-empty folder written into (what
        clutchlab wrote there is replaced, every other file is kept).
    what : str
        Name of the output in messages (e.g. ``"--out"``).
    whole : bool
        The folder is written whole by :func:`write_folder_atomic` (swapped in): it must not
        be the current working folder or hold it.

    Returns
    -------
    pathlib.Path
        ``path`` as a Path.

    Raises
    ------
    OutputError
        The path is a folder where a file is expected or the reverse, exists (a file, without
        ``overwrite``), or lies under something that is not a writable folder.
    """
    if kind not in ("file", "folder"):
        raise ValueError(f"kind must be 'file' or 'folder', not {kind!r}")
    path = Path(path)
    if kind == "file":
        if path.is_dir():
            raise OutputError(f"{what} {path}: is a folder; a file name is expected")
        if path.exists() or path.is_symlink():
            if not overwrite:
                raise OutputError(f"{what} {path}: exists (pass --overwrite to replace it)")
            if not path.is_file():
                raise OutputError(f"{what} {path}: exists and is not a regular file")
    elif path.exists() and not path.is_dir():
        raise OutputError(f"{what} {path}: exists and is not a folder")
    elif whole and _holds_cwd(path):
        raise OutputError(
            f"{what} {path or '.'}: is the current folder or holds it; name a folder to "
            "create (a folder is written by swapping it whole, which cannot be done to the "
            "folder you are in)"
        )
    elif path.is_dir() and not overwrite and any(path.iterdir()):
        raise OutputError(
            f"{what} {path}: folder exists and is not empty (pass --overwrite to write into "
            "it: what clutchlab wrote there is replaced, every other file is kept)"
        )
    parent = _nearest_existing(path.parent if kind == "file" or not path.is_dir() else path)
    if not parent.is_dir():
        raise OutputError(f"{what} {path}: {parent} is not a folder")
    # A real probe (a temporary file created and removed where the output's temporary
    # sibling will go): it also catches read-only file systems and ACLs, and works as root.
    holder = parent if parent != path else path.parent
    try:
        fd, probe = tempfile.mkstemp(prefix=".clutchlab-probe.", dir=holder)
    except OSError as exc:
        raise OutputError(
            f"{what} {path}: cannot write into {holder} ({exc.strerror or exc})"
        ) from exc
    os.close(fd)
    os.unlink(probe)
    return path


def _holds_cwd(path: Path) -> bool:
    """Whether ``path`` is the current working folder or one of its parents."""
    try:
        here, there = Path.cwd().resolve(), path.resolve()
    except OSError:
        return False
    return there == here or there in here.parents


def _write_content(target: Path, content: Content) -> None:
    if callable(content):
        content(target)
    else:
        with open(target, "wb") as fh:
            fh.write(content)
            fh.flush()
            os.fsync(fh.fileno())


def write_file_atomic(path: str | Path, content: Content, *, overwrite: bool = False) -> Path:
    """Write one file atomically (temporary sibling, then rename).

    Parameters
    ----------
    path : path-like
        Destination file.
    content : bytes or callable
        The bytes, or a function ``f(tmp_path)`` that writes the file.
    overwrite : bool
        Replace an existing file; without it an existing file is an error.

    Returns
    -------
    pathlib.Path
        The destination.

    Raises
    ------
    OutputError
        As :func:`check_output`, or an operating-system error while writing (nothing is
        left behind then).
    """
    path = check_output(path, kind="file", overwrite=overwrite)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    os.close(fd)
    tmp = Path(name)
    try:
        _write_content(tmp, content)
        os.chmod(tmp, 0o666 & ~_umask())
        _killpoint("file-before-rename")
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_file_writer(write_to: Callable[..., Any]) -> Callable[..., Path]:
    """Make a public ``write_x(obj, path, ...)`` function write its file atomically.

    The decorated function writes at the path it is given; the wrapper hands it
    :func:`write_file_atomic`'s temporary sibling and renames that into place, replacing an
    existing file only once the new one is complete. A failure (or a kill) leaves the earlier
    file byte for byte; a folder at the path is an :class:`~clutchlab.errors.OutputError`.

    Parameters
    ----------
    write_to : callable
        ``write_to(obj, path, *args, **kwargs)``; writes one complete file at ``path``.

    Returns
    -------
    callable
        ``write(obj, path, *args, **kwargs) -> pathlib.Path`` (the destination).
    """

    @functools.wraps(write_to)
    def write(obj: Any, path: str | Path, *args: Any, **kwargs: Any) -> Path:
        return write_file_atomic(
            path, lambda tmp: write_to(obj, tmp, *args, **kwargs), overwrite=True
        )

    return write


def ownership_record(files: list[str] | tuple[str, ...], kind: str, **extra: str) -> bytes:
    """The content of a folder's :data:`OWNED_NAME`: who wrote it, what it is, its files.

    Parameters
    ----------
    files : sequence of str
        Relative POSIX paths clutchlab wrote there.
    kind : str
        What the folder is (``"dataset folder"``, ``"report folder"``, ``"sweep parts"`` …);
        another kind of output is not written into it (:func:`check_folder_kind`).
    **extra : str
        Further descriptions (a sweep's part-file pattern).
    """
    record = {"written_by": "clutchlab", "kind": kind, "files": sorted(files), **extra}
    return (json.dumps(record, indent=1) + "\n").encode("utf-8")


def has_ownership_record(folder: str | Path) -> bool:
    """Whether ``folder`` holds a readable ownership record that clutchlab wrote."""
    record = Path(folder) / OWNED_NAME
    if not record.is_file() or record.is_symlink():
        return False
    try:
        doc = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("written_by") == "clutchlab"


def owned_files(folder: str | Path) -> set[str]:
    """The files (relative POSIX paths) clutchlab recorded as written in ``folder``."""
    return _ownership(folder)[0]


def _ownership(folder: str | Path) -> tuple[set[str], str | None]:
    """The files clutchlab recorded as written in ``folder``, and what it wrote there.

    The kind is the ``what`` of :func:`write_folder_atomic` (``"dataset folder"``, ``"report
    folder"`` …); records written before it was kept are recognized by their files (a
    ``manifest.json``: a dataset; a ``report.html`` or ``report.md``: a report), else None.
    """
    record = Path(folder) / OWNED_NAME
    if not record.is_file():
        return set(), None
    try:
        doc = json.loads(record.read_text(encoding="utf-8"))
        files = doc["files"]
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            raise TypeError("files is not a list of names")
    except (OSError, ValueError, KeyError, TypeError):
        return set(), None  # an unreadable record owns nothing: everything is kept
    kind = doc.get("kind") if isinstance(doc.get("kind"), str) else None
    if kind == "--out" and "classifiers.csv" in files:  # recorded so before it had a name
        kind = "classifier comparison folder"
    if kind is None and "manifest.json" in files:
        kind = "dataset folder"
    elif kind is None and {"report.html", "report.md"} & set(files):
        kind = "report folder"
    return {f for f in files if _safe_relative(f)}, kind


def _safe_relative(name: str) -> bool:
    p = Path(name)
    return bool(name) and not p.is_absolute() and ".." not in p.parts and name != OWNED_NAME


def _tree(folder: Path) -> list[str]:
    """Every file, symlink and empty folder under ``folder`` (relative POSIX paths)."""
    out = []
    for root, dirs, files in os.walk(folder, followlinks=False):
        rel_root = Path(root).relative_to(folder)
        for d in list(dirs):
            full = Path(root) / d
            if full.is_symlink():
                out.append((rel_root / d).as_posix())
                dirs.remove(d)
        if not dirs and not files and rel_root != Path("."):
            out.append(rel_root.as_posix() + "/")
        out.extend((rel_root / f).as_posix() for f in files)
    return [o for o in out if o != OWNED_NAME]


def _clashes(kept: str, new: set[str]) -> bool:
    """Whether a kept (user's) path stands where a new file or its folder would go."""
    name = kept.rstrip("/")
    new_dirs = {p.as_posix() for n in new for p in Path(n).parents if p != Path(".")}
    if name in new:
        return True  # a user's file (or folder) where clutchlab would write a file
    if not kept.endswith("/") and name in new_dirs:
        return True  # a user's file where clutchlab needs a folder
    return any(name.startswith(n + "/") for n in new)  # a folder where a file would go


def _carry_over(src: Path, dst: Path, names: list[str]) -> None:
    """Hard-link (or copy) the user's files ``names`` from ``src`` into ``dst``."""
    for name in names:
        if name.endswith("/"):
            (dst / name).mkdir(parents=True, exist_ok=True)
            continue
        s, d = src / name, dst / name
        d.parent.mkdir(parents=True, exist_ok=True)
        if s.is_symlink():
            os.symlink(os.readlink(s), d)
            continue
        try:
            os.link(s, d, follow_symlinks=False)
        except OSError:
            shutil.copy2(s, d, follow_symlinks=False)


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths (Linux ``renameat2``); False where unsupported."""
    libc_name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(libc_name, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError, TypeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _recover(path: Path) -> None:
    """Restore a folder left half-swapped by the rename fallback of a killed run."""
    if path.exists():
        return
    backups = sorted(path.parent.glob(f".{path.name}.*.old"))
    for backup in backups:
        if (backup / OWNED_NAME).is_file():
            os.replace(backup, path)
            return


def check_folder_kind(path: str | Path, what: str) -> None:
    """Refuse to write a ``what`` into a folder that holds another kind of clutchlab output.

    A folder clutchlab wrote records what it is (:func:`write_folder_atomic`'s ``what``).
    Writing another kind there (a report into a dataset folder) would count the dataset's
    files as the report's stale files and remove them; so it is refused.

    Raises
    ------
    OutputError
        Naming the folder, what it holds and how many files.
    """
    owned, kind = _ownership(path)
    if kind is not None and kind != what and owned:
        raise OutputError(
            f"{what} {path}: holds a {kind} clutchlab wrote ({len(owned)} files); writing a "
            f"{what} there would replace it; choose another folder"
        )


def check_report_out(
    path: str | Path, names: Iterable[str], *, kind: str, what: str = "--out"
) -> None:
    """Refuse, before any work, a report folder that writing the report would refuse.

    Parameters
    ----------
    path : path-like
        The report folder (nothing but its parents need exist yet).
    names : iterable of str
        The report's fixed files (relative POSIX paths).
    kind : str
        The folder's kind in its ownership record (e.g. ``"report folder"``).
    what : str
        How the folder is named in messages (the option, ``--out``).

    Raises
    ------
    OutputError
        A file, the current folder or one holding it (the folder is swapped whole), another
        kind of clutchlab output, or a user's file where one of ``names`` would go.
    """
    check_output(path, kind="folder", overwrite=True, what=what, whole=True)
    check_folder_kind(path, kind)
    check_folder_files(path, names, what=kind)


def check_folder_files(
    path: str | Path, names: Iterable[str], *, what: str = "output"
) -> list[str]:
    """Refuse a folder that :func:`write_folder_atomic` would refuse for ``names``: a
    command calls this before its work, the write again when writing.

    Parameters
    ----------
    path : path-like
        The output folder (nothing to check when it does not exist yet).
    names : iterable of str
        Relative POSIX paths of files that will be written there.
    what : str
        Name (and kind) of the output, as given to :func:`write_folder_atomic`.

    Returns
    -------
    list of str
        The files (relative POSIX paths) clutchlab did not write there: kept by a write.

    Raises
    ------
    OutputError
        The folder holds another kind of clutchlab output (:func:`check_folder_kind`), or a
        file clutchlab did not write stands where one of ``names`` would go (all listed).
    """
    path = Path(path)
    if not path.is_dir():
        return []
    check_folder_kind(path, what)
    owned = owned_files(path)
    keep = [n for n in _tree(path) if n not in owned]
    clash = sorted(k for k in keep if _clashes(k, set(names)))
    if clash:
        raise OutputError(
            f"{what} {path}: clutchlab did not write these files and would replace them; "
            "move them away or choose another folder: " + ", ".join(clash)
        )
    return keep


def write_folder_atomic(
    path: str | Path,
    files: Mapping[str, Content],
    *,
    overwrite: bool = False,
    what: str = "output",
) -> Path:
    """Write a folder of files atomically, keeping every file clutchlab did not write.

    Parameters
    ----------
    path : path-like
        Destination folder.
    files : mapping of str to bytes or callable
        Relative POSIX path → content (bytes, or ``f(tmp_path)`` writing the file).
    overwrite : bool
        Allow writing into an existing non-empty folder: the files clutchlab recorded as its
        own there are replaced or removed, every other file is kept.
    what : str
        Name of the output in messages.

    Returns
    -------
    pathlib.Path
        The destination folder.

    Raises
    ------
    OutputError
        The destination is not a writable folder location, or a file clutchlab did not write
        stands where it would write one (listed; nothing is changed then).
    """
    path = Path(path)
    bad = [n for n in files if not _safe_relative(n)]
    if bad:
        raise ValueError(f"output names must be relative and inside the folder: {bad}")
    with contextlib.suppress(OSError):
        _recover(path)
    check_output(path, kind="folder", overwrite=overwrite, what=what, whole=True)
    exists = path.is_dir()
    keep = check_folder_files(path, list(files), what=what)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    except OSError as exc:
        raise OutputError(f"{what} {path}: cannot write: {exc.strerror or exc}") from exc
    try:
        mode = 0o777 & ~_umask()
        if exists:
            mode = stat.S_IMODE(path.stat().st_mode)
        os.chmod(tmp, mode)
        for name, content in files.items():
            target = tmp / name
            target.parent.mkdir(parents=True, exist_ok=True)
            _write_content(target, content)
        (tmp / OWNED_NAME).write_bytes(ownership_record(list(files), what))
        if exists:
            _carry_over(path, tmp, keep)
        _killpoint("folder-before-swap")
        if not exists:
            os.rename(tmp, path)
        elif _exchange(tmp, path):
            _killpoint("folder-after-swap")
            shutil.rmtree(tmp, ignore_errors=True)  # the old content, user files linked over
        else:  # no atomic exchange here: two renames, recovered by the next write
            backup = tmp.with_name(tmp.name[: -len(".tmp")] + ".old")
            os.replace(path, backup)
            _killpoint("folder-between-renames")
            os.replace(tmp, path)
            shutil.rmtree(backup, ignore_errors=True)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"{what} {path}: cannot write: {exc.strerror or exc}") from exc
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path
