"""Issue 34: the plausibility gate refuses a body outside the human ranges in one line naming the
file and the figure (exit 2, nothing written), proceeds with --trust-skeleton, and lets every real
clip of tests/data through."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.synth.motion import Motion, read_motion
from effortface.synth.plausibility import ImplausibleBodyError, check_plausible, measure_body, spatial_axes
from tests.synth.bvh_fixtures import bandai_layout_bvh, doubled_positions

#: the real clips of tests/data that read as a whole body (C3D files without a full body or with gaps
#: are refused by their reader before the gate; see tests/synth/test_motion_c3d_real.py)
REAL_CLIPS = ("bvh/pymo_walk.bvh", "motion/cmu_13_29_full_30fps.bvh", "motion/cmu_13_29_jumping_jacks_120fps.bvh",
              "motion/cmu_13_29_squats_120fps.bvh", "motion/amp_humanoid_walk.npz", "motion/amp_humanoid_run.npz",
              "motion/amp_humanoid_hop.npz", "c3d/PiG_Calibration-FlatFoot-Full.c3d")


def _synth(tmp_path: Path, clip: Path, *extra: str) -> tuple[int, Path]:
    out = tmp_path / "out.csv"
    return main(["synth", "default", str(clip), "--out", str(out), *extra]), out


def test_the_old_readers_doubled_bones_are_refused_in_one_line(tmp_path: Path, capsys) -> None:
    """The body the reader made of a 6-channel file before issue 34 (OFFSET + channel: every bone
    twice its length) is refused naming the file and its height; nothing is written."""
    clip = doubled_positions(bandai_layout_bvh(tmp_path / "walk.bvh"), tmp_path / "doubled.bvh")
    status, out = _synth(tmp_path, clip, "--unit-m", "0.01")
    err = capsys.readouterr().err
    assert status == 2
    assert err == (f"effortface synth: error: {clip}: standing height 3.16 m: expected 1.2-2.2 m; check --unit-m "
                   "/ --up or the skeleton's position channels (or --trust-skeleton for a child, a creature or a clip "
                   "that never stands up)\n")
    assert not out.exists() and not (tmp_path / "out.units.json").exists()


def test_the_same_walk_read_right_passes(tmp_path: Path, capsys) -> None:
    status, out = _synth(tmp_path, bandai_layout_bvh(tmp_path / "walk.bvh"))
    assert status == 0, capsys.readouterr().err
    body = json.loads((tmp_path / "out.units.json").read_text())["reading"]["body"]
    assert 1.5 < body["height_m"] < 1.7 and body["segments_m"]["left_thigh"] == pytest.approx(0.42)
    assert not body["trusted"]


def test_a_child_is_refused_unless_trusted(tmp_path: Path, capsys) -> None:
    clip = bandai_layout_bvh(tmp_path / "child.bvh", scale=0.7)
    status, out = _synth(tmp_path, clip, "--unit-m", "0.01")
    assert status == 2 and not out.exists()
    assert f"{clip}: standing height 1.11 m: expected 1.2-2.2 m" in capsys.readouterr().err
    status, out = _synth(tmp_path, clip, "--unit-m", "0.01", "--trust-skeleton")
    assert status == 0 and out.exists()
    assert "outside the human ranges: --trust-skeleton" in capsys.readouterr().out
    assert json.loads((tmp_path / "out.units.json").read_text())["reading"]["body"]["trusted"]


def test_a_wrong_unit_is_refused_by_a_segment(tmp_path: Path) -> None:
    """A body of the right height with an arm 2.5 times too long: the segment is named."""
    motion = read_motion(bandai_layout_bvh(tmp_path / "walk.bvh"))
    pos = motion.positions_m.copy()
    hand = motion.joint_names.index("Hand_L")
    elbow = motion.joint_names.index("LowerArm_L")
    pos[:, hand] = pos[:, elbow] + 2.5 * (pos[:, hand] - pos[:, elbow])
    with pytest.raises(ImplausibleBodyError, match=r"walk\.bvh: left forearm 0\.62 m: expected 0\.15-0\.4 m; check"):
        check_plausible(Motion(motion.joint_names, motion.parents, pos, None, motion.fps, motion.source))


def test_a_body_lying_on_its_side_is_refused(tmp_path: Path) -> None:
    """Read with the wrong up axis: the standing height is the body's depth."""
    motion = read_motion(bandai_layout_bvh(tmp_path / "walk.bvh"), up="z")
    with pytest.raises(ImplausibleBodyError, match=r"walk\.bvh: standing height 0\.\d\d m: expected 1\.2-2\.2 m"):
        check_plausible(motion)
    assert check_plausible(motion, trust=True)["trusted"]


def test_a_ground_that_is_no_plane_is_refused(tmp_path: Path) -> None:
    """The lowest joint rising by 1 m a frame every other frame (the floor is not under the body)."""
    motion = read_motion(bandai_layout_bvh(tmp_path / "walk.bvh"))
    pos = motion.positions_m.copy()
    pos[1::2, :, 2] += 1.0
    figures = measure_body(Motion(motion.joint_names, motion.parents, pos, None, motion.fps, "lift"))
    assert figures["ground_spread_m"] > 0.4
    with pytest.raises(ImplausibleBodyError, match=r"^lift: ground: the lowest joint a median 0\.\d\d m off one "
                                                   r"plane: expected at most 0\.25 m"):
        check_plausible(Motion(motion.joint_names, motion.parents, pos, None, motion.fps, "lift"))


@pytest.mark.parametrize("clip", REAL_CLIPS)
def test_every_real_clip_passes_the_gate(shared_data: Path, clip: str) -> None:
    figures = check_plausible(read_motion(shared_data / clip))
    assert not figures["trusted"]
    assert 1.4 < figures["height_m"] < 1.9
    assert figures["ground_tilt_deg"] < 10 and figures["ground_spread_m"] < 0.05
    assert all(0.3 < figures["segments_m"][f"{s}_thigh"] < 0.5 for s in ("left", "right"))
    assert np.isfinite(figures["ground_m"])


def test_spatial_axes_say_where_the_body_faces(shared_data: Path, tmp_path: Path) -> None:
    """The generated walk faces +x of its Y-up file, which is +y once Z up: x is then its right."""
    assert spatial_axes(read_motion(bandai_layout_bvh(tmp_path / "walk.bvh"))) == "RAS"
    assert spatial_axes(read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh")) == "ALS"
    assert spatial_axes(read_motion(shared_data / "bvh/pymo_walk.bvh")) == "__S"  # it turns: no one facing


def test_a_c3d_refusal_names_the_file_alone(shared_data: Path, tmp_path: Path) -> None:
    """MACsample.c3d's markers, mapped by hand, make a body 0.57 m tall: the message names the file,
    not the reader's description of it (its Motion.source)."""
    from effortface.synth.plausibility import read_checked
    from effortface.synth.read_options import MotionReadOptions

    clip = shared_data / "c3d" / "MACsample.c3d"
    ends = {"head": ["RSHO", "LSHO"], "trunk": ["RSHO", ["RHIP", "LHIP"]]}
    for s, S, shank in (("left", "L", "LSHA (point 17)"), ("right", "R", "RSHA (point 6)")):  # labels the file repeats
        ends |= {f"{s}_upper_arm": [f"{S}SHO", f"{S}ELB"], f"{s}_forearm": [f"{S}ELB", f"{S}WRI"],
                 f"{s}_hand": [f"{S}WRI", f"{S}WRI"], f"{s}_thigh": [f"{S}HIP", shank],
                 f"{s}_shank": [shank, f"{S}HEE"], f"{s}_foot": [f"{S}HEE", f"{S}TOE"]}
    mapping = tmp_path / "mac.json"
    mapping.write_text(json.dumps(ends))
    assert read_motion(clip).source != str(clip)
    with pytest.raises(ImplausibleBodyError, match=rf"^{re.escape(str(clip))}: standing height 0\.\d\d m: "):
        read_checked(clip, MotionReadOptions(mapping=str(mapping)))


def test_a_folder_of_clips_skips_the_implausible_one(tmp_path: Path, capsys) -> None:
    clips = tmp_path / "clips"
    clips.mkdir()
    bandai_layout_bvh(clips / "walk.bvh")
    bandai_layout_bvh(clips / "child.bvh", scale=0.7)
    status = main(["synth", "default", str(clips), "--out", str(tmp_path / "out"), "--unit-m", "0.01"])
    err = capsys.readouterr().err
    assert status == 1
    assert f"effortface synth: failed: {clips / 'child.bvh'}: {clips / 'child.bvh'}: standing height 1.11 m" in err
    assert (tmp_path / "out" / "walk.csv").exists() and not (tmp_path / "out" / "child.csv").exists()
    reading = json.loads((tmp_path / "out" / "walk.units.json").read_text())["reading"]
    assert reading["unit_from"] == "given (--unit-m)" and reading["up_axis"] == "y"
    assert main(["synth", "default", str(clips), "--out", str(tmp_path / "out2"), "--unit-m", "0.01",
                 "--trust-skeleton"]) == 0
