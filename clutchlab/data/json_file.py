"""A JSON object read from a file, to tell what kind of clutchlab file it is."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["read_json_object"]


def read_json_object(path: str | Path, max_bytes: int | None = None) -> dict[str, Any] | None:
    """The JSON object in ``path``, or None when there is none to read.

    Used to recognize a file before it is loaded and checked (a fit result, a parameter
    file, a saved model): what the file is decides which loader names its problems.

    Parameters
    ----------
    path : path-like
        The file.
    max_bytes : int, optional
        Larger files are not read (None: no limit).

    Returns
    -------
    dict or None
        None when the file is missing, not a regular file, larger than ``max_bytes``, not
        UTF-8 JSON, nested too deeply, or holds something other than an object.
    """
    path = Path(path)
    try:
        if max_bytes is not None and (not path.is_file() or path.stat().st_size > max_bytes):
            return None
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None
