"""C3D clips: a real clip written as C3D by the c3d package reads back as the same motion."""

from __future__ import annotations

import dataclasses
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.synth.energy import work_and_power
from effortface.synth.motion import Motion, MotionFormatError, read_motion
from effortface.synth.segments import build_body

c3d = pytest.importorskip("c3d")


def write_c3d(motion: Motion, path: Path, *, occlude: tuple[int, int] | None = None, n_occluded: int = 1) -> Path:
    """The motion's joints as labelled C3D points in millimetres (optionally one point occluded)."""
    writer = c3d.Writer(point_rate=motion.fps, analog_rate=0)
    writer.set_point_labels(list(motion.joint_names))
    frames = []
    for k in range(motion.n_frames):
        points = np.zeros((len(motion.joint_names), 5), dtype=np.float32)
        points[:, :3] = motion.positions_m[k] * 1000.0
        if occlude is not None and occlude[0] <= k < occlude[0] + n_occluded:
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
    from tests.synth.test_motion_attach import TRUE_OFFSET_S, _raw_apexes_s, _session

    bvh_path = shared_data / "motion" / "cmu_13_29_full_30fps.bvh"
    clip = write_c3d(read_motion(bvh_path), tmp_path / "routine.c3d")
    (apex,) = _raw_apexes_s(bvh_path, [(0.0, 0.6)])
    folder = _session(tmp_path, [TRUE_OFFSET_S + apex])
    assert main(["motion", "attach", str(folder), str(clip), "--sync"]) == 0
    entry = json.loads((folder / "motion" / "motion.json").read_text())["files"][0]
    assert entry["format"] == "c3d" and abs(entry["offset_s"] - TRUE_OFFSET_S) < 0.1


def test_an_occluded_point_is_filled_or_named(shared_data: Path, tmp_path: Path) -> None:
    """A short occlusion (at most MAX_GAP_S) is interpolated; a longer one is named with its own count."""
    bvh = read_motion(shared_data / "motion" / "cmu_13_29_squats_120fps.bvh")
    short = read_motion(write_c3d(bvh, tmp_path / "short.c3d", occlude=(40, 3), n_occluded=3))
    assert "linearly interpolated (3 point-frames)" in short.source
    np.testing.assert_allclose(short.positions_m[40:43, 3], bvh.positions_m[40:43, 3], atol=0.01)
    path = write_c3d(bvh, tmp_path / "gap.c3d", occlude=(40, 3), n_occluded=30)
    long = read_motion(path)                 # the longest window without the long gap is kept, and stated
    assert long.reading["window"] == {"first_frame": 70, "n_frames": bvh.n_frames - 70, "of_frames": bvh.n_frames,
                                      "why": long.reading["window"]["why"]}
    assert f"kept frames 70-{bvh.n_frames - 1} of {bvh.n_frames}" in long.source
    np.testing.assert_allclose(long.positions_m, bvh.positions_m[70:], atol=1e-4)
    short_clip = dataclasses.replace(bvh, positions_m=bvh.positions_m[:150], rotations=None)   # 1.25 s
    path = write_c3d(short_clip, tmp_path / "gap.c3d", occlude=(40, 3), n_occluded=30)
    with pytest.raises(MotionFormatError, match=rf"gap.c3d: point '{bvh.joint_names[3]}': expected every needed "
                                                r"marker present \(gaps up to 0.2 s filled\) over at least 1 s, found "
                                                rf"'{bvh.joint_names[3]}' missing in 30 of 150 frames, a gap of 30 frames "
                                                r"from frame 40; the longest complete window is 80 frames \(0.67 s from "
                                                r"frame 70\)"):
        read_motion(path)


# --------------------------------------------------------------------------------------------
# the one C3D reader (effortface.synth.c3d_motion): labelled points and Plug-in Gait alike


def _write_points(path: Path, labels: list[str], xyz: np.ndarray, units: str = "mm", fps: float = 100.0) -> Path:
    """Labelled points (T, P, 3) in ``units`` as a C3D file declaring them."""
    writer = c3d.Writer(point_rate=fps, analog_rate=0, point_units=f"{units:<4}")
    writer.set_point_labels(labels)
    frames = []
    for frame in xyz:
        points = np.zeros((len(labels), 5), dtype=np.float32)
        points[:, :3] = frame
        frames.append((points, np.zeros((0, 0), dtype=np.float32)))
    with open(path, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        writer.add_frames(frames)
        writer.write(fh)
    return path


def _walk_xyz(n_frames: int = 20) -> np.ndarray:
    """Two points moving 1 unit a frame along x, 40 and 90 units up."""
    t = np.arange(n_frames, dtype=float)
    return np.stack([np.column_stack([t, np.zeros_like(t), np.full_like(t, h)]) for h in (90.0, 40.0)], axis=1)


def test_read_c3d_is_the_one_api_for_labelled_points_with_its_units_and_up_axis(tmp_path: Path) -> None:
    from effortface.synth.c3d_motion import read_c3d

    path = _write_points(tmp_path / "in.c3d", ["Hips", "LeftFoot"], _walk_xyz(), units="in")
    motion = read_c3d(path)
    assert motion.joint_names == ("Hips", "LeftFoot") and list(motion.parents) == [-1, 0]
    np.testing.assert_allclose(motion.positions_m, _walk_xyz() * 0.0254, rtol=1e-6)
    assert motion.fps == 100.0 and motion.positions_m.shape == read_motion(path).positions_m.shape
    y_up = read_c3d(path, up_axis="y")
    np.testing.assert_allclose(y_up.positions_m[..., 2], motion.positions_m[..., 1], atol=1e-9)
    np.testing.assert_allclose(y_up.positions_m[..., 0], motion.positions_m[..., 2], rtol=1e-6)


def test_an_all_zero_point_is_missing_in_labelled_points_too(tmp_path: Path) -> None:
    """The one definition of a missing point: before, labelled points took an all-zero gap as a
    position at the lab origin (a 2 m jump in one frame)."""
    xyz = _walk_xyz()
    truth = xyz.copy()
    xyz[7:9, 1] = 0.0
    path = _write_points(tmp_path / "gap.c3d", ["Hips", "LeftFoot"], xyz)
    motion = read_motion(path)              # a 2-frame gap: interpolated, not taken as the origin
    assert "linearly interpolated (2 point-frames)" in motion.source
    assert np.abs(motion.positions_m[7:9, 1] - truth[7:9, 1] / 1000).max() < 0.05


def test_without_the_c3d_package_reading_and_writing_say_what_to_install(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from effortface.synth.c3d_motion import write_c3d_markers

    path = _write_points(tmp_path / "clip.c3d", ["Hips", "LeftFoot"], _walk_xyz())
    monkeypatch.setitem(sys.modules, "c3d", None)  # `import c3d` raises ImportError, as in the runtime's venv
    monkeypatch.setitem(sys.modules, "ezc3d", None)
    expected = r"expected the 'c3d' package to read C3D files, found it not installed \(pip install 'c3d>=0\.5\.2,<0\.7'\)"
    with pytest.raises(MotionFormatError, match=rf"clip\.c3d: {expected}"):
        read_motion(path)
    with pytest.raises(MotionFormatError, match=rf"new\.c3d: {expected}"):
        write_c3d_markers(tmp_path / "new.c3d", {"Hips": _walk_xyz()[:, 0]}, 100.0)
    assert not (tmp_path / "new.c3d").exists()


def test_a_bad_up_axis_is_named(tmp_path: Path) -> None:
    from effortface.core.errors import UserError
    from effortface.synth.c3d_motion import read_c3d

    with pytest.raises(UserError, match=r"up: expected one of x, y, z, -x, -y, -z, found 'w'"):
        read_c3d(tmp_path / "none.c3d", up="w")
