"""``effortface synth MODEL CLIPS_DIR --out OUT_DIR``: every clip through Dask, one file per clip, a
bad clip named in the summary and skipped, exit status 1 when some failed."""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.cli import main
from effortface.synth.curves_io import LIVELINK_BLENDSHAPES

ROOT = Path(__file__).resolve().parents[2]
CLIPS = ("motion/cmu_13_29_jumping_jacks_120fps.bvh", "motion/amp_humanoid_walk.npz")
#: a local Dask cluster starts in seconds; a hung run fails the test instead of blocking CI
TIMEOUT_S = 600


@pytest.fixture
def clips_dir(shared_data: Path, tmp_path: Path) -> Path:
    """Two real clips (BVH, npz) and one corrupt BVH."""
    folder = tmp_path / "clips"
    folder.mkdir()
    for clip in CLIPS:
        shutil.copy(shared_data / clip, folder)
    good = (shared_data / CLIPS[0]).read_text()
    (folder / "broken.bvh").write_text(good[: len(good) // 3] + "\nMOTION\nFrames: x\n")
    (folder / "notes.txt").write_text("not a clip\n")
    return folder


def _frames(path: Path) -> int:
    with path.open(newline="") as f:
        return sum(1 for _ in csv.reader(f)) - 1


def test_batch_with_one_corrupt_clip_on_two_workers(clips_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "curves"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([sys.executable, "-m", "effortface", "synth", "default", str(clips_dir),
                           "--out", str(out), "--workers", "2"], cwd=ROOT, capture_output=True,
                          text=True, env=env, timeout=TIMEOUT_S)
    assert done.returncode == 1, done.stderr[-2000:]
    assert sorted(p.name for p in out.iterdir()) == [
        "amp_humanoid_walk.csv", "amp_humanoid_walk.units.json",
        "cmu_13_29_jumping_jacks_120fps.csv", "cmu_13_29_jumping_jacks_120fps.units.json"]
    assert _frames(out / "cmu_13_29_jumping_jacks_120fps.csv") == 439
    failed = [line for line in done.stderr.splitlines() if line.startswith("effortface synth: failed:")]
    assert len(failed) == 1 and "broken.bvh" in failed[0]
    assert "1 of 3 clips failed (skipped)" in done.stderr
    assert "synthesized 2 of 3 clips" in done.stdout
    assert "Traceback" not in done.stderr


def test_batch_in_process_livelink_and_no_silent_overwrite(clips_dir: Path, tmp_path: Path, capsys) -> None:
    (clips_dir / "broken.bvh").unlink()
    out = tmp_path / "curves"
    assert main(["synth", "default", str(clips_dir), "--out", str(out), "--format", "livelink"]) == 0
    with (out / "amp_humanoid_walk.csv").open(newline="") as f:
        header = next(csv.reader(f))
    assert header[:3] == ["Timecode", "BlendShapeCount", LIVELINK_BLENDSHAPES[0]]
    before = (out / "amp_humanoid_walk.csv").read_bytes()
    capsys.readouterr()
    assert main(["synth", "default", str(clips_dir), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "expected new files, found 2 existing" in err and "--force" in err
    assert (out / "amp_humanoid_walk.csv").read_bytes() == before
    assert main(["synth", "default", str(clips_dir), "--out", str(out), "--force"]) == 0
    assert (out / "amp_humanoid_walk.csv").read_bytes() != before


def test_a_folder_without_clips_is_one_error_line(tmp_path: Path, capsys) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["synth", "default", str(empty), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "expected motion clips (.bvh, .npz, .c3d, .csv), found none" in err[0]


def test_an_existing_units_sidecar_is_not_replaced_silently(clips_dir: Path, tmp_path: Path, capsys) -> None:
    (clips_dir / "broken.bvh").unlink()
    out = tmp_path / "curves"
    out.mkdir()
    sidecar = out / "amp_humanoid_walk.units.json"
    sidecar.write_text("{}\n")
    assert main(["synth", "default", str(clips_dir), "--out", str(out)]) == 2
    assert "found 1 existing (first amp_humanoid_walk.units.json" in capsys.readouterr().err
    assert sidecar.read_text() == "{}\n" and not (out / "amp_humanoid_walk.csv").exists()


def test_one_list_of_motion_suffixes() -> None:
    """Batch synth, the Synthesize stage and motion attach take exactly what read_motion reads."""
    from effortface.synth import attach, batch_synth, synth_session
    from effortface.synth.motion import MOTION_SUFFIXES

    assert batch_synth.CLIP_SUFFIXES is MOTION_SUFFIXES
    assert synth_session.MOTION_SUFFIXES is MOTION_SUFFIXES
    assert set(attach.CLIP_FORMATS) == set(MOTION_SUFFIXES)
