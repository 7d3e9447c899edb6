"""The ``effortface`` dispatcher: a mistyped command, a missing app DIR and an unchecked file-system
error are each one line on stderr and exit status 2, never a traceback nor a window on nothing."""

from __future__ import annotations

import argparse

import pytest

import effortface.app as app_module
import effortface.commands.demo as demo_module
from effortface.cli import COMMANDS, main


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture
def opened(monkeypatch: pytest.MonkeyPatch) -> list[argparse.Namespace]:
    """Stand-in for the Qt application: records what it would have been opened on."""
    calls: list[argparse.Namespace] = []

    def fake_main(args: argparse.Namespace) -> int:
        calls.append(args)
        return 0

    monkeypatch.setattr(app_module, "main", fake_main)
    return calls


@pytest.mark.parametrize("word", ["demoo", "agrement", "nowhere/sessions"])
def test_a_mistyped_command_is_refused(tmp_path, monkeypatch, capsys, opened, word) -> None:
    monkeypatch.chdir(tmp_path)
    assert main([word, "--out", "x"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line == (f"effortface: error: expected a command ({', '.join(COMMANDS)}) or a sessions folder, "
                    f"found {word!r}")
    assert line.startswith("effortface: error: expected a command (app, ports, capture, ")
    assert opened == [] and not (tmp_path / "x").exists()


def test_a_file_is_not_a_sessions_folder(tmp_path, capsys, opened) -> None:
    afile = tmp_path / "notes.txt"
    afile.write_text("x")
    assert main([str(afile)]) == 2
    assert f"or a sessions folder, found {str(afile)!r} (a file)" in _one_line(capsys.readouterr().err)
    assert opened == []


def test_an_existing_folder_or_an_option_still_opens_the_app(tmp_path, capsys, opened) -> None:
    assert main([str(tmp_path), "--stage", "train"]) == 0
    assert main(["--stage", "train"]) == 0
    assert main([]) == 0
    assert [(a.dir, a.stage) for a in opened] == [(str(tmp_path), "train"), ("sample_sessions", "train"),
                                                 ("sample_sessions", "capture")]


def test_app_without_dir_outside_the_repo_opens_the_users_copy(tmp_path, monkeypatch, capsys, opened) -> None:
    """No DIR: ./sample_sessions when the current directory has one, else the user's own copy of the
    sample lab in the user data folder (made once, said on stderr), never the checkout's folder."""
    from effortface.samplelab import repo_lab

    monkeypatch.setenv("EFFORTFACE_DATA_DIR", str(tmp_path / "data"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main([]) == 0
    copy = tmp_path / "data" / "sample_sessions"
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"effortface: first use: copying the sample lab from {repo_lab()} "
                                               f"into {copy} (yours to edit)... done in ")
    assert main([]) == 0 and capsys.readouterr().err == ""  # made once
    (work / "sample_sessions").mkdir()
    assert main(["app"]) == 0
    assert [a.dir for a in opened] == [str(copy), str(copy), "sample_sessions"]
    assert sorted(p.name for p in copy.iterdir()) == sorted(
        p.name for p in repo_lab().iterdir() if p.is_dir() and p.name not in ("_ground_truth", "__pycache__"))


def test_app_on_a_missing_folder_is_refused(tmp_path, capsys, opened) -> None:
    missing, png = tmp_path / "nonexistent" / "dir", tmp_path / "x.png"
    assert main(["app", str(missing), "--screenshot", str(png)]) == 2
    assert _one_line(capsys.readouterr().err) == (
        f"effortface app: error: DIR {missing}: expected a folder of sessions, found nothing")
    assert opened == [] and not png.exists()


def test_an_unwritable_out_is_one_line(tmp_path, capsys) -> None:
    """An OSError a command did not check (here demo's mkdir under a file) names the path."""
    from effortface.samplelab import repo_lab

    if repo_lab() is None:
        pytest.skip("not a checkout: the sample lab would be built first")
    afile = tmp_path / "afile"
    afile.write_bytes(b"keep")
    out = afile / "demo"
    assert main(["demo", "--out", str(out)]) == 2
    assert _one_line(capsys.readouterr().err) == (
        f"effortface demo: error: {out}: expected a readable/writable path, found Not a directory")
    assert afile.read_bytes() == b"keep"


@pytest.mark.parametrize(("exc", "message"), [
    (PermissionError(13, "Permission denied", "/root/x.csv"),
     "effortface demo: error: /root/x.csv: expected a readable/writable path, found Permission denied"),
    (IsADirectoryError(21, "Is a directory", "/tmp"),
     "effortface demo: error: /tmp: expected a readable/writable path, found Is a directory"),
    (FileNotFoundError(2, "No such file or directory", "a.csv", None, "b.csv"),
     "effortface demo: error: a.csv -> b.csv: expected a readable/writable path, found No such file or directory"),
])
def test_os_errors_of_a_command_are_one_line(monkeypatch, capsys, exc, message) -> None:
    def run(args: argparse.Namespace) -> int:
        raise exc

    monkeypatch.setattr(demo_module, "run", run)
    assert main(["demo"]) == 2
    assert _one_line(capsys.readouterr().err) == message


@pytest.mark.parametrize("exc", [ZeroDivisionError("bug"), OSError("no errno, no path")])
def test_other_errors_are_not_hidden(monkeypatch, exc) -> None:
    def run(args: argparse.Namespace) -> int:
        raise exc

    monkeypatch.setattr(demo_module, "run", run)
    with pytest.raises(type(exc)):
        main(["demo"])


def test_top_help_keeps_every_command_apart_from_its_description(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()
             if line.startswith("  ") and line.split() and line.split()[0] in COMMANDS}
    assert set(lines) == set(COMMANDS)
    for name, line in lines.items():
        assert line[2 + len(name):2 + len(name) + 2] == "  ", line  # 'preannotate the machine...' ran together


def test_no_display_is_refused_before_the_sample_lab_is_copied(tmp_path, monkeypatch, capsys) -> None:
    """A headless ``effortface`` outside the repository refused at once (it copied 40 MB first)."""
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("EFFORTFACE_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.chdir(tmp_path)
    assert main([]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "display: expected $DISPLAY or $WAYLAND_DISPLAY" in err[0]
    assert not (tmp_path / "data").exists()
