"""C3D clips: a real clip written as C3D by the c3d package reads back as the same motion."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.train.energy import work_and_power
from effortface.train.motion import Motion, MotionFormatError, read_motion
from effortface.train.segments import build_body

c3d = pytest.importorskip("c3d")


def write_c3d(motion: Motion, path: Path, *, occlude: tuple[int, int] | None = None) -> Path:
    """The motion's joints as labelled C3D points in millimetres (optionally one point occluded)."""
    writer = c3d.Writer(point_rate=motion.fps, analog_rate=0)
    writer.set_point_labels(list(motion.joint_names))
    frames = []
    for k in range(motion.n_frames):
        points = np.zeros((len(motion.joint_names), 5), dtype=np.float32)
        points[:, :3] = motion.positions_m[k] * 1000.0
        if occlude is not None and occlude[0] == k:
            points[occlude[1], 3] = -1.0
        frames.append((points, np.zeros((0, 0), dtype=np.float32)))
    with open(path, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the writer warns that the file has no analog channels
        writer.add_frames(frames)
        writer.write(fh)
    return path


def test_c3d_reads_back_and_gives_the_same_work(shared_data: Path, tmp_path: Path) -> None:
    bvh = read_motion(shared_data / "motion" / "cmu_13_29_squats_120fps.bvh")
    clip = read_motion(write_c3d(bvh, tmp_path / "squats.c3d"))
    assert clip.joint_names == bvh.joint_names and clip.fps == bvh.fps
    np.testing.assert_allclose(clip.positions_m, bvh.positions_m, atol=1e-4)  # float32 millimetres

    def w(m: Motion) -> np.ndarray:
        body = build_body(m.joint_names, m.parents, 72.0, "male", reference_positions_m=m.positions_m)
        return work_and_power(m, body, use_rotations=False).w_per_kg

    np.testing.assert_allclose(w(clip), w(bvh), rtol=0.01, atol=0.01)


def test_c3d_attaches_with_sync(shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from tests.train.test_motion_attach import TRUE_OFFSET_S, _raw_apexes_s, _session

    bvh_path = shared_data / "motion" / "cmu_13_29_full_30fps.bvh"
    clip = write_c3d(read_motion(bvh_path), tmp_path / "routine.c3d")
    (apex,) = _raw_apexes_s(bvh_path, [(0.0, 0.6)])
    folder = _session(tmp_path, [TRUE_OFFSET_S + apex])
    assert main(["motion", "attach", str(folder), str(clip), "--sync"]) == 0
    entry = json.loads((folder / "motion" / "motion.json").read_text())["files"][0]
    assert entry["format"] == "c3d" and abs(entry["offset_s"] - TRUE_OFFSET_S) < 0.1


def test_an_occluded_point_is_named(shared_data: Path, tmp_path: Path) -> None:
    bvh = read_motion(shared_data / "motion" / "cmu_13_29_squats_120fps.bvh")
    path = write_c3d(bvh, tmp_path / "gap.c3d", occlude=(40, 3))
    with pytest.raises(MotionFormatError, match=rf"gap.c3d: point '{bvh.joint_names[3]}': expected a position "
                                                r"in every frame, found it occluded in 1 point-frames \(first at frame 40\)"):
        read_motion(path)
