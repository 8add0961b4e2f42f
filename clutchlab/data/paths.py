"""Where input files may come from: inside the folder given, regular files only.

One check for every reader: a manifest's ``"file"`` / ``"channel_map"`` must name a regular
file inside the dataset folder (no absolute path, no ``..``, no symlink leading out), and any
log or map given to a reader must be a regular file (a folder, FIFO, socket or device is
named as such, and a FIFO is never opened: it would block). A refused file is never opened,
so nothing of its content reaches an error message or an output.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path, PurePath

from ..errors import DataError

__all__ = ["check_input_file", "contained_file", "file_kind_problem"]


def file_kind_problem(path: str | Path) -> str | None:
    """Why ``path`` is not a readable regular file (``"not found"``, ``"is a folder"``, …).

    Returns None for a regular file (symlinks are followed). Nothing is opened.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "not found"
    except NotADirectoryError:
        return "not found (a parent is not a folder)"
    except PermissionError:
        return "not readable (permission denied)"
    except (OSError, ValueError) as exc:
        return f"not accessible ({exc})"
    if stat.S_ISDIR(st.st_mode):
        return "is a folder, not a file"
    if stat.S_ISFIFO(st.st_mode):
        return "is not a regular file (a FIFO)"
    if stat.S_ISSOCK(st.st_mode):
        return "is not a regular file (a socket)"
    if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode):
        return "is not a regular file (a device)"
    if not stat.S_ISREG(st.st_mode):
        return "is not a regular file"
    return None


def check_input_file(path: str | Path, what: str = "file") -> Path:
    """Raise a clear ``DataError`` unless ``path`` is a regular file; return it as a Path."""
    path = Path(path)
    why = file_kind_problem(path)
    if why is not None:
        raise DataError(f"{path}: {what} {why}")
    return path


def contained_file(
    root: str | Path, value: object, where: str, what: str
) -> tuple[Path | None, str | None]:
    """Resolve a file name from a manifest inside the dataset folder ``root``.

    Parameters
    ----------
    root : path-like
        The dataset folder.
    value : object
        The manifest's value (should be a relative file name).
    where : str
        How messages name the entry (``"experiments[3]"``).
    what : str
        The key (``"file"``, ``"channel_map"``).

    Returns
    -------
    (path, None) or (None, problem)
        The path inside ``root``, or why it is refused. A refused file is never opened.
    """
    if not isinstance(value, str) or not value.strip():
        return None, f"{where}: {what!r} must be a file name, got {value!r:.80}"
    if "\0" in value:
        return None, f"{where}: {what!r} contains a NUL character"
    pure = PurePath(value)
    if pure.is_absolute() or value.startswith(("/", "\\")) or ":" in (pure.parts or ("",))[0]:
        return None, (
            f"{where}: {what!r} {value!r:.200} is an absolute path; files must be named "
            "relative to the dataset folder and lie inside it"
        )
    if ".." in pure.parts or ".." in value.replace("\\", "/").split("/"):
        return None, f"{where}: {what!r} {value!r:.200} leads out of the dataset folder ('..')"
    root = Path(root)
    path = root / value
    try:
        real, real_root = path.resolve(), root.resolve()
    except (OSError, RuntimeError) as exc:  # symlink loop
        return None, f"{where}: {what!r} {value!r:.200} cannot be resolved ({exc})"
    if not real.is_relative_to(real_root):
        return None, (
            f"{where}: {what!r} {value!r:.200} is a link that leads out of the dataset folder"
        )
    why = file_kind_problem(path)
    if why is not None:
        label = what.replace("_", " ")
        return None, f"{where}: {label} {value!r:.200} {why} ({path})"
    return path, None
