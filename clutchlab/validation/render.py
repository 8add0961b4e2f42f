"""Check that a report renders in headless Chromium with every figure visible; screenshot it.

The report carries a small script that, once the page has loaded, writes on ``<body>`` how
many figures it has (``data-figures``: PNG images and interactive Plotly plots) and how many
are drawn (``data-figures-visible``: an image decoded and laid out with a non-zero size, a
plot that plotly.js turned into a ``.js-plotly-plot`` with an ``svg.main-svg`` of non-zero
size), and the plots alone (``data-plots``, ``data-plots-drawn``). :func:`load_page` reads
them from the DOM that headless Chromium serializes — by default with the network disabled
(every host name unresolvable, every request sent to a closed proxy), so a page that needs
anything but its own file shows it as figures not drawn. :func:`check_rendering` also writes
a full-page screenshot beside the report.

The browser is ``$CLUTCHLAB_CHROMIUM`` when set, else the first of :data:`BROWSERS` on
``PATH``, else ``/usr/bin/chromium``.

Command line::

    python -m clutchlab.validation.render clutchlab-demo/report.html
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ClutchlabError

__all__ = [
    "BROWSERS",
    "BROWSER_ENV",
    "OFFLINE_FLAGS",
    "PageLoad",
    "RenderCheck",
    "check_rendering",
    "find_browser",
    "load_page",
]

#: Environment variable naming the Chromium executable to use.
BROWSER_ENV = "CLUTCHLAB_CHROMIUM"

#: Executable names tried, in order, for a headless Chromium.
BROWSERS: tuple[str, ...] = (
    "chromium-headless-shell",
    "chromium",
    "chromium-browser",
    "google-chrome",
    "google-chrome-stable",
)


#: Fallback path (Debian's ``chromium`` package) when none of :data:`BROWSERS` is on PATH.
_DEBIAN_CHROMIUM = "/usr/bin/chromium"

#: Chromium flags that cut the page off the network: no host name resolves, every request
#: goes to a closed local port, and the browser's own background traffic is off. ``file://``
#: pages load as usual.
OFFLINE_FLAGS: tuple[str, ...] = (
    "--host-resolver-rules=MAP * ~NOTFOUND",
    "--proxy-server=http://127.0.0.1:9",
    "--proxy-bypass-list=<-loopback>",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
)


def find_browser() -> str | None:
    """The headless Chromium to use, or None when there is none.

    ``$CLUTCHLAB_CHROMIUM`` when set (an executable path or a name on PATH; one that does not
    exist gives None, never a silent fallback), else the first of :data:`BROWSERS` on PATH,
    else ``/usr/bin/chromium`` when present.

    Returns
    -------
    str or None
        Path of the executable.
    """
    env = os.environ.get(BROWSER_ENV, "").strip()
    if env:
        return shutil.which(env)
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return shutil.which(_DEBIAN_CHROMIUM)


@dataclass(frozen=True)
class PageLoad:
    """What headless Chromium saw after loading a report.

    Attributes
    ----------
    figures : int
        Figures in the page: PNG images and interactive plots.
    visible : int
        Figures drawn: images decoded and laid out, plots drawn by plotly.js, non-zero size.
    plots : int
        Interactive (Plotly) plot containers.
    plots_drawn : int
        Plot containers that plotly.js drew (``.js-plotly-plot`` with an ``svg.main-svg``).
    page_height_px : int
        Height of the laid-out page, px.
    offline : bool
        Whether the page was loaded with the network disabled (:data:`OFFLINE_FLAGS`).
    dom : str
        The DOM serialized after load (not in ``repr``).
    """

    figures: int
    visible: int
    plots: int
    plots_drawn: int
    page_height_px: int
    offline: bool
    dom: str = field(repr=False)


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
    plots : int
        Interactive (Plotly) plots among the figures.
    plots_drawn : int
        Plots that plotly.js drew.
    offline : bool
        Whether the page was loaded with the network disabled.
    """

    figures: int
    visible: int
    screenshot: Path
    size_px: tuple[int, int]
    plots: int = 0
    plots_drawn: int = 0
    offline: bool = True

    @property
    def ok(self) -> bool:
        """Whether there are figures and every one is visible."""
        return self.figures > 0 and self.visible == self.figures


def _run(browser: str, args: list[str], timeout: float, offline: bool) -> str:
    with tempfile.TemporaryDirectory(prefix="clutchlab-chromium-") as profile:
        cmd = [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            f"--user-data-dir={profile}",
            *(OFFLINE_FLAGS if offline else ()),
            *args,
        ]
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as exc:
            raise ClutchlabError(f"{browser} did not finish within {timeout:g} s") from exc
    if res.returncode != 0:
        raise ClutchlabError(f"{browser} failed ({res.returncode}): {res.stderr[-2000:]}")
    return res.stdout


def _browser(browser: str | None) -> str:
    found = browser or find_browser()
    if found is None:
        env = os.environ.get(BROWSER_ENV, "").strip()
        where = (
            f"${BROWSER_ENV}={env!r} is not an executable"
            if env
            else f"tried ${BROWSER_ENV}, {', '.join(BROWSERS)} on PATH and {_DEBIAN_CHROMIUM}"
        )
        raise ClutchlabError(
            f"no headless Chromium found ({where}); on Debian: apt-get install chromium, "
            f"or set {BROWSER_ENV} to a Chromium executable"
        )
    return found


def _attr(dom: str, name: str) -> int | None:
    body = re.search(r"<body[^>]*>", dom)
    m = re.search(rf'\s{name}="(\d+)"', body.group(0)) if body else None
    return int(m.group(1)) if m else None


def load_page(
    report: str | Path,
    browser: str | None = None,
    offline: bool = True,
    timeout_s: float = 120.0,
) -> PageLoad:
    """Load ``report`` in headless Chromium and read the figure counts the page wrote.

    Parameters
    ----------
    report : path
        An HTML report of clutchlab (carrying the figure marker script).
    browser : str, optional
        Chromium executable; :func:`find_browser` by default.
    offline : bool
        Disable the network (:data:`OFFLINE_FLAGS`); the page's own ``file://`` URL loads.
    timeout_s : float
        Limit of the browser run, s.

    Returns
    -------
    PageLoad

    Raises
    ------
    ClutchlabError
        No browser found, the browser failed, or the page lacks the figure marker.
    """
    report = Path(report).resolve()
    exe = _browser(browser)
    dom = _run(
        exe, ["--virtual-time-budget=10000", "--dump-dom", report.as_uri()], timeout_s, offline
    )
    figures, visible = _attr(dom, "data-figures"), _attr(dom, "data-figures-visible")
    if figures is None or visible is None:
        raise ClutchlabError(f"{report}: no figure marker on <body> after load")
    return PageLoad(
        figures=figures,
        visible=visible,
        plots=_attr(dom, "data-plots") or 0,
        plots_drawn=_attr(dom, "data-plots-drawn") or 0,
        page_height_px=_attr(dom, "data-page-height") or 0,
        offline=offline,
        dom=dom,
    )


def check_rendering(
    report: str | Path,
    screenshot: str | Path | None = None,
    browser: str | None = None,
    width_px: int = 1280,
    timeout_s: float = 120.0,
    offline: bool = True,
) -> RenderCheck:
    """Render ``report`` in headless Chromium: count drawn figures, write a screenshot.

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
    offline : bool
        Load the page with the network disabled (:data:`OFFLINE_FLAGS`), for both the count
        and the screenshot.

    Returns
    -------
    RenderCheck

    Raises
    ------
    ClutchlabError
        No browser found, the browser failed, or the report lacks the figure marker.
    """
    report = Path(report).resolve()
    exe = _browser(browser)
    page = load_page(report, exe, offline, timeout_s)
    height = min(page.page_height_px + 40 if page.page_height_px else 8000, 16384)
    shot = Path(screenshot) if screenshot else report.with_name("report_screenshot.png")
    _run(
        exe,
        [
            f"--window-size={width_px},{height}",
            "--virtual-time-budget=10000",
            f"--screenshot={shot.resolve()}",
            report.as_uri(),
        ],
        timeout_s,
        offline,
    )
    head = shot.read_bytes()[:24]
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        raise ClutchlabError(f"{shot}: the browser wrote no PNG")
    size = struct.unpack(">II", head[16:24])
    return RenderCheck(
        page.figures,
        page.visible,
        shot,
        (int(size[0]), int(size[1])),
        page.plots,
        page.plots_drawn,
        offline,
    )


def main(argv: list[str] | None = None) -> int:
    """``python -m clutchlab.validation.render REPORT [--screenshot PNG]``."""
    p = argparse.ArgumentParser(prog="python -m clutchlab.validation.render", description=__doc__)
    p.add_argument("report", help="report.html")
    p.add_argument("--screenshot", help="PNG to write (default: beside the report)")
    p.add_argument("--browser", help=f"Chromium executable (default: ${BROWSER_ENV}, PATH)")
    p.add_argument("--online", action="store_true", help="leave the network on (default: disabled)")
    args = p.parse_args(argv)
    check = check_rendering(args.report, args.screenshot, args.browser, offline=not args.online)
    print(
        f"{check.visible} of {check.figures} figures visible ({check.plots_drawn} of "
        f"{check.plots} interactive plots drawn), network "
        f"{'disabled' if check.offline else 'enabled'}; screenshot {check.screenshot} "
        f"({check.size_px[0]}×{check.size_px[1]} px)"
    )
    return 0 if check.ok else 1


if __name__ == "__main__":
    sys.exit(main())
