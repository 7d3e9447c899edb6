"""Issue 37: outputs of several files are replaced together or not at all.

A full disk is simulated as the project's other tests do (an ``OSError(ENOSPC, "No space left on
device")``), here raised by the fsync of one chosen file's temporary copy: the real writers run, and
the disk "fills" exactly while that file is written.
"""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path

import pytest

from effortface.annotate.annotate_session import BlindRound
from effortface.annotate.machine.track import machine_paths, read_machine_track, write_machine_track
from effortface.annotate.reliability import read_corrections
from effortface.core import fileio
from tests.annotate.machine_helpers import fake_machine_track, write_fake_machine

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P01_20260112-093000_cardio"


def fill_the_disk_on(monkeypatch: pytest.MonkeyPatch, name: str) -> list[str]:
    """Make the fsync of a temporary copy of the file ``name`` fail as on a full disk; the names hit."""
    real_fsync, hit = os.fsync, []

    def fsync(fd: int) -> None:
        target = os.readlink(f"/proc/self/fd/{fd}")
        if Path(target).name.startswith(f".{name}.") and target.endswith(".tmp"):
            hit.append(Path(target).name)
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(fileio.os, "fsync", fsync)
    return hit


def _bytes(*paths: Path) -> list[bytes]:
    return [p.read_bytes() for p in paths]


def test_preannotate_force_on_a_full_disk_keeps_the_old_csv_and_sidecar_together(tmp_path, monkeypatch) -> None:
    """Before: the new sidecar was renamed into place, then the CSV's write failed: a new sidecar beside
    the old CSV (they disagreed). Now the pair is the old one, byte for byte, and no temporary is left."""
    session = tmp_path / SESSION
    shutil.copytree(SAMPLES / SESSION, session, ignore=shutil.ignore_patterns("serial", "video.avi"))
    write_fake_machine(session, seed=1)
    csv_path, sidecar_path = machine_paths(session)
    before = _bytes(csv_path, sidecar_path)
    hit = fill_the_disk_on(monkeypatch, csv_path.name)
    with pytest.raises(OSError) as err:
        write_machine_track(session, fake_machine_track(session, seed=2), force=True)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(csv_path) and hit
    assert _bytes(csv_path, sidecar_path) == before
    assert sorted(p.name for p in csv_path.parent.iterdir()) == sorted([csv_path.name, sidecar_path.name])
    monkeypatch.undo()
    write_machine_track(session, fake_machine_track(session, seed=2), force=True)  # space again: both new
    track = read_machine_track(session)
    assert track is not None and track.sidecar["seed"] == 2 and _bytes(csv_path) != before[:1]


def _finished_round(tmp_path: Path) -> BlindRound:
    shutil.copytree(SAMPLES / "reliability", tmp_path / "reliability")
    r4 = BlindRound(tmp_path, "R4")
    for pose in r4.poses:
        for name in r4.blendshapes.names:
            r4.set_rating(pose.pose_id, name, 0.25)
    return r4


@pytest.mark.parametrize("full", ["ratings_R4.csv", "corrections_R4.csv"])
def test_a_correction_on_a_full_disk_is_neither_logged_nor_applied(tmp_path, monkeypatch, full) -> None:
    """Before: the correction was appended to the log, then the ratings file's write failed: logged as
    applied but not applied. Now neither file changes, the error names the file, and the round in
    memory still has the old value; with space again the correction is logged and applied."""
    r4 = _finished_round(tmp_path)
    ratings = tmp_path / "reliability" / "ratings_R4.csv"
    r4.correct_rating("pose02", "eye_squint", 0.1, "wrong row")  # a log already there
    before = _bytes(ratings, r4.corrections_path)
    hit = fill_the_disk_on(monkeypatch, full)
    with pytest.raises(OSError) as err:
        r4.correct_rating("pose01", "mouth_open", 0.7, "typo: 0.25 for 0.7")
    assert err.value.errno == errno.ENOSPC and Path(err.value.filename).name == full and hit
    assert _bytes(ratings, r4.corrections_path) == before
    assert r4.rating("pose01", "mouth_open") == 0.25
    assert not list((tmp_path / "reliability").glob(".*.tmp"))
    monkeypatch.undo()
    r4.correct_rating("pose01", "mouth_open", 0.7, "typo: 0.25 for 0.7")
    assert [c.pose_id for c in read_corrections(r4.corrections_path)] == ["pose02", "pose01"]
    assert BlindRound(tmp_path, "R4").rating("pose01", "mouth_open") == 0.7
