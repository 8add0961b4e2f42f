"""``clutchlab evaluate``: usage errors are refused before any work, with exit status 2.

Exit status 1 means "a variant failed" (the report lists it); a bad option is not that.
"""

from __future__ import annotations

import pytest

from clutchlab.cli import main


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--fmu-param", "reg_m=heavy", "--physics-fmu", "x.fmu"], "expected NAME=VALUE"),
        (["--fmu-param", "reg_m=40"], "no --physics-fmu was given"),
    ],
)
def test_a_bad_fmu_param_is_a_usage_error(tmp_path, capsys, extra, message):
    out = tmp_path / "report"
    code = main(["evaluate", str(tmp_path / "no-data"), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("clutchlab evaluate: error: --fmu-param") and message in err
    assert not out.exists()
