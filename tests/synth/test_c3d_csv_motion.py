"""C3D (Plug-in Gait markers) and joint-positions CSV motion: the Must-show (a C3D made from a BVH
clip's joint positions gives w within 3 % of the BVH), the dispatch, the errors, the lazy import."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.c3d_motion import (MarkerSetOptions, hip_centres, read_c3d,
                                                 write_c3d_markers)
from effortface.synth.motion import Motion, MotionFormatError, read_motion
from effortface.synth.motion_csv import read_positions_csv, write_positions_csv
from effortface.synth.runtime import Character, load_model
from effortface.synth.synth_session import find_clips

SQUATS = "motion/cmu_13_29_squats_120fps.bvh"
JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def plug_in_gait_markers(bvh: Motion, opts: MarkerSetOptions = MarkerSetOptions()) -> dict[str, np.ndarray]:
    """Virtual Plug-in Gait markers placed on a CMU BVH clip's joints (the inverse of the rules,
    written independently here: the markers sit where a lab would stick them)."""
    j = {n: bvh.positions_m[:, i] for i, n in enumerate(bvh.joint_names)}
    hip_l, hip_r = j["LeftUpLeg"], j["RightUpLeg"]
    lateral = _unit(hip_l - hip_r)
    forward = _unit(np.cross(lateral, [0.0, 0.0, 1.0]))
    up = np.cross(forward, lateral)
    width = np.linalg.norm(hip_l - hip_r, axis=-1, keepdims=True) / 0.72       # Bell: 0.36 W each side
    mid_asis = (hip_l + hip_r) / 2 + 0.19 * width * forward + 0.30 * width * up
    m = {"LASI": mid_asis + width / 2 * lateral, "RASI": mid_asis - width / 2 * lateral,
         "LPSI": mid_asis - 0.16 * forward + 0.05 * lateral, "RPSI": mid_asis - 0.16 * forward - 0.05 * lateral}
    neck = j["Neck1"]
    m["C7"], m["CLAV"] = neck - 0.07 * forward, neck + 0.07 * forward
    m["T10"], m["STRN"] = j["Spine"] - 0.08 * forward, j["Spine"] + 0.08 * forward
    head_axis = _unit(j["Head_end"] - neck)
    centre = j["Head_end"] - opts.head_top_offset_m * head_axis
    side = _unit(np.cross(head_axis, forward))
    for name, f, s in (("LFHD", 1, -1), ("RFHD", 1, 1), ("LBHD", -1, -1), ("RBHD", -1, 1)):
        m[name] = centre + 0.08 * f * forward + 0.07 * s * side
    shoulders_lat = _unit(j["LeftArm"] - j["RightArm"])
    thorax_up = _unit(neck - (j["Spine"]))
    for s_, sign, name in (("L", 1.0, "Left"), ("R", -1.0, "Right")):
        m[f"{s_}KNE"] = j[f"{name}Leg"] + sign * lateral * (opts.knee_width_m / 2 + opts.marker_radius_m)
        m[f"{s_}ANK"] = j[f"{name}Foot"] + sign * lateral * (opts.ankle_width_m / 2 + opts.marker_radius_m)
        m[f"{s_}TOE"] = j[f"{name}ToeBase_end"]
        m[f"{s_}SHO"] = j[f"{name}Arm"] + thorax_up * opts.shoulder_offset_m
        m[f"{s_}ELB"] = j[f"{name}ForeArm"] + sign * shoulders_lat * (opts.elbow_width_m / 2 + opts.marker_radius_m)
        bone = _unit(j[f"{name}Hand"] - j[f"{name}ForeArm"])
        across = _unit(np.cross(bone, forward))
        m[f"{s_}WRA"], m[f"{s_}WRB"] = j[f"{name}Hand"] + 0.03 * across, j[f"{name}Hand"] - 0.03 * across
        m[f"{s_}FIN"] = j[f"{name}HandIndex1_end"]
    return m


def _w_per_kg(motion: Motion) -> np.ndarray:
    return load_model("default").synthesize(motion, Character())["w_per_kg"]


@pytest.mark.parametrize("clip", [SQUATS, JJ])
def test_c3d_from_bvh_joint_positions_gives_w_within_3_percent(shared_data, tmp_path, clip):
    bvh = read_motion(shared_data / clip)
    path = write_c3d_markers(tmp_path / "clip.c3d", plug_in_gait_markers(bvh), bvh.fps)
    c3d = read_motion(path)
    assert c3d.fps == pytest.approx(bvh.fps) and c3d.n_frames == bvh.n_frames
    w_bvh, w_c3d = _w_per_kg(bvh), _w_per_kg(c3d)
    mean_bvh, mean_c3d = float(np.mean(w_bvh)), float(np.mean(w_c3d))
    assert mean_bvh > 0.5
    assert abs(mean_c3d - mean_bvh) / mean_bvh < 0.03, (mean_bvh, mean_c3d)
    assert np.corrcoef(w_bvh, w_c3d)[0, 1] > 0.95


def test_c3d_joint_centres_recover_the_hips_and_knees(shared_data, tmp_path):
    bvh = read_motion(shared_data / SQUATS).slice_s(0, 1)
    c3d = read_c3d(write_c3d_markers(tmp_path / "s.c3d", plug_in_gait_markers(bvh), bvh.fps))
    for joint in ("LeftUpLeg", "RightUpLeg", "LeftLeg", "RightFoot", "Neck1", "Head_end", "LeftHand"):
        got = c3d.positions_m[:, c3d.joint_names.index(joint)]
        want = bvh.positions_m[:, bvh.joint_names.index(joint)]
        assert np.max(np.linalg.norm(got - want, axis=-1)) < 2e-3, joint  # C3D stores float32 mm


def test_modelled_joint_centres_win_and_gaps_are_filled(shared_data, tmp_path):
    bvh = read_motion(shared_data / SQUATS).slice_s(0, 0.5)
    markers = plug_in_gait_markers(bvh)
    knee = bvh.positions_m[:, bvh.joint_names.index("LeftLeg")] + [0.0, 0.0, 0.01]
    markers["LKJC"] = knee
    markers["LKNE"] = markers["LKNE"].copy()
    markers["LKNE"][5:9] = 0.0      # a gap: all-zero points are missing in C3D
    c3d = read_c3d(write_c3d_markers(tmp_path / "g.c3d", markers, bvh.fps))
    np.testing.assert_allclose(c3d.positions_m[:, c3d.joint_names.index("LeftLeg")], knee, atol=2e-4)
    assert np.all(np.isfinite(c3d.positions_m))


def test_c3d_missing_marker_is_named(shared_data, tmp_path):
    markers = plug_in_gait_markers(read_motion(shared_data / SQUATS).slice_s(0, 0.2))
    del markers["RANK"]
    path = write_c3d_markers(tmp_path / "m.c3d", markers, 120)
    with pytest.raises(MotionFormatError, match=r"m\.c3d: expected the Plug-in Gait markers RANK"):
        read_motion(path)
    (tmp_path / "bad.c3d").write_bytes(b"not a c3d file at all" * 30)
    with pytest.raises(MotionFormatError, match=r"bad\.c3d: expected a C3D file"):
        read_motion(tmp_path / "bad.c3d")


def test_positions_csv_round_trip_and_same_w(shared_data, tmp_path):
    bvh = read_motion(shared_data / JJ).slice_s(0, 4)
    path = write_positions_csv(tmp_path / "jj.csv", bvh)
    csv = read_motion(path)
    assert csv.joint_names == bvh.joint_names and list(csv.parents) == list(bvh.parents)
    assert csv.fps == pytest.approx(bvh.fps, rel=1e-6)
    np.testing.assert_allclose(csv.positions_m, bvh.positions_m, atol=1e-8)
    positions_only = Motion(bvh.joint_names, bvh.parents, bvh.positions_m, None, bvh.fps)
    np.testing.assert_allclose(_w_per_kg(csv), _w_per_kg(positions_only), rtol=1e-6, atol=1e-9)
    (tmp_path / "jj.skeleton.json").unlink()
    assert set(read_positions_csv(path).parents) == {-1}   # no skeleton file: all roots


@pytest.mark.parametrize(("text", "match"), [
    ("t,a_x_m,a_y_m,a_z_m\n0,0,0,0\n", r"bad\.csv: line 1: expected the header t_s"),
    ("t_s,a_x_m,a_y_m,b_z_m\n0,0,0,0\n1,0,0,0\n", r"bad\.csv: line 1, column 2: expected a_x_m"),
    ("t_s,a_x_m,a_y_m,a_z_m\n0,0,0,0\n0.1,0,x,0\n", r"bad\.csv: expected rows of 4 numbers"),
    ("t_s,a_x_m,a_y_m,a_z_m\n0,0,0,0\n0.1,0,0,0\n0.1,0,0,0\n", r"bad\.csv: line 4: t_s: expected increasing"),
])
def test_bad_positions_csv_is_named(tmp_path, text, match):
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(MotionFormatError, match=match):
        read_motion(tmp_path / "bad.csv")


def test_clip_list_offers_c3d_and_positions_csv_only(shared_data, tmp_path):
    bvh = read_motion(shared_data / SQUATS).slice_s(0, 0.2)
    write_positions_csv(tmp_path / "clip.csv", bvh)
    write_c3d_markers(tmp_path / "clip.c3d", plug_in_gait_markers(bvh), bvh.fps)
    (tmp_path / "heart_rate.csv").write_text("t_s,hr_bpm,rr_ms,beat_count,device,valid\n")
    assert [p.name for p in find_clips(tmp_path)] == ["clip.c3d", "clip.csv"]


def test_runtime_reads_csv_without_loading_c3d(shared_data, tmp_path):
    bvh = read_motion(shared_data / SQUATS).slice_s(0, 0.3)
    path = write_positions_csv(tmp_path / "clip.csv", bvh)
    c3d_path = write_c3d_markers(tmp_path / "clip.c3d", plug_in_gait_markers(bvh), bvh.fps)
    code = ("import sys; from effortface.runtime import read_motion; "
            f"read_motion({str(path)!r}); assert not {{'c3d', 'ezc3d'}} & set(sys.modules), 'csv loaded a C3D reader'; "
            f"read_motion({str(c3d_path)!r}); assert 'c3d' in sys.modules; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "ok", out.stderr
