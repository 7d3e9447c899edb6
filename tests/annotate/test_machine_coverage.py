"""``effortface preannotate`` warns, naming the likely cause, when fewer than half the frames have a face (issue 38).

The sessions are recorded by ``effortface capture --video`` from a real GRID talking face
(tests/data/video): as it is (the face 42 % of the frame height), shrunk to 12 % of the frame
height, and darkened to a tenth of its light over a grey that hides nothing.
"""

from __future__ import annotations

import re
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.machine.face_coverage import describe_cause
from effortface.annotate.machine.track import read_machine_track
from effortface.cli import main
from effortface.core.framing import Framing

from ..capture_tool.capture_helpers import BODY, effortface, hxm_chunks, start_replay, write_serlog
from ..capture_tool.test_framing import grid_frames, scale_for, shrink_face, write_video


def _record(video: Path, shared_data: Path, tmp: Path) -> Path:
    replay, pty = start_replay(write_serlog(tmp / "strap.serlog", hxm_chunks(shared_data, 0, 30)))
    cap = subprocess.run(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P07", *BODY,
                                    "--video", video, "--duration", "3.5", "--out", tmp / "lab"),
                         capture_output=True, text=True, timeout=120)
    replay.send_signal(signal.SIGTERM)
    replay.wait(10)
    assert cap.returncode == 0, cap.stderr
    return Path(cap.stdout.splitlines()[0])


@pytest.fixture(scope="module")
def sessions(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("coverage")
    frames = grid_frames()
    small = [shrink_face(f, scale_for(0.12)) for f in frames]
    blank = [np.full_like(f, 128) for f in frames]
    videos = {"framed": write_video(tmp / "framed.avi", frames), "small": write_video(tmp / "small.avi", small),
              "blank": write_video(tmp / "blank.avi", blank)}
    out = {}
    for name, video in videos.items():
        (tmp / name).mkdir()
        out[name] = _record(video, shared_data, tmp / name)
    return out


def test_a_face_at_12_percent_warns_with_its_size_and_exits_1(sessions, capsys) -> None:
    session = sessions["small"]
    assert main(["preannotate", str(session)]) == 1
    out, err = capsys.readouterr()
    track = read_machine_track(session)
    assert track is not None and track.face.sum() < len(track.frame) / 2  # the rater found (almost) nothing
    assert "wrote " in out  # the track is written all the same
    warning = err.splitlines()[-1]
    assert warning.startswith(f"warning: {session}: a face on {int(track.face.sum())} of {len(track.frame)} frames "
                              "(fewer than half); likely cause: size: the face is ")
    share = int(warning.split("the face is ")[1].split(" %")[0])
    assert 9 <= share <= 15 and warning.endswith("the rater needs 25 % (move the camera closer)")


def test_no_face_at_all_names_none_found(sessions, capsys) -> None:
    assert main(["preannotate", str(sessions["blank"])]) == 1
    warning = capsys.readouterr().err.splitlines()[-1]
    assert re.search(r"a face on 0 of 75 frames \(fewer than half\); likely cause: none found: no face in the "
                     r"frames, not even a small one \(brightness 12\d of 255\)$", warning), warning  # grey 128 via JPEG


def test_a_well_framed_face_has_no_warning(sessions, capsys) -> None:
    assert main(["preannotate", str(sessions["framed"])]) == 0
    assert "warning" not in capsys.readouterr().err


def test_darkness_is_named_when_most_looks_are_dark() -> None:
    looks = [Framing(None, False, 12.0), Framing(None, False, 20.0), Framing(None, False, 130.0)]
    assert describe_cause(looks) == "darkness: the frames are dark (brightness 20 of 255; light the face)"
