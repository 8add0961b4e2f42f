"""The fixed files of a comparison report folder (``clutchlab evaluate`` / ``clutchlab demo``).

A constants-only module (no imports), so the command-line parser and the validation layer
read the same names without loading the numerical stack.
"""

from __future__ import annotations

__all__ = ["REPORT_FILES"]

#: The fixed files of a comparison report (``figures/`` beside them varies); a user's file
#: of one of these names in the report folder is refused before any work.
REPORT_FILES = ("report.html", "report.md", "metrics.json", "metrics.csv")
