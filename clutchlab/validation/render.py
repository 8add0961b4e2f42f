"""Check that a report renders in headless Chromium with every figure visible; screenshot it.

The report carries a small script that, once the page has loaded, writes on ``<body>`` how
many figures it has (``data-figures``) and how many were decoded and laid out with a
non-zero size (``data-figures-visible``). :func:`check_rendering` reads both from the DOM
that headless Chromium serializes, and writes a full-page screenshot beside the report.

Command line::

    python -m clutchlab.validation.render clutchlab-demo/report.html
"""

from __future__ import annotations

import argparse
import re
import shutil
import struct
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from ..errors import ClutchlabError

__all__ = ["BROWSERS", "RenderCheck", "check_rendering", "find_browser"]

#: Executable names tried, in order, for a headless Chromium.
BROWSERS: tuple[str, ...] = (
    "chromium-headless-shell",
    "chromium",
    "chromium-browser",
    "google-chrome",
    "google-chrome-stable",
)


def find_browser() -> str | None:
    """Path of the first headless-capable Chromium on PATH (see :data:`BROWSERS`), or None."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass(frozen=True)
class RenderCheck:
    """What headless Chromium saw.

    Attributes
    ----------
    figures : int
        Figures (images) in the report.
    visible : int
        Figures decoded and laid out with a non-zero size.
    screenshot : Path
        Full-page PNG written beside the report.
    size_px : tuple of int
        Width and height of the screenshot, px.
    """

    figures: int
    visible: int
    screenshot: Path
    size_px: tuple[int, int]

    @property
    def ok(self) -> bool:
        """Whether there are figures and every one is visible."""
        return self.figures > 0 and self.visible == self.figures


def _run(browser: str, args: list[str], timeout: float) -> str:
    cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", *args]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if res.returncode != 0:
        raise ClutchlabError(f"{browser} failed ({res.returncode}): {res.stderr[-2000:]}")
    return res.stdout


def check_rendering(
    report: str | Path,
    screenshot: str | Path | None = None,
    browser: str | None = None,
    width_px: int = 1280,
    timeout_s: float = 120.0,
) -> RenderCheck:
    """Render ``report`` in headless Chromium: count visible figures, write a screenshot.

    Parameters
    ----------
    report : path
        ``report.html``.
    screenshot : path, optional
        PNG to write; ``report_screenshot.png`` beside the report by default.
    browser : str, optional
        Chromium executable; :func:`find_browser` by default.
    width_px : int
        Window width, px; the height is the page's (capped at 16 384 px).
    timeout_s : float
        Limit per browser run, s.

    Returns
    -------
    RenderCheck

    Raises
    ------
    ClutchlabError
        No browser found, the browser failed, or the report lacks the figure marker.
    """
    report = Path(report).resolve()
    browser = browser or find_browser()
    if browser is None:
        raise ClutchlabError(
            f"no headless Chromium found (tried {', '.join(BROWSERS)}); on Debian: "
            "apt-get install chromium-headless-shell"
        )
    url = report.as_uri()
    dom = _run(browser, ["--virtual-time-budget=10000", "--dump-dom", url], timeout_s)
    m = re.search(r"<body[^>]*data-figures=\"(\d+)\"[^>]*data-figures-visible=\"(\d+)\"", dom)
    if m is None:
        raise ClutchlabError(f"{report}: no figure marker on <body> after load")
    figures, visible = int(m.group(1)), int(m.group(2))
    h = re.search(r"data-page-height=\"(\d+)\"", dom)
    height = min(int(h.group(1)) + 40 if h else 8000, 16384)
    shot = Path(screenshot) if screenshot else report.with_name("report_screenshot.png")
    _run(
        browser,
        [
            f"--window-size={width_px},{height}",
            "--virtual-time-budget=10000",
            f"--screenshot={shot.resolve()}",
            url,
        ],
        timeout_s,
    )
    head = shot.read_bytes()[:24]
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        raise ClutchlabError(f"{shot}: the browser wrote no PNG")
    size = struct.unpack(">II", head[16:24])
    return RenderCheck(figures, visible, shot, (int(size[0]), int(size[1])))


def main(argv: list[str] | None = None) -> int:
    """``python -m clutchlab.validation.render REPORT [--screenshot PNG]``."""
    p = argparse.ArgumentParser(prog="python -m clutchlab.validation.render", description=__doc__)
    p.add_argument("report", help="report.html")
    p.add_argument("--screenshot", help="PNG to write (default: beside the report)")
    p.add_argument("--browser", help="Chromium executable")
    args = p.parse_args(argv)
    check = check_rendering(args.report, args.screenshot, args.browser)
    print(
        f"{check.visible} of {check.figures} figures visible; screenshot {check.screenshot} "
        f"({check.size_px[0]}×{check.size_px[1]} px)"
    )
    return 0 if check.ok else 1


if __name__ == "__main__":
    sys.exit(main())
