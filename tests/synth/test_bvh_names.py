"""BVH name sets recognised without a mapping (issue 24): a real PyMO walk (tests/data/bvh, MIT), the
classic Biovision, SMPL and Xsens names; an unknown skeleton gets one line listing the unmapped
segments and how to write --mapping."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.motion import read_motion
from effortface.synth.segments import SegmentMappingError, map_skeleton

DATA = Path(__file__).resolve().parents[1] / "data" / "bvh"


def test_real_pymo_walk_gives_curves(tmp_path):
    clip = read_motion(DATA / "pymo_walk.bvh")
    assert map_skeleton(clip.joint_names)[0] == "CMU"          # no neck joint: the head starts at Head
    out = tmp_path / "walk.csv"
    done = subprocess.run([sys.executable, "-m", "effortface", "synth", "default", str(DATA / "pymo_walk.bvh"),
                           "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    table = np.genfromtxt(out, delimiter=",", names=True)
    assert len(table) == clip.n_frames and all(np.isfinite(table[c]).all() for c in table.dtype.names)


def _sides(template: list[str]) -> list[str]:
    return [n.replace("{S}", s) for n in template for s in (("Left", "Right") if "{S}" in n else ("",))]


@pytest.mark.parametrize("convention, names", [
    ("Biovision", _sides(["Hips", "Chest", "Neck", "Head", "Head_end", "{S}Collar", "{S}UpArm", "{S}LowArm", "{S}Hand",
                          "{S}Hand_end", "{S}UpLeg", "{S}LowLeg", "{S}Foot", "{S}Foot_end"])),
    ("SMPL", [n.replace("{s}", s) for n in ["pelvis", "{s}_hip", "spine1", "{s}_knee", "spine2", "{s}_ankle", "spine3",
                                            "{s}_foot", "neck", "{s}_collar", "head", "{s}_shoulder", "{s}_elbow",
                                            "{s}_wrist", "{s}_hand"] for s in (("left", "right") if "{s}" in n else ("",))]),
    ("Xsens", _sides(["Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head", "Head_end", "{S}Shoulder", "{S}UpperArm",
                      "{S}ForeArm", "{S}Hand", "{S}Hand_end", "{S}UpperLeg", "{S}LowerLeg", "{S}Foot", "{S}Toe"])),
])
def test_research_name_sets_need_no_mapping(convention, names):
    assert map_skeleton(names)[0] == convention


def test_unknown_skeleton_is_one_line_with_how_to_map(tmp_path):
    text = (DATA / "pymo_walk.bvh").read_text()
    for old, new in (("LeftUpLeg", "Bone07"), ("RightUpLeg", "Bone11"), ("LeftArm", "Bone03")):
        text = text.replace(f"JOINT {old}\n", f"JOINT {new}\n")
    clip = tmp_path / "renamed.bvh"
    clip.write_text(text)
    done = subprocess.run([sys.executable, "-m", "effortface", "synth", "default", str(clip), "--out",
                           str(tmp_path / "o.csv")], capture_output=True, text=True, timeout=600)
    assert done.returncode == 2 and "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert "unmapped segments: trunk, left_upper_arm, left_thigh, right_thigh" in done.stderr, done.stderr
    assert 'Map them with --mapping FILE.json: {"version": 2, "trunk": [' in done.stderr
    assert done.stderr.startswith(f"effortface: {clip}: skeleton joints:") or f"{clip}: skeleton joints:" in done.stderr
    with pytest.raises(SegmentMappingError):
        map_skeleton(read_motion(clip).joint_names)


def test_mapping_kept_by_motion_attach_and_used_by_work(tmp_path):
    """An unknown skeleton attached with --mapping: motion.json keeps the mapping and `effortface work`
    takes the clip's seconds; without it, work refuses in one line, or takes `work --mapping`."""
    import json
    import shutil

    text = (DATA / "pymo_walk.bvh").read_text()
    for old, new in (("LeftUpLeg", "Bone07"), ("RightUpLeg", "Bone11")):
        text = text.replace(f"JOINT {old}\n", f"JOINT {new}\n")
    (tmp_path / "renamed.bvh").write_text(text)
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({"trunk": ["Head", ["Bone07", "Bone11"]], "left_thigh": ["Bone07", "LeftLeg"],
                                   "right_thigh": ["Bone11", "RightLeg"]} | {
        k: v for k, v in {"head": ["Head_end", "Head"]}.items()} | {
        f"{s}_{part}": [a.format(S=S), b.format(S=S)] for s, S in (("left", "Left"), ("right", "Right"))
        for part, (a, b) in {"upper_arm": ("{S}Arm", "{S}ForeArm"), "forearm": ("{S}ForeArm", "{S}Hand"),
                             "hand": ("{S}Hand", "{S}Hand_End"), "shank": ("{S}Leg", "{S}Foot"),
                             "foot": ("{S}Foot", "{S}ToeBase_end")}.items()}))
    src = Path(__file__).resolve().parents[2] / "sample_sessions" / "P01_20260112-093000_cardio"
    run = lambda *a: subprocess.run([sys.executable, "-m", "effortface", *map(str, a)], capture_output=True,
                                    text=True, timeout=600)
    sessions = []
    for name, attach_mapping in (("with", True), ("without", False)):
        session = tmp_path / name / src.name
        shutil.copytree(src, session, ignore=shutil.ignore_patterns("video.avi", "serial"))
        done = run("motion", "attach", session, tmp_path / "renamed.bvh", "--offset", "60",
                   *(["--mapping", mapping] if attach_mapping else []))
        if attach_mapping:
            assert done.returncode == 0, done.stderr
        else:  # issue 34: an unmapped clip is refused before anything is copied (the clip named) ...
            assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
            assert f"{tmp_path / 'renamed.bvh'}: skeleton joints:" in done.stderr
            assert not (session / "motion").exists()
            # ... so the clip is put there as an earlier release's attach did (motion.json version 1)
            (session / "motion").mkdir()
            shutil.copyfile(tmp_path / "renamed.bvh", session / "motion" / "renamed.bvh")
            (session / "motion" / "motion.json").write_text(json.dumps(
                {"files": [{"path": "renamed.bvh", "offset_s": 60.0, "format": "bvh", "aligned": "offset"}]}))
        sessions.append(session)
    entry = json.loads((sessions[0] / "motion" / "motion.json").read_text())["files"][0]
    assert entry["mapping"]["left_thigh"] == ["Bone07", "LeftLeg"]
    done = run("work", sessions[0])
    assert done.returncode == 0 and "motion 9 s" in done.stdout, done.stdout + done.stderr
    refused = run("work", sessions[1])
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    assert "unmapped segments: trunk, left_thigh, right_thigh" in refused.stderr
    assert f"{sessions[1] / 'motion' / 'renamed.bvh'}: skeleton joints:" in refused.stderr  # work names the clip
    assert not (sessions[1] / "work.csv").exists()
    done = run("work", sessions[1], "--mapping", mapping)
    assert done.returncode == 0 and "motion 9 s" in done.stdout, done.stdout + done.stderr
