"""Progress on stderr: plain lines where stderr is a log or a pipe, a tqdm bar only on a terminal."""

from __future__ import annotations

import io

import pytest

from effortface.core.progress import ProgressBar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_redirected_stderr_gets_one_plain_line_per_tenth_and_step(capsys) -> None:
    with ProgressBar("rate") as bar:
        for done in range(0, 1001):
            bar(done / 1000, "frames rated")
        bar(1.0, "done")
    err = capsys.readouterr().err
    assert "\r" not in err and "\x1b" not in err
    lines = err.splitlines()
    assert lines[0] == "rate:   0% frames rated" and lines[-2:] == ["rate: 100% frames rated", "rate: 100% done"]
    assert len(lines) == 12  # 0, 10, ..., 100 % and the last step


def test_a_terminal_gets_a_bar_and_a_disabled_bar_nothing(monkeypatch, capsys) -> None:
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    with ProgressBar("train") as bar:
        bar(0.5, "half")
    assert "\r" in terminal.getvalue() and "50%" in terminal.getvalue()
    with ProgressBar("quiet", enabled=False) as bar:
        bar(0.5, "half")
    assert "quiet" not in terminal.getvalue()


@pytest.mark.parametrize("fraction", [0.0, 0.25, 1.0])
def test_nothing_is_printed_before_the_first_report(fraction, capsys) -> None:
    bar = ProgressBar("export")
    assert capsys.readouterr().err == ""
    bar(fraction, "step")
    assert capsys.readouterr().err.startswith("export:")
