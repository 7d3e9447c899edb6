"""A ``_x_m`` joint-positions CSV without its skeleton file (every joint a root) is one line saying it needs
its skeleton file, not ``RuntimeError: generator raised StopIteration`` (issue 37); with the file it maps."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from effortface.cli import main
from effortface.synth.motion import read_motion
from effortface.synth.motion_csv import skeleton_beside, write_positions_csv

ROOT = Path(__file__).resolve().parents[2]
SESSION = ROOT / "sample_sessions" / "P02_20260112-113700_strength"


@pytest.fixture
def clip(tmp_path: Path) -> Path:
    """The sample session's real BVH clip written as a positions CSV and its skeleton file."""
    out = tmp_path / "clips" / "squats.csv"
    out.parent.mkdir()
    write_positions_csv(out, read_motion(SESSION / "motion" / "squats_set2.bvh"))
    return out


@pytest.fixture
def session(tmp_path: Path) -> Path:
    out = tmp_path / SESSION.name
    shutil.copytree(SESSION, out, ignore=shutil.ignore_patterns("motion", "work.csv", "*.avi", "serial"))
    return out


def test_with_its_skeleton_the_clip_attaches(clip: Path, session: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["motion", "attach", str(session), str(clip), "--offset", "10"]) == 0


def _one_line_needs_skeleton(capsys: pytest.CaptureFixture[str]) -> None:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "StopIteration" not in err, err
    assert "squats.csv: head: expected its joints (Head_end, Neck1) in one skeleton tree, found them in separate " \
           "trees: a joint-positions CSV needs its skeleton file squats.skeleton.json beside it" in err


def test_attach_without_its_skeleton_file_says_it_needs_it(clip: Path, session: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    skeleton_beside(clip).unlink()
    assert main(["motion", "attach", str(session), str(clip), "--offset", "10"]) == 2
    _one_line_needs_skeleton(capsys)
    assert not (session / "motion").exists()


def test_work_on_an_attached_clip_without_its_skeleton_file_says_it_needs_it(clip: Path, session: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["motion", "attach", str(session), str(clip), "--offset", "10"]) == 0
    for stray in (session / "motion").glob("*.skeleton.json"):
        stray.unlink()  # as a copy by hand (or an attach that did not copy it) leaves the clip
    capsys.readouterr()
    assert main(["work", str(session)]) == 2
    _one_line_needs_skeleton(capsys)
    assert not (session / "work.csv").exists()
