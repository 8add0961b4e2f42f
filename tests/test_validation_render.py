"""Issue 6 must-show 5: the HTML report renders in headless Chromium with every figure
visible, and a screenshot is written beside the report (needs a Chromium on PATH, e.g.
Debian's ``chromium-headless-shell``)."""

from __future__ import annotations

import pytest
from test_validation_report import TINY_RAMPS

from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand
from clutchlab.validation import evaluate, write_report
from clutchlab.validation.render import check_rendering, find_browser


@pytest.mark.slow
def test_report_renders_with_every_figure_visible(tmp_path):
    # A missing browser fails loudly (never a silent skip): this test is the evidence.
    assert find_browser() is not None, (
        "no headless Chromium on PATH: install one (Debian: apt-get install "
        "chromium-headless-shell) to run the rendering check"
    )
    data = run_stand(StandConfig(settings=DEFAULT_SETTINGS[:2], ramps=TINY_RAMPS), False)
    ev = evaluate(data.dataset, ["physics_default"], progress=False)
    files = write_report(ev, tmp_path / "report")
    check = check_rendering(files.html)
    assert check.ok and check.figures == len(files.doc["figures"]["drawn"]) >= 4
    assert check.screenshot == files.folder / "report_screenshot.png"
    assert check.size_px[0] == 1280 and check.size_px[1] > 2000
