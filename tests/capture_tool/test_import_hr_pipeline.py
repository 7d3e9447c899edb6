"""Issue 35 (Must show): a real FIT file imported with a video beside it, a mocap clip attached, then
``work``, ``train`` with the sample lab and ``export bids`` with no validator error, all through the
command line. The video's frames land at ``--video-offset + k / fps`` on the heart-rate file's clock."""

from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.annotate.keyframes import read_annotations
from effortface.cli import main
from effortface.core.session.folder import read_session, validate_session

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sessions"
FIT = ROOT / "tests" / "data" / "hr" / "garmin-fenix2-run.fit"
CLIP = ROOT / "tests" / "data" / "motion" / "cmu_13_29_full_30fps.bvh"
DONOR = "P01_20260112-093000_cardio"   # its video and raters' annotations go with the imported run
OFFSET_S = 120.0


def _effortface(*args: object) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "effortface", *map(str, args)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    return done


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> tuple[Path, Path]:
    """The sample lab with P01's cardio session replaced by the Fenix 2 run, its video and a mocap clip."""
    tmp = tmp_path_factory.mktemp("hr")
    lab = tmp / "lab"
    shutil.copytree(SAMPLE, lab, ignore=shutil.ignore_patterns("_ground_truth", "reliability", "simlab", "*.py",
                                                               "*.md", "serial"))
    donor = tmp / DONOR
    shutil.move(str(lab / DONOR), donor)
    done = _effortface("import", "hr", FIT, "--out", lab, "--participant", "P01", "--video", donor / "video.avi",
                       "--video-offset", OFFSET_S, "--label", "cardio")
    folder = Path(done.stdout.strip())
    (folder / "annotations").mkdir()
    for path in sorted((donor / "annotations").glob("*.json")):
        keys = read_annotations(path)
        dataclasses.replace(keys, session_id=folder.name).save(folder / "annotations" / path.name)
    _effortface("motion", "attach", folder, CLIP, "--offset", 200)
    (lab / "dataset_description.json").write_text(json.dumps(
        {"Name": "effortface sample lab and an imported watch run", "Authors": ["A. Researcher", "B. Engineer"],
         "License": "CC0"}))
    _effortface("work", lab)
    return folder, donor


def test_video_aligned_on_the_fit_clock(lab):
    folder, donor = lab
    assert validate_session(folder) == []
    session = read_session(folder)
    with open(donor / "video_frames.csv", newline="") as fh:
        n_frames = sum(1 for _ in csv.DictReader(fh))
    info = session.info.devices["camera"]
    assert len(session.frame_times_s) == n_frames == info["frames"]
    assert session.frame_times_s[0] == OFFSET_S
    assert session.frame_times_s[-1] == pytest.approx(OFFSET_S + (n_frames - 1) / info["fps"], abs=1e-3)
    # the heart rate at a session time is the FIT record at the file's start + that time
    import fitparse

    records = {m.get_value("timestamp").replace(tzinfo=dt.timezone.utc): m.get_value("heart_rate")
               for m in fitparse.FitFile(str(FIT)).get_messages("record") if m.get_value("heart_rate") is not None}
    start = dt.datetime.fromisoformat(session.info.extra["import"]["start_time"].replace("Z", "+00:00"))
    for row in session.heart_rate[::200]:
        assert records[start + dt.timedelta(seconds=row.t_s)] == row.hr_bpm


def test_work_train_and_bids(lab, tmp_path):
    folder, _ = lab
    with open(folder / "work.csv", newline="") as fh:
        sources = {r["source"] for r in csv.DictReader(fh)}
    assert f"motion:{CLIP.name}" in sources
    _effortface("train", folder.parent, "--out", tmp_path / "model", "--max-rows", "40")
    doc = json.loads((tmp_path / "model" / "model.json").read_text())
    assert doc["provenance"]["n_sessions"] == 12 and "P01" in doc["provenance"]["participants"]
    from tests.interop.test_bids import _validate

    _effortface("export", "bids", folder.parent, "--out", tmp_path / "ds")
    assert [i for i in _validate(tmp_path / "ds") if i["severity"] == "error"] == []
    ses = tmp_path / "ds" / "sub-P01" / "ses-20150815144508"
    assert (ses / "motion").is_dir()
    assert next(ses.glob("beh/*recording-heartrate_physio.tsv.gz"))


@pytest.mark.parametrize(("extra", "match"), [
    (["--video-offset", "3"], "--video-offset: expected --video FILE with it, found no --video"),
    (["--video", "none.avi"], "--video none.avi: expected a video file, found no such file"),
    (["--hr-stream", "HR"], "--hr-stream: only for 'import xdf', found with 'import hr'"),
])
def test_bad_video_options(capsys, tmp_path, extra, match):
    argv = ["import", "hr", str(FIT), "--out", str(tmp_path / "lab"), "--participant", "P01", "--sex", "male",
            "--age", "30", "--height", "1.8", "--mass", "80", "--training-level", "5", *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]
    assert not (tmp_path / "lab").exists()


def _flash_video(path: Path, flash_frame: int | None, n_frames: int = 80, fps: float = 10.0) -> Path:
    """A dark MJPG clip whose frames from ``flash_frame`` on, for five frames, are bright (a torch filmed)."""
    import cv2
    import numpy as np

    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (64, 48))
    for k in range(n_frames):
        lit = flash_frame is not None and flash_frame <= k < flash_frame + 5
        writer.write(np.full((48, 64, 3), 200 if lit else 30 + k % 3, np.uint8))
    writer.release()
    return path


def test_video_placed_by_a_flash(tmp_path):
    """--video-flash-at S: the video's first bright frame lands at S seconds of the heart-rate file."""
    video = _flash_video(tmp_path / "torch.avi", flash_frame=43)
    fit = ROOT / "tests" / "data" / "hr" / "garmin-fenix5-run.fit"
    assert main(["import", "hr", str(fit), "--out", str(tmp_path / "lab"), "--participant", "P01", "--sex", "male",
                 "--age", "30", "--height", "1.8", "--mass", "80", "--training-level", "5", "--video", str(video),
                 "--video-flash-at", "20"]) == 0
    (folder,) = [p for p in (tmp_path / "lab").iterdir() if p.is_dir()]
    frames = read_session(folder).frame_times_s
    assert len(frames) == 80 and frames[43] == pytest.approx(20.0, abs=1e-4)
    assert frames[0] == pytest.approx(20.0 - 4.3, abs=1e-4)


def test_video_without_a_flash_is_refused(capsys, tmp_path):
    video = _flash_video(tmp_path / "dark.avi", flash_frame=None)
    argv = ["import", "hr", str(FIT), "--out", str(tmp_path / "lab"), "--participant", "P01", "--sex", "male",
            "--age", "30", "--height", "1.8", "--mass", "80", "--training-level", "5", "--video", str(video),
            "--video-flash-at", "20"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "dark.avi: expected a flash" in err[0] and "found none" in err[0]
    assert not (tmp_path / "lab").exists() or not any((tmp_path / "lab").iterdir())
