"""Issue 37: the files ``agreement`` reads get the checks their siblings get.

Each case writes a hostile file into a copy of two sample sessions (with the blind round and a machine
track per session) and runs the real command: one line naming the file (and line, field), exit 2.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from effortface.annotate.machine.track import machine_paths, read_machine_track
from effortface.annotate.reliability import read_poses
from effortface.cli import main
from tests.annotate.machine_helpers import write_fake_machine

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
CARDIO, STRENGTH = "P01_20260112-093000_cardio", "P02_20260112-113700_strength"


@pytest.fixture(scope="module")
def rated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two sample sessions, each with a machine track, and the blind round (read-only: copy it)."""
    lab = tmp_path_factory.mktemp("rated") / "lab"
    for name in (CARDIO, STRENGTH):
        shutil.copytree(SAMPLES / name, lab / name, ignore=shutil.ignore_patterns("*.avi", "serial"))
        write_fake_machine(lab / name)
    shutil.copytree(SAMPLES / "reliability", lab / "reliability")
    return lab


@pytest.fixture
def lab(rated: Path, tmp_path: Path) -> Path:
    """A fresh copy of :func:`rated` a test may damage."""
    return Path(shutil.copytree(rated, tmp_path / "lab"))


def _refused(capsys: pytest.CaptureFixture[str], args: list[str], *needles: str) -> str:
    """Run the command: exit 2, one line on stderr holding every needle, nothing on stdout."""
    assert main(args) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


def test_the_intact_lab_still_reads(lab: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", str(lab)]) == 0
    assert "machine" in capsys.readouterr().out


def test_a_machine_track_of_another_session_is_refused(lab: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for src, dst in zip(machine_paths(lab / STRENGTH), machine_paths(lab / CARDIO)):
        shutil.copyfile(src, dst)
    _refused(capsys, ["agreement", str(lab)], f"{CARDIO}/machine/face_landmarker.csv",
             "expected the 953 frames of this session's video_frames.csv, found 1042")


def test_a_machine_track_with_the_right_length_but_other_times_is_refused(lab: Path) -> None:
    csv_path = machine_paths(lab / CARDIO)[0]
    lines = csv_path.read_text().splitlines()
    cells = lines[5].split(",")
    cells[1] = f"{float(cells[1]) + 0.5:.4f}"
    lines[5] = ",".join(cells)
    csv_path.write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception, match=r"face_landmarker\.csv: line 6: column t_s: expected frame 4 at "):
        read_machine_track(lab / CARDIO)


@pytest.mark.parametrize("column, value", [(3, "7.5"), (4, "-3"), (3 + 4 + 26, "2e300")])
def test_impossible_machine_weights_are_refused(lab: Path, capsys: pytest.CaptureFixture[str], column: int,
                                                value: str) -> None:
    csv_path = machine_paths(lab / CARDIO)[0]
    lines = csv_path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines[1:], 1) if line.split(",")[2] == "1")
    cells = lines[k].split(",")
    cells[column] = value
    lines[k] = ",".join(cells)
    csv_path.write_text("\n".join(lines) + "\n")
    _refused(capsys, ["agreement", str(lab)], f"face_landmarker.csv: line {k + 1}: column ",
             f"expected a number from 0 to 1, found {float(value):g}")


def test_a_machine_track_numbered_otherwise_than_the_video_frames_is_refused(lab: Path) -> None:
    csv_path = machine_paths(lab / CARDIO)[0]
    lines = csv_path.read_text().splitlines()
    lines[3] = "7" + lines[3][lines[3].index(","):]
    csv_path.write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception, match=r"line 4: column frame: expected frame 2 .*found '7'"):
        read_machine_track(lab / CARDIO)


def test_a_sidecar_counting_other_frames_is_refused(lab: Path) -> None:
    sidecar = machine_paths(lab / CARDIO)[1]
    doc = json.loads(sidecar.read_text())
    sidecar.write_text(json.dumps({**doc, "frames": 12}))
    with pytest.raises(Exception, match=r"expected the 12 frames its sidecar face_landmarker.json counts, found 953"):
        read_machine_track(lab / CARDIO)


@pytest.mark.parametrize("row, needles", [
    (f"pose01,{CARDIO},99999,270.257700", ("poses.csv:2: frame: expected a frame of session", "found 99999")),
    (f"pose01,{CARDIO},402,5.0", ("poses.csv:2: t_s: expected 270.257700 s, the time of frame 402", "found 5.000000")),
    (f"pose01,{CARDIO},{10 ** 20},270.2577", ("poses.csv:2: frame: expected a number from 0 to 1e+09",)),
])
def test_poses_that_contradict_the_sessions_frames_are_refused(lab: Path, capsys: pytest.CaptureFixture[str],
                                                               row: str, needles: tuple[str, ...]) -> None:
    poses = lab / "reliability" / "poses.csv"
    lines = poses.read_text().splitlines()
    assert lines[1].startswith(f"pose01,{CARDIO},402,")
    poses.write_text("\n".join([lines[0], row, *lines[2:]]) + "\n")
    _refused(capsys, ["agreement", str(lab)], *needles)


def test_the_sample_poses_agree_with_their_sessions_frames() -> None:
    from effortface.annotate.agreement import frames_by_session
    from effortface.core.session.folder import list_sessions

    poses = read_poses(SAMPLES / "reliability" / "poses.csv", frames_by_session(list_sessions(SAMPLES)))
    assert len(poses) == 18


@pytest.mark.parametrize("name", ["ratings.csv", "poses.csv"])
def test_a_field_over_the_csv_limit_is_one_line(lab: Path, capsys: pytest.CaptureFixture[str], name: str) -> None:
    path = lab / "reliability" / name
    path.write_text(path.read_text() + 'pose99,R9,mouth_open,"' + "x" * 200_000 + '"\n')
    _refused(capsys, ["agreement", str(lab)], f"reliability/{name}: line ",
             "expected CSV fields of at most 131072 characters, found a longer one")


def test_a_key_on_frame_1e20_is_refused_by_agreement(lab: Path, capsys: pytest.CaptureFixture[str]) -> None:
    shutil.rmtree(lab / "reliability")
    path = lab / CARDIO / "annotations" / "R1.json"
    doc = json.loads(path.read_text())
    doc["tracks"]["mouth_stretch"][0]["frame"] = 10 ** 20
    path.write_text(json.dumps(doc))
    _refused(capsys, ["agreement", str(lab)], "annotations/R1.json: tracks.mouth_stretch[0]: key-frame frame: "
             "expected an integer from 0 to 1e+09, found 100000000000000000000")


def test_an_unknown_blendshape_in_ratings_names_the_file_and_line(lab: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    ratings = lab / "reliability" / "ratings.csv"
    ratings.write_text(ratings.read_text() + "pose01,R9,smile_big,0.5\n")
    n = len(ratings.read_text().splitlines())
    _refused(capsys, ["agreement", str(lab)], f"reliability/ratings.csv:{n}: blendshape: expected one of "
             "mouth_stretch, mouth_open, eye_squint, brow_lower, found 'smile_big'")
    _refused(capsys, ["agreement", "--ratings", str(ratings)], f"ratings.csv:{n}: blendshape")


def test_a_pose_of_a_session_without_video_is_refused(lab: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (lab / CARDIO / "video_frames.csv").unlink()
    _refused(capsys, ["agreement", str(lab)], "poses.csv:2: session_id: expected a session with video frames, "
             f"found {CARDIO} without video_frames.csv")
