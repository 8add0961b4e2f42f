"""Range errors for numeric options, before any work (a new-user session found tracebacks
and silently accepted values: ``stand --seed -1``, ``--ramps fast=1e9``, ``--time-limit nan``,
``--fmu-timeout 0``)."""

from __future__ import annotations

import pytest

from clutchlab.cli import main


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["stand", "--out", "{tmp}/s", "--seed", "-1"], "-1 is negative"),
        (["stand", "--out", "{tmp}/s", "--ramps", "fast=1e9"], "0 < SECONDS <= 3600"),
        (["stand", "--out", "{tmp}/s", "--ramps", "fast=inf"], "0 < SECONDS <= 3600"),
        (["fit-physics", "{tmp}", "--out", "{tmp}/m.json", "--time-limit", "nan"], "finite"),
        (["evaluate", "{tmp}", "--out", "{tmp}/r", "--fmu-timeout", "0"], "finite number > 0"),
        (["evaluate", "{tmp}", "--out", "{tmp}/r", "--fit-time-limit", "-5"], "> 0"),
        (["discover", "{tmp}", "--out", "{tmp}/d", "--time-limit", "0"], "> 0"),
        (["select-structure", "{tmp}", "--time-limit", "inf"], "finite"),
    ],
)
def test_numeric_options_out_of_range_are_refused(argv, message, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code not in (0, None)
    out = capsys.readouterr()
    assert message in out.err + out.out + str(info.value.code)
    assert sorted(tmp_path.iterdir()) == []  # nothing written
