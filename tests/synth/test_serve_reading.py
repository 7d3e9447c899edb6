"""Issue 34: ``serve --skeleton`` reads the skeleton and its MoCap frames with ``--unit-m`` / ``--up``
(the up axis detected from the rest pose's head and feet) and gates the rest pose."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from effortface.interop.serve import FaceProcessor
from effortface.synth.motion import read_motion
from effortface.synth.plausibility import ImplausibleBodyError
from effortface.synth.read_options import MotionReadOptions
from effortface.synth.runtime import Character, load_model

SQUATS = "motion/cmu_13_29_squats_120fps.bvh"


def _skeleton(path: Path, clip, rest_positions: np.ndarray) -> str:
    path.write_text(json.dumps({"joints": list(clip.joint_names), "parents": [int(p) for p in clip.parents],
                                "rest_positions_m": rest_positions.tolist()}))
    return str(path)


def test_a_y_up_centimetre_skeleton_streams_like_the_z_up_metre_one(shared_data: Path, tmp_path: Path) -> None:
    clip = read_motion(shared_data / SQUATS).slice_s(0, 1)
    to_y_up_cm = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]) * 100.0  # (x, y, z) -> (y, z, x) cm
    model = load_model("default")
    metres = FaceProcessor(model, Character(), _skeleton(tmp_path / "m.skeleton.json", clip, clip.positions_m[0]),
                           fps=clip.fps)
    assert metres.reading["up_axis"] == "z" and metres.reading["unit_m"] == 1.0
    cm = FaceProcessor(model, Character(), _skeleton(tmp_path / "cm.skeleton.json", clip,
                                                     clip.positions_m[0] @ to_y_up_cm.T),
                       fps=clip.fps, read=MotionReadOptions(unit_m=0.01))
    assert cm.reading["up_axis"] == "y" and cm.reading["up_from"].startswith("gravity over the clip")
    assert 1.4 < cm.body["height_m"] < 1.8
    for frame in clip.positions_m:
        want = metres.step(frame.ravel().tolist(), 1 / clip.fps)
        row = cm.step((frame @ to_y_up_cm.T).ravel().tolist(), 1 / clip.fps)
    np.testing.assert_allclose(row, want, atol=1e-9)


def test_a_skeleton_in_the_wrong_unit_is_refused(shared_data: Path, tmp_path: Path) -> None:
    clip = read_motion(shared_data / SQUATS).slice_s(0, 0.1)
    path = _skeleton(tmp_path / "cm.skeleton.json", clip, clip.positions_m[0] * 100.0)
    with pytest.raises(ImplausibleBodyError, match=r"cm\.skeleton\.json: standing height 15\d\.\d\d m: expected "
                                                   r"1\.2-2\.2 m; check --unit-m"):
        FaceProcessor(load_model("default"), Character(), path, fps=clip.fps)
    trusted = FaceProcessor(load_model("default"), Character(), path, fps=clip.fps,
                            read=MotionReadOptions(trust_skeleton=True))
    assert trusted.body["trusted"]
