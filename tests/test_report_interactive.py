"""Issue 19 must-show 1: the interactive report renders in headless Chromium with every Plotly
figure drawn, with the network disabled, and a screenshot is written beside the report; the
sweep page too (the discovery report's check is in ``test_discover.py``).

The browser is ``$CLUTCHLAB_CHROMIUM``, a Chromium on PATH or ``/usr/bin/chromium`` (Debian:
``apt-get install chromium``). A missing browser fails these tests with that message; they
are never skipped.
"""

from __future__ import annotations

import re
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pandas as pd
import pytest
from test_sweep_run import _spec
from test_validation_report import TINY_RAMPS

from clutchlab.physics.design.figures import _metrics
from clutchlab.physics.design.interactive import sweep_html
from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand
from clutchlab.validation import evaluate, write_report
from clutchlab.validation.interactive import MAX_POINTS, interactive_figures
from clutchlab.validation.render import check_rendering, find_browser, load_page

INTERACTIVE_KEYS = ["prediction_vs_time", "pressure_vs_current", "hysteresis_bands", "residuals"]


def _browser() -> str:
    browser = find_browser()
    assert browser is not None, (
        "no headless Chromium found: set CLUTCHLAB_CHROMIUM to a Chromium executable or "
        "install one (Debian: apt-get install chromium) — this test is the evidence that the "
        "interactive report renders, so it fails rather than skips"
    )
    return browser


@pytest.fixture(scope="module")
def evaluation():
    data = run_stand(StandConfig(settings=DEFAULT_SETTINGS[:2], ramps=TINY_RAMPS), False)
    return evaluate(data.dataset, ["physics_default"], progress=False)


@pytest.fixture(scope="module")
def report(evaluation, tmp_path_factory):
    return write_report(evaluation, tmp_path_factory.mktemp("interactive") / "report")


def test_every_interactive_figure_is_drawn_offline_with_a_screenshot(report):
    browser = _browser()
    html = report.html.read_text(encoding="utf-8")
    drawn = report.doc["figures"]["drawn"]
    assert [k for k in drawn if f"id='plot-{k}'" in html] == INTERACTIVE_KEYS
    assert html.count("* plotly.js v") == 1  # plotly.js embedded once, inline
    assert not re.search(r"<script[^>]*\ssrc=", html)  # and nothing loaded from elsewhere
    # PNGs stay beside the report for report.md.
    md = report.markdown.read_text(encoding="utf-8")
    for key in drawn:
        assert f"(figures/{key}.png)" in md and (report.folder / "figures" / f"{key}.png").is_file()

    check = check_rendering(report.html, browser=browser)  # network disabled by default
    assert check.offline
    assert check.plots == len(INTERACTIVE_KEYS) and check.plots_drawn == check.plots
    assert check.ok and check.figures == len(drawn)
    # Independently of the page's own marker: the serialized DOM holds one plotly.js plot
    # (class js-plotly-plot, with its svg.main-svg layers) per interactive figure.
    page = load_page(report.html, browser)
    containers = re.findall(r'<div[^>]*id="(plot-[a-z_]+)"[^>]*class="([^"]*)"', page.dom)
    assert [i for i, cls in containers if "js-plotly-plot" in cls.split()] == [
        f"plot-{k}" for k in INTERACTIVE_KEYS
    ]
    assert page.dom.count('class="main-svg"') >= 2 * len(INTERACTIVE_KEYS)
    # The screenshot beside the report: a PNG as wide as the window, the whole page tall.
    assert check.screenshot == report.folder / "report_screenshot.png"
    assert check.size_px[0] == 1280 and check.size_px[1] > 3000
    assert check.screenshot.stat().st_size > 50_000


class _PlotlyJs(BaseHTTPRequestHandler):
    body = b""

    def do_GET(self):  # the http.server API
        self.send_response(200)
        self.send_header("Content-Type", "text/javascript")
        self.send_header("Content-Length", str(len(self.body)))
        self.end_headers()
        self.wfile.write(self.body)

    def log_message(self, *args):
        pass


def test_disabled_network_is_really_off(report, tmp_path):
    """Control: the same page with plotly.js served over HTTP (127.0.0.1) draws its plots
    with the network on and none with it off, so "drawn offline" means self-contained."""
    browser = _browser()
    html = report.html.read_text(encoding="utf-8")
    start = html.index("<script>/**\n* plotly.js v")
    end = html.index("</script>", start) + len("</script>")
    _PlotlyJs.body = html[start + len("<script>") : end - len("</script>")].encode("utf-8")
    server = ThreadingHTTPServer(("127.0.0.1", 0), _PlotlyJs)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/plotly.js"
        remote = tmp_path / "report_remote_plotly.html"
        remote.write_text(html[:start] + f"<script src='{url}'></script>" + html[end:], "utf-8")
        online = load_page(remote, browser, offline=False)
        offline = load_page(remote, browser, offline=True)
    finally:
        server.shutdown()
        server.server_close()
    n = len(INTERACTIVE_KEYS)
    assert (online.plots, online.plots_drawn) == (n, n)
    assert (offline.plots, offline.plots_drawn) == (n, 0)


def test_traces_are_thinned_and_each_variant_is_one_legend_group(evaluation):
    figs = interactive_figures(evaluation)
    assert list(figs) == INTERACTIVE_KEYS
    for key, fig in figs.items():
        for trace in fig.data:
            assert len(trace.x) <= MAX_POINTS, key
            assert np.asarray(trace.y).dtype == np.float32, key
    # A variant (and the measurement) is one legend entry toggling all of its traces.
    res = figs["residuals"]
    groups = {t.legendgroup for t in res.data if t.legendgroup}
    assert groups == set(evaluation.scores)
    assert sum(t.showlegend is not False for t in res.data if t.legendgroup) == len(groups)
    bands = figs["hysteresis_bands"]
    assert {t.legendgroup for t in bands.data} == set(evaluation.curves)
    assert bands.layout.legend.groupclick == "togglegroup"


def test_sweep_page_draws_both_figures_offline(tmp_path):
    """sweep.html (written by write_figures beside the PNGs, see test_sweep_run): tornado and
    metric scatter, failed points marked; a synthetic result table (no simulation) with a
    linear metric and a failed point."""
    browser = _browser()
    spec = _spec(n=12)
    rng = np.random.default_rng(0)
    rows = []
    for k in range(12):
        row = {"point_id": f"p{k:02d}", "index": k, "status": "ok", "error": ""}
        row |= {v.name: rng.uniform(v.low, v.high) for v in spec.variables}
        row |= {m: rng.normal() for m in _metrics(spec)}
        row["latch_off_mA"] = 500.0 + 400.0 * row["vfs_d_orf"]  # a clear tornado bar
        rows.append(row)
    rows[-1] |= {"status": "failed", "error": "simulation failed: <test> & more"}
    table = pd.DataFrame(rows)
    html = sweep_html(table, spec)
    assert html.count("* plotly.js v") == 1 and "<test>" not in html
    page_path = tmp_path / "sweep.html"
    page_path.write_text(html, encoding="utf-8")
    page = load_page(page_path, browser)
    assert page.offline and page.figures == page.visible == page.plots == page.plots_drawn == 2
