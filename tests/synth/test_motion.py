"""Motion readers: BVH (CMU cgspeed), AMP .npz clips, plain positions, and their errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from effortface.synth.motion import (
    Motion,
    CMU_UNIT_M,
    MotionFormatError,
    detect_bvh_unit_m,
    motion_from_positions,
    read_bvh,
    read_motion,
    read_npz_motion,
)
from effortface.core.errors import UserError

JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"


@pytest.fixture(scope="module")
def jj(shared_data: Path) -> Motion:
    return read_bvh(shared_data / JJ)


def test_cmu_bvh_is_read_in_metres_z_up(jj: Motion) -> None:
    """The cgspeed unit is detected, Y-up becomes Z-up and the frame time gives 120 fps."""
    assert jj.fps == 120.0
    assert jj.positions_m.shape == (439, 38, 3)
    assert jj.rotations is not None and jj.rotations.shape == (439, 38, 3, 3)
    names = jj.joint_names
    head, foot = names.index("Head_end"), names.index("LeftFoot")
    assert np.all(jj.positions_m[:, head, 2] > jj.positions_m[:, foot, 2] + 1.0)
    last = jj.positions_m[-1]
    assert 1.1 < last[:, 2].max() - last[:, 2].min() < 2.3


def test_bvh_forward_kinematics_keeps_bones_rigid(jj: Motion, shared_data: Path) -> None:
    """Every bone keeps its OFFSET length (times 0.05644 m) in every frame; rotations stay orthonormal."""
    lines = (shared_data / JJ).read_text().splitlines()
    offsets = [list(map(float, ln.split()[1:])) for ln in lines if ln.strip().startswith("OFFSET")]
    lengths = np.linalg.norm(np.array(offsets), axis=1) * CMU_UNIT_M
    for j, p in enumerate(jj.parents):
        if p >= 0:
            bone = np.linalg.norm(jj.positions_m[:, j] - jj.positions_m[:, p], axis=1)
            np.testing.assert_allclose(bone, lengths[j], atol=1e-9)
    r = jj.rotations
    assert r is not None
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)


def test_explicit_unit_scales_positions(jj: Motion, shared_data: Path) -> None:
    """An explicit unit_m overrides detection; positions scale linearly."""
    inches = read_bvh(shared_data / JJ, unit_m=0.0254)
    np.testing.assert_allclose(inches.positions_m * CMU_UNIT_M / 0.0254, jj.positions_m, atol=1e-12)


@pytest.mark.parametrize(
    ("height_units", "unit"),
    [(1.75, "metre"), (30.0, "CMU cgspeed unit"), (68.0, "inch"), (175.0, "centimetre"), (1750.0, "millimetre")],
)
def test_unit_rule(height_units: float, unit: str) -> None:
    assert detect_bvh_unit_m(height_units)[0] == unit


def test_npz_clip_has_end_sites_and_speed(shared_data: Path) -> None:
    """The AMP run clip: 60 fps, Z up, end sites added, pelvis moves about 3.4 m/s forward."""
    run = read_npz_motion(shared_data / "motion/amp_humanoid_run.npz")
    assert run.fps == 60.0 and run.rotations is not None
    assert {"head_end", "left_hand_end", "right_foot_toe"} <= set(run.joint_names)
    pelvis = run.positions_m[:, 0]
    speed = np.linalg.norm(pelvis[-1, :2] - pelvis[0, :2]) / (run.t_s[-1] - run.t_s[0])
    assert 3.0 < speed < 3.8
    head = run.positions_m[:, run.joint_names.index("head_end"), 2]
    assert np.all(head > 1.4)


def test_read_motion_dispatch_and_decimate(shared_data: Path) -> None:
    squats = read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh")
    assert squats.n_frames == 813
    d = squats.decimate(4)
    assert d.fps == 30.0 and d.n_frames == 204
    np.testing.assert_array_equal(d.positions_m[1], squats.positions_m[4])
    assert read_motion(shared_data / "motion/amp_humanoid_walk.npz").n_frames == 154


def _bvh_variant(shared_data: Path, tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    text = (shared_data / JJ).read_text()
    assert old in text
    out = tmp_path / "bad.bvh"
    out.write_text(text.replace(old, new, count))
    return out


# message regex -> (text replaced, replacement)
BAD_BVH = {
    r"bad\.bvh: line 4: expected 'OFFSET', found 'OFSET'": ("OFFSET 0.00000 0.00000 0.00000", "OFSET 0 0 0"),
    r"bad\.bvh: line 5: expected a channel name .*found 'Wrotation'": ("Zrotation Yrotation Xrotation", "Zrotation Yrotation Wrotation"),
    r"bad\.bvh: line 187: expected 'Frame Time: <number>'": ("Frame Time: .0083333", "Frame Time: fast"),
    r"bad\.bvh: line 188: expected 96 numbers, found 'nan\?'": ("-0.0035 15.8971", "nan? 15.8971"),
    r"bad\.bvh: line \d+: expected 500 frame lines \(Frames:\), found 439": ("Frames: 439", "Frames: 500"),
}


@pytest.mark.parametrize(("match", "edit"), list(BAD_BVH.items()), ids=list(range(len(BAD_BVH))))
def test_malformed_bvh_names_file_and_line(shared_data: Path, tmp_path: Path, match: str, edit: tuple[str, str]) -> None:
    path = _bvh_variant(shared_data, tmp_path, *edit)
    with pytest.raises(MotionFormatError, match=match):
        read_bvh(path)


def test_truncated_frame_line_is_named(shared_data: Path, tmp_path: Path) -> None:
    lines = (shared_data / JJ).read_text().splitlines()
    lines[199] = " ".join(lines[199].split()[:-3])
    path = tmp_path / "short.bvh"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MotionFormatError, match=r"short\.bvh: line 200: expected 96 numbers, found 93"):
        read_bvh(path)


BAD_OTHER = {
    r"clip\.fbx: expected a motion file ending in \.bvh, \.npz, \.c3d, \.csv, got suffix '\.fbx'": "clip.fbx",
    r"missing\.bvh: expected a readable BVH file": "missing.bvh",
    r"empty\.npz: expected a readable \.npz": "empty.npz",
}


@pytest.mark.parametrize(("match", "name"), list(BAD_OTHER.items()), ids=list(BAD_OTHER.values()))
def test_read_motion_rejects_bad_files(tmp_path: Path, match: str, name: str) -> None:
    if name != "missing.bvh":
        (tmp_path / name).write_bytes(b"not a motion")
    with pytest.raises(MotionFormatError, match=match):
        read_motion(tmp_path / name)


def test_npz_missing_key_is_named(tmp_path: Path) -> None:
    path = tmp_path / "partial.npz"
    np.savez(path, fps=60, node_names=np.array(["pelvis"]))
    with pytest.raises(MotionFormatError, match=r"partial\.npz: .*missing parent_indices"):
        read_npz_motion(path)


BAD_POSITIONS = {
    r"positions_m: expected shape \(T >= 1, 2, 3\)": dict(positions_m=np.zeros((5, 3, 3)), fps=30),
    r"positions_m: expected shape \(T >= 1, 2, 3\) with 2 parents, got \(0, 2, 3\)": dict(
        positions_m=np.zeros((0, 2, 3)), fps=30),
    r"fps: expected a positive number, got -1": dict(positions_m=np.zeros((5, 2, 3)), fps=-1),
}


@pytest.mark.parametrize(("match", "kw"), list(BAD_POSITIONS.items()), ids=["shape", "empty", "fps"])
def test_motion_from_positions_checks(match: str, kw: dict) -> None:
    with pytest.raises(UserError, match=match):
        motion_from_positions(joint_names=("a", "b"), parents=(-1, 0), **kw)


def test_undetectable_unit_asks_for_unit_m() -> None:
    with pytest.raises(UserError, match=r"unit_m: cannot tell the BVH length unit .* pass unit_m"):
        detect_bvh_unit_m(5.0)


def _tiny_bvh(order: str, frame: str) -> str:
    """A 3-joint metre BVH (any names) with the given rotation channel order and one frame."""
    rot = " ".join(f"{a}rotation" for a in order)
    return f"""HIERARCHY
ROOT pelvis_bone
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {rot}
  JOINT spine_bone
  {{
    OFFSET 0 0.5 0
    CHANNELS 3 {rot}
    End Site
    {{
      OFFSET 0 0.7 0
    }}
  }}
}}
MOTION
Frames: 1
Frame Time: 0.02
{frame}
"""


def test_any_names_and_channel_order(tmp_path: Path) -> None:
    """Hand-computed forward kinematics: R_local = product of the channel rotations in file order.

    Root at (0, 1, 0) (Y-up) turned by X 90 deg then Z 90 deg (order 'XZY': R = Rx Rz Ry). The spine
    joint sits at root + R (0, 0.5, 0) = (0, 1, 0) + Rx(90) Rz(90) (0, 0.5, 0) = (-0.5, 1, 0);
    with order 'ZXY' (R = Rz Rx) the same angles give (0, 1, 0.5). Z-up: (x, y, z) -> (z, x, y).
    """
    cases = {"XZY": [-0.5, 1.0, 0.0], "ZXY": [0.0, 1.0, 0.5]}
    for order, expected_y_up in cases.items():
        angles = {"X": 90.0, "Z": 90.0, "Y": 0.0}
        values = " ".join(str(angles[a]) for a in order)
        path = tmp_path / f"tiny_{order}.bvh"
        path.write_text(_tiny_bvh(order, f"0 1 0 {values} 0 0 0"))
        motion = read_bvh(path)
        assert motion.joint_names == ("pelvis_bone", "spine_bone", "spine_bone_end")
        assert motion.fps == 50.0
        x, y, z = expected_y_up
        np.testing.assert_allclose(motion.positions_m[0, 1], [z, x, y], atol=1e-12)


# --------------------------------------------------------------------------------------------
# bad skeletons and values (audit: parentsself.npz hang, parents99.npz IndexError, NaN frames,
# empty.npz EOFError, fps0.npz named cutoff_hz, onejoint.bvh asked for a missing option)

AMP = "motion/amp_humanoid_walk.npz"


def _npz_variant(shared_data: Path, tmp_path: Path, **changes) -> Path:
    """A copy of the AMP walk clip with some arrays replaced (values may be callables of the old)."""
    with np.load(shared_data / AMP, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    for key, value in changes.items():
        data[key] = value(data[key].copy()) if callable(value) else value
    out = tmp_path / "bad.npz"
    np.savez(out, **data)
    return out


def _set(index, value):
    def edit(a: np.ndarray) -> np.ndarray:
        a[index] = value
        return a
    return edit


BAD_NPZ = {
    r"bad\.npz: parent_indices: expected -1 or the index of an earlier joint .*joint 0 with parent 0":
        dict(parent_indices=_set(0, 0)),
    r"bad\.npz: parent_indices: .*joint 3 with parent 3": dict(parent_indices=_set(3, 3)),
    r"bad\.npz: parent_indices: .*joint 2 with parent 5": dict(parent_indices=_set(2, 5)),
    r"bad\.npz: parent_indices: .*joint 1 with parent 99": dict(parent_indices=_set(1, 99)),
    r"bad\.npz: parent_indices: .*joint 1 with parent -7": dict(parent_indices=_set(1, -7)),
    r"bad\.npz: parent_indices: expected a 1-D array of integers": dict(
        parent_indices=lambda a: a.astype(str)),
    r"bad\.npz: root_translation: expected finite numbers, found nan at frame 7":
        dict(root_translation=_set((7, 1), np.nan)),
    r"bad\.npz: rotation_xyzw_local: expected finite numbers, found inf at frame 3":
        dict(rotation_xyzw_local=_set((3, 2, 0), np.inf)),
    r"bad\.npz: rotation_xyzw_local: expected unit quaternions, found \(0, 0, 0, 0\) at frame 4":
        dict(rotation_xyzw_local=_set((4, 1), 0.0)),
    r"bad\.npz: local_translation: expected finite numbers, found nan": dict(
        local_translation=_set((2, 0), np.nan)),
    r"bad\.npz: fps: expected one positive frame rate, found 0": dict(fps=np.array(0)),
    r"bad\.npz: fps: expected one positive frame rate, found -30": dict(fps=np.array(-30.0)),
    r"bad\.npz: fps: expected one positive frame rate, found nan": dict(fps=np.array(np.nan)),
    r"bad\.npz: fps: expected one positive frame rate, found \[30, 60\]": dict(fps=np.array([30, 60])),
    r"bad\.npz: fps: expected one positive frame rate, found abc": dict(fps=np.array("abc")),
    r"bad\.npz: root_translation: expected numbers, found <U": dict(
        root_translation=lambda a: a.astype(str)),
}


@pytest.mark.parametrize(("match", "changes"), list(BAD_NPZ.items()), ids=list(range(len(BAD_NPZ))))
def test_bad_npz_content_is_named(shared_data: Path, tmp_path: Path, match: str, changes: dict) -> None:
    """Cyclic/out-of-range parents (which hung or raised IndexError), NaN values and bad fps."""
    with pytest.raises(MotionFormatError, match=match):
        read_npz_motion(_npz_variant(shared_data, tmp_path, **changes))


def test_empty_and_npy_files_are_named(tmp_path: Path) -> None:
    """A 0-byte .npz raised EOFError; a plain .npy array under .npz broke the context manager."""
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(MotionFormatError, match=r"empty\.npz: expected a readable \.npz motion file"):
        read_motion(tmp_path / "empty.npz")
    np.save(tmp_path / "one.npy", np.zeros(3))
    (tmp_path / "one.npy").rename(tmp_path / "one.npz")
    with pytest.raises(MotionFormatError, match=r"one\.npz: expected a \.npz archive of arrays"):
        read_motion(tmp_path / "one.npz")


BAD_BVH_VALUES = {
    r"bad\.bvh: line 188: expected finite numbers in frame 0, found nan": ("-0.0035 15.8971", "nan 15.8971"),
    r"bad\.bvh: line 188: expected finite numbers in frame 0, found inf": ("-0.0035 15.8971", "-0.0035 inf"),
    r"bad\.bvh: line 4: expected an OFFSET number \(finite\), found 'nan'":
        ("OFFSET 0.00000 0.00000 0.00000", "OFFSET nan 0 0"),
    r"bad\.bvh: line 186: expected 'Frames: <number>', found 'Frames: inf'": ("Frames: 439", "Frames: inf"),
    r"bad\.bvh: line 186: expected 'Frames: <number>', found 'Frames: nan'": ("Frames: 439", "Frames: nan"),
}


@pytest.mark.parametrize(("match", "edit"), list(BAD_BVH_VALUES.items()), ids=list(range(len(BAD_BVH_VALUES))))
def test_non_finite_bvh_values_are_named(shared_data: Path, tmp_path: Path, match: str,
                                         edit: tuple[str, str]) -> None:
    """A NaN frame used to turn almost every output row into NaN; now the file and line are named."""
    with pytest.raises(MotionFormatError, match=match):
        read_bvh(_bvh_variant(shared_data, tmp_path, *edit))


def test_undetectable_bvh_unit_names_the_file(tmp_path: Path) -> None:
    """A 1-unit-tall skeleton: say what the file lacks, not to pass an option the CLI lacks."""
    path = tmp_path / "tiny.bvh"
    path.write_text(_tiny_bvh("XYZ", "0 0 0 0 0 0 0 0 0").replace("OFFSET 0 0.7 0", "OFFSET 0 0.05 0")
                    .replace("OFFSET 0 0.5 0", "OFFSET 0 0.05 0"))
    with pytest.raises(MotionFormatError, match=r"tiny\.bvh: expected a skeleton whose rest pose is "
                                                r"1\.1-2\.3 m tall .*found a rest-pose height of 0\.1 file units"):
        read_bvh(path)
    assert read_bvh(path, unit_m=10.0).positions_m.shape == (1, 3, 3)


@pytest.mark.parametrize(("match", "kw"), [
    (r"cycle: parent_indices: .*joint 0 with parent 1", dict(parents=(1, 0))),
    (r"cycle: parent_indices: .*joint 1 with parent 9", dict(parents=(-1, 9))),
    (r"cycle: positions_m: expected finite numbers, found nan at frame 2", dict(
        parents=(-1, 0), positions_m=np.where(np.arange(5)[:, None, None] == 2, np.nan, np.zeros((5, 2, 3))))),
    (r"fps: expected a positive number, got nan", dict(parents=(-1, 0), fps=float("nan"))),
], ids=["cycle", "range", "nan", "fps-nan"])
def test_motion_from_positions_checks_skeleton_and_values(match: str, kw: dict) -> None:
    args = dict(positions_m=np.zeros((5, 2, 3)), fps=30.0) | kw
    with pytest.raises(UserError, match=match):
        motion_from_positions(joint_names=("a", "b"), source="cycle", **args)
