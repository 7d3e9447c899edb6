"""Issue 34: BVH bones as the file means them (position channels replace the OFFSET), the unit from
the rest pose's size, the up axis from gravity over the clip, and how it was read (Motion.reading)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from effortface.core.errors import UserError
from effortface.synth import motion as motion_module
from effortface.synth.motion import (
    UP_TO_Z_UP,
    Motion,
    read_bvh,
    read_motion,
    read_motion_blocks,
    register_motion_reader,
)
from tests.synth.bvh_fixtures import bandai_layout_bvh

#: a hand-written skeleton: position channels on the root and on child joints (all three on Chest,
#: only Yposition on Leg), rotations on some joints; metres, one frame
HAND_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 5 6 7
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 20 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 5 0
      }
    }
  }
  JOINT Leg
  {
    OFFSET 3 -50 0
    CHANNELS 4 Yposition Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -40 0
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.04
1 100 2 90 0 0  0 12 3 0 0 0  0 0 0  -45 0 90 0
"""

#: the same frame posed by hand (file units, Y up). The root's rotation is Rz(90): (x, y, z) ->
#: (-y, x, z). Hips: its channels (1, 100, 2), not OFFSET + channels (6, 106, 9). Chest: root +
#: Rz(90) (0, 12, 3) = (-11, 100, 5). Head: Chest + Rz(90) (0, 20, 0) = (-31, 100, 5); its End Site
#: + Rz(90) (0, 5, 0) = (-36, 100, 5). Leg: Yposition -45 replaces the OFFSET's y, its x (3) and
#: z (0) stay: root + Rz(90) (3, -45, 0) = (46, 103, 2). Leg's End Site: Rz(90) Rx(90) (0, -40, 0)
#: = Rz(90) (0, 0, -40) = (0, 0, -40) -> (46, 103, -38).
HAND_POSED_Y_UP = {
    "Hips": (1, 100, 2), "Chest": (-11, 100, 5), "Head": (-31, 100, 5), "Head_end": (-36, 100, 5),
    "Leg": (46, 103, 2), "Leg_end": (46, 103, -38),
}


def _z_up(y_up: tuple[float, float, float]) -> tuple[float, float, float]:
    """A file's Y-up point in Z up: x' = z, y' = x, z' = y."""
    x, y, z = y_up
    return z, x, y


def test_position_channels_replace_the_offset_forward_kinematics_by_hand(tmp_path: Path) -> None:
    path = tmp_path / "hand.bvh"
    path.write_text(HAND_BVH)
    motion = read_bvh(path, unit_m=1.0, up_axis="y")
    assert motion.joint_names == tuple(HAND_POSED_Y_UP)
    for name, expected in HAND_POSED_Y_UP.items():
        np.testing.assert_allclose(motion.positions_m[0, motion.joint_names.index(name)], _z_up(expected),
                                   atol=1e-12, err_msg=name)
    blocks = read_motion_blocks(path, unit_m=1.0, up="y")
    np.testing.assert_array_equal(next(blocks.blocks())[0], motion.positions_m)


def test_the_bandai_layout_reads_one_bone_per_bone(tmp_path: Path) -> None:
    """6 channels on every joint, positions repeating the OFFSETs: the thigh is the file's 42 cm
    (it was 84 cm when the channels were added to the OFFSET), the body 1.5-1.7 m tall."""
    path = bandai_layout_bvh(tmp_path / "walk.bvh")
    motion = read_motion(path)
    names = motion.joint_names
    thigh = motion.positions_m[:, names.index("LowerLeg_L")] - motion.positions_m[:, names.index("UpperLeg_L")]
    np.testing.assert_allclose(np.linalg.norm(thigh, axis=-1), 0.42, atol=1e-9)
    hips_z = motion.positions_m[:, names.index("Hips"), 2]
    assert 0.90 < hips_z.min() and hips_z.max() < 0.96  # the Hips' position channel, not OFFSET + channel
    assert motion.reading["unit_m"] == 0.01
    assert motion.reading["unit_from"] == "rest pose 142 units along x -> centimetre (0.01 m)"
    assert motion.reading["up_axis"] == "y"
    assert motion.reading["up_from"].startswith("gravity over the clip: the head above the feet along y in 100%")
    assert "the rest pose lies along x (not upright: not used)" in motion.reading["up_from"]


def test_the_streamed_reader_agrees_with_the_whole_clip_reader(tmp_path: Path) -> None:
    path = bandai_layout_bvh(tmp_path / "walk.bvh", n_frames=300)
    whole = read_motion(path)
    blocks = read_motion_blocks(path, reference_frames=100)
    np.testing.assert_array_equal(np.concatenate([p for p, _ in blocks.blocks()]), whole.positions_m)
    np.testing.assert_array_equal(np.concatenate([r for _, r in blocks.blocks()]), whole.rotations)
    np.testing.assert_array_equal(blocks.skeleton.positions_m, whole.positions_m[::3])
    assert blocks.skeleton.reading == whole.reading


@pytest.mark.parametrize("root_zxy, up", [((0, 0, 0), "y"), ((0, 90, 0), "z"), ((0, -90, 0), "-z"),
                                          ((-90, 0, 0), "x"), ((90, 0, 0), "-x"), ((180, 0, 0), "-y")])
def test_the_up_axis_comes_from_gravity_over_the_clip(tmp_path: Path, root_zxy, up: str) -> None:
    """The same walk stood up along each axis of the file: read Z up, the same heights above the
    floor and the same bone lengths; ``--up`` given says so."""
    reference = read_motion(bandai_layout_bvh(tmp_path / "y.bvh"))
    path = bandai_layout_bvh(tmp_path / f"{up}.bvh", root_rotation_zxy=root_zxy)
    motion = read_motion(path)
    assert motion.reading["up_axis"] == up
    np.testing.assert_allclose(motion.positions_m[..., 2], reference.positions_m[..., 2], atol=1e-9)
    given = read_motion(path, up=up)
    np.testing.assert_array_equal(given.positions_m, motion.positions_m)
    assert given.reading["up_from"] == "given (--up)"
    blocks = read_motion_blocks(path)
    assert blocks.skeleton.reading["up_axis"] == up


def test_every_up_turn_is_a_proper_rotation() -> None:
    for up, turn in UP_TO_Z_UP.items():
        assert np.linalg.det(turn) == pytest.approx(1.0)
        axis = np.zeros(3)
        axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
        np.testing.assert_array_equal(turn @ axis, [0, 0, 1])


def test_a_wrong_up_option_is_named(tmp_path: Path) -> None:
    path = bandai_layout_bvh(tmp_path / "walk.bvh")
    with pytest.raises(UserError, match=r"up_axis: expected one of x, y, z, -x, -y, -z, found 'w'"):
        read_motion(path, up="w")


def test_csv_and_npz_say_how_they_were_read(shared_data: Path, tmp_path: Path) -> None:
    from effortface.synth.motion_csv import write_positions_csv

    npz = read_motion(shared_data / "motion" / "amp_humanoid_walk.npz")
    assert npz.reading == {"unit_m": 1.0, "unit_from": "the format (metres)", "up_axis": "z",
                           "up_from": "the format (Z up)"}
    csv = read_motion(write_positions_csv(tmp_path / "walk.csv", npz))
    assert csv.reading["unit_from"] == "the column names (<joint>_x_m: metres)"
    assert csv.reading["up_axis"] == "z" and csv.reading["up_from"].startswith("gravity over the clip")
    # the same positions written Y up: detected and turned back
    y_up = Motion(npz.joint_names, npz.parents, npz.positions_m[..., [1, 2, 0]], None, npz.fps, "y")
    turned = read_motion(write_positions_csv(tmp_path / "walk_y.csv", y_up))
    assert turned.reading["up_axis"] == "y"
    np.testing.assert_allclose(turned.positions_m, csv.positions_m, atol=1e-5)


def test_a_reader_registered_with_two_arguments_still_reads(tmp_path: Path, monkeypatch) -> None:
    """register_motion_reader's old contract, reader(path, unit_m); an up axis it cannot take is refused."""
    path = bandai_layout_bvh(tmp_path / "walk.bvh")
    monkeypatch.setattr(motion_module, "_READERS", dict(motion_module._READERS))
    register_motion_reader(".bvhx", lambda p, unit_m: read_bvh(p.with_suffix(".bvh"), unit_m=unit_m))
    (tmp_path / "walk.bvhx").write_text("")
    motion = read_motion(tmp_path / "walk.bvhx", unit_m=0.01)
    assert motion.reading["unit_m"] == 0.01
    with pytest.raises(UserError, match=r"walk\.bvhx: --up: the reader registered for \.bvhx takes no up axis"):
        read_motion(tmp_path / "walk.bvhx", up="z")


#: Blender 5.0.1's BVH importer (``bpy.ops.import_anim.bvh``, global_scale 1, rotate_mode NATIVE) on
#: HAND_BVH with all three position channels on Leg (``3 -45 0``): the armature's bone heads and the
#: End Sites' tails at frame 1, in Blender's axes (x, -z, y of the file). Measured on 2026-11-28
#: (pip install bpy, Python 3.11); bpy is not a dependency, so its numbers are kept here.
BLENDER_HAND_FULL = {
    "Hips": (1.0, -2.0, 100.0), "Chest": (-11.0, -5.0, 100.0), "Head": (-31.0, -5.0, 100.0),
    "Leg": (46.0, -2.0, 103.0), "Head_end": (-36.0, -5.0, 100.0), "Leg_end": (46.0, 38.0, 103.0),
}


def test_blenders_importer_reads_the_same_bones(tmp_path: Path) -> None:
    path = tmp_path / "hand_full.bvh"
    path.write_text(HAND_BVH.replace("CHANNELS 4 Yposition Zrotation", "CHANNELS 6 Xposition Yposition Zposition "
                                     "Zrotation").replace("0 0 0  -45 0 90 0", "0 0 0  3 -45 0 0 90 0"))
    motion = read_bvh(path, unit_m=1.0, up_axis="y")
    for name, (bx, by, bz) in BLENDER_HAND_FULL.items():
        file_xyz = (bx, bz, -by)
        np.testing.assert_allclose(motion.positions_m[0, motion.joint_names.index(name)], _z_up(file_xyz),
                                   atol=1e-9, err_msg=name)


def test_a_csv_without_units_in_centimetres_is_detected_and_given(shared_data: Path, tmp_path: Path) -> None:
    """``<joint>_x`` columns hold the format's metres; a body 155 units tall is read as centimetres."""
    npz = read_motion(shared_data / "motion" / "amp_humanoid_walk.npz").slice_s(0, 1)
    names = npz.joint_names
    header = "t_s," + ",".join(f"{n}_{a}" for n in names for a in "xyz")
    rows = [",".join([f"{t:.6f}", *(f"{v * 100:.4f}" for v in frame.ravel())])
            for t, frame in zip(npz.t_s, npz.positions_m)]
    path = tmp_path / "cm.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    motion = read_motion(path)
    assert motion.reading["unit_m"] == 0.01 and motion.reading["unit_from"].endswith("-> centimetre")
    np.testing.assert_allclose(motion.positions_m, npz.positions_m, atol=1e-6)
    given = read_motion(path, unit_m=0.01)
    assert given.reading["unit_from"] == "given (--unit-m)"
    np.testing.assert_allclose(given.positions_m, motion.positions_m)


def test_a_c3d_takes_the_up_axis(shared_data: Path) -> None:
    path = shared_data / "c3d" / "PiG_Calibration-FlatFoot-Full.c3d"
    z_up = read_motion(path)
    laid = read_motion(path, up="y")
    assert not np.allclose(laid.positions_m, z_up.positions_m)
    with pytest.raises(UserError, match=r"up_axis: expected one of"):
        read_motion(path, up="q")


def test_a_body_leaning_far_forward_keeps_the_formats_up_axis(tmp_path: Path) -> None:
    """A push-up: the body lies mostly along x (25 degrees from it), its head above its feet: y stays up."""
    path = bandai_layout_bvh(tmp_path / "pushup.bvh", root_rotation_zxy=(-65, 0, 0))
    motion = read_motion(path)
    assert motion.reading["up_axis"] == "y"
    assert motion.reading["up_from"].endswith("(the format's convention); the rest pose lies along x "
                                              "(not upright: not used)")


def test_a_given_unit_replaces_a_declared_one(shared_data: Path, tmp_path: Path) -> None:
    npz = read_motion(shared_data / "motion" / "amp_humanoid_walk.npz")
    halved = read_motion(shared_data / "motion" / "amp_humanoid_walk.npz", unit_m=0.5)
    np.testing.assert_allclose(halved.positions_m, npz.positions_m * 0.5)
    assert halved.reading["unit_from"] == "given (--unit-m; the file says 1 m)"
    # a reader that says no unit: the option is refused, not ignored
    monkey = dict(motion_module._READERS)
    try:
        register_motion_reader(".npy3", lambda p, unit_m, up: motion_module._given_unit(
            dataclasses.replace(npz, reading={}, source=str(p)), unit_m))
        with pytest.raises(UserError, match=r"walk\.npy3: --unit-m: expected a reader that says the unit it read"):
            read_motion(tmp_path / "walk.npy3", unit_m=0.01)
    finally:
        motion_module._READERS.clear()
        motion_module._READERS.update(monkey)
