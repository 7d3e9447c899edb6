"""``effortface motion inspect`` on real files, mapping files people write (partial, version 2, template),
and ``motion attach`` / ``work`` with the read options (issue 34)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.synth.segments import (SegmentMappingError, build_body, map_skeleton, mapping_from_json,
                                       read_mapping)
from effortface.synth.motion import read_motion

ROOT = Path(__file__).resolve().parents[2]
WALK = ROOT / "tests/data/bvh/bvhtoolbox_walk01.bvh"  # bvh-toolbox (MIT): feet end in End Sites, no toe joint
PYMO = ROOT / "tests/data/bvh/pymo_walk.bvh"
C3D = ROOT / "tests/data/c3d"
SESSION = ROOT / "sample_sessions" / "P01_20260119-140000_strength"  # 215 s, no motion/
FEET = {"version": 2, "left_foot": ["LeftFoot", "LeftFoot_end"], "right_foot": ["RightFoot", "RightFoot_end"]}


def _inspect(capsys, *args: str) -> dict:
    assert main(["motion", "inspect", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _write(path: Path, data: object) -> Path:
    path.write_text(json.dumps(data))
    return path


def test_inspect_json_of_a_bvh_the_conventions_map_but_for_the_feet(capsys) -> None:
    found = _inspect(capsys, str(WALK))
    assert {"fps", "n_frames", "duration_s", "unit_m", "up_axis", "height_m", "labels", "mapping", "unmapped",
            "unit_from", "up_from", "producer", "gaps", "window"} <= set(found)
    assert (found["fps"], found["n_frames"], found["duration_s"]) == (24.0, 101, pytest.approx(101 / 24, abs=1e-3))
    assert found["unit_m"] == 0.01 and "centimetre" in found["unit_from"] and found["up_axis"] == "y"
    assert 1.6 < found["height_m"] < 1.9
    assert "RightFoot_end" in found["labels"] and len(found["labels"]) == 24
    assert found["unmapped"] == ["left_foot", "right_foot"]
    assert found["convention"] == "CMU (partial: 12 of 14 segments)"
    # every segment listed from the trunk outwards, the head like the limbs
    assert found["mapping"]["head"] == {"proximal": ["Neck"], "distal": ["Head_end"]}
    assert found["mapping"]["left_thigh"] == {"proximal": ["LeftUpLeg"], "distal": ["LeftLeg"]}
    assert found["mapping"]["trunk"] == {"proximal": ["Neck"], "distal": ["LeftUpLeg", "RightUpLeg"]}
    assert found["window"] == {"first_frame": 0, "n_frames": 101, "of_frames": 101} and found["gaps"] == {}


def test_inspect_text_report_is_aligned(capsys) -> None:
    assert main(["motion", "inspect", str(PYMO)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"file        {PYMO}"
    assert "frames      1064 at 120 Hz (8.87 s)" in lines
    unit = next(line for line in lines if line.startswith("unit "))
    assert unit.startswith("unit        0.0254 m per file unit (rest pose") and "inch" in unit
    assert max(map(len, lines)) <= 98  # long values wrap (the File info panel shows the report whole)
    assert "  left_foot       LeftFoot -> LeftToeBase_end" in lines and "unmapped   none" in lines


def test_a_partial_mapping_of_the_two_feet_reads_the_walk(tmp_path: Path, capsys) -> None:
    """The Must show: the bvh-toolbox walk refused without a mapping, read with the two feet mapped."""
    feet = _write(tmp_path / "feet.json", FEET)
    names = read_motion(WALK).joint_names
    assert map_skeleton(names, feet)[0] == "user + CMU"
    out = tmp_path / "walk.csv"
    assert main(["synth", "default", str(WALK), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{WALK}: skeleton joints:" in err and "unmapped segments: left_foot, right_foot" in err
    assert not out.exists()
    assert main(["synth", "default", str(WALK), "--out", str(out), "--mapping", str(feet)]) == 0
    w = np.genfromtxt(out, delimiter=",", names=True)["w_per_kg"]
    assert np.isfinite(w).all() and 0.5 < float(np.mean(w)) < 10
    capsys.readouterr()
    found = _inspect(capsys, str(WALK), "--mapping", str(feet))
    assert found["unmapped"] == [] and found["convention"] == "user + CMU"
    assert found["mapping"]["left_foot"] == {"proximal": ["LeftFoot"], "distal": ["LeftFoot_end"]}


def test_segments_a_user_mapping_names_override_the_convention(tmp_path: Path) -> None:
    names = read_motion(PYMO).joint_names
    plain = build_body(names, read_motion(PYMO).parents, 70, "male")
    hands = _write(tmp_path / "hands.json", {"version": 2, "left_hand": ["LeftHand", "LeftHandThumb1_end"]})
    body = build_body(names, read_motion(PYMO).parents, 70, "male", mapping=hands)
    k = body.segment_names.index("left_hand")
    assert body.convention == "user + CMU"
    assert body.distal_weights[k, names.index("LeftHandThumb1_end")] == 1.0
    assert plain.distal_weights[k, names.index("LeftHand_End")] == 1.0
    same = [s for s in body.segment_names if s != "left_hand"]
    for s in same:
        i = body.segment_names.index(s)
        assert np.array_equal(body.distal_weights[i], plain.distal_weights[i]), s


def test_version_1_and_2_mapping_files_give_the_same_body(tmp_path: Path) -> None:
    """Version 2 lists the head [neck, head top] like the limbs; a version 1 file (no "version",
    head [head top, neck]) still reads the same; a list is a mean, ``A|B`` the first present."""
    names = read_motion(WALK).joint_names
    parents = read_motion(WALK).parents
    v1 = {"head": ["Head_end", "Neck"], "trunk": ["Spine1|Neck", ["LeftUpLeg", "RightUpLeg"]],
          "left_foot": ["LeftFoot", "LeftFoot_end"], "right_foot": ["RightFoot", "RightFoot_end"]}
    v2 = {"version": 2, **v1, "head": ["Neck", "Head_end"]}
    bodies = [build_body(names, parents, 70, "male", mapping=_write(tmp_path / f"v{k}.json", m))
              for k, m in ((1, v1), (2, v2))]
    assert np.array_equal(bodies[0].proximal_weights, bodies[1].proximal_weights)
    assert np.array_equal(bodies[0].com_weights, bodies[1].com_weights)
    trunk = bodies[1].segment_names.index("trunk")
    assert bodies[1].proximal_weights[trunk, names.index("Spine1")] == 1.0  # the first present of Spine1|Neck
    assert read_mapping(tmp_path / "v2.json")["head"] == ("Head_end", "Neck")  # internal: from the head top
    with pytest.raises(SegmentMappingError, match=r"^m.json: version: expected 1 or 2, found 3$"):
        mapping_from_json({"version": 3}, "m.json")


def test_mapping_template_is_complete_refuses_overwrite_and_maps_once_filled(tmp_path: Path, capsys) -> None:
    out = tmp_path / "walk-mapping.json"
    assert main(["motion", "inspect", str(WALK), "--mapping-template", str(out)]) == 0
    assert f"mapping template written to {out}" in capsys.readouterr().out
    template = json.loads(out.read_text())
    assert template["version"] == 2 and len(template) == 15
    assert template["head"] == ["Neck", "Head_end"]
    assert template["left_foot"] == ["LeftFoot", "<left toe (toe joint or its End Site), e.g. LeftToeBase_end>"]
    assert len(out.read_text().splitlines()) == 17  # one segment a line
    with pytest.raises(SegmentMappingError, match=r"template placeholders '<...>' in left_foot, right_foot"):
        read_mapping(out)
    before = out.read_text()
    assert main(["motion", "inspect", str(WALK), "--mapping-template", str(out)]) == 2
    assert "expected a new file for the mapping template, found one" in capsys.readouterr().err
    assert out.read_text() == before
    _write(out, {**template, "left_foot": ["LeftFoot", "LeftFoot_end"], "right_foot": ["RightFoot", "RightFoot_end"]})
    assert map_skeleton(read_motion(WALK).joint_names, out)[0] == "user"
    assert main(["motion", "inspect", str(WALK), "--mapping-template", str(out), "--force", "--mapping", str(out)]) == 0
    assert json.loads(out.read_text())["left_foot"] == ["LeftFoot", "LeftFoot_end"]


def test_inspect_c3d_trimmed_to_its_complete_window_lists_its_points(capsys) -> None:
    """A marker gap too long to fill: read over the longest complete window (the reader's), labels and
    gaps of the whole file, no body to map, exit 0."""
    found = _inspect(capsys, str(C3D / "Eb015pi.c3d"))
    assert found["read_error"] is None
    assert (found["fps"], found["n_frames"], found["unit_m"], found["up_axis"]) == (50.0, 450, 0.001, "z")
    assert len(found["labels"]) == 48 and found["labels"][:3] == ["RFT1", "RFT2", "RFT3"]
    assert found["gaps"]["PV2"] == {"missing_frames": 59, "gaps": 2, "longest_gap_s": 0.94}
    window = dict(found["window"])
    assert window.pop("why").startswith("the longest window where every needed marker is present: 'PV2'")
    assert window == {"first_frame": 47, "n_frames": 296, "of_frames": 450}
    assert len(found["unmapped"]) == 14


def test_inspect_c3d_plug_in_gait_producer_and_mapping(capsys) -> None:
    found = _inspect(capsys, str(C3D / "PiG_Calibration-FlatFoot-Full.c3d"))
    assert found["producer"].startswith("Vicon Vicon Nexus") and found["marker_set"].startswith("plug-in-gait")
    assert found["convention"] == "CMU" and found["unmapped"] == [] and found["read_error"] is None
    assert "LASI" in found["labels"] and "LeftUpLeg" in found["joints"]
    assert "POINT:UNITS mm" in found["unit_from"] and 1.3 < found["height_m"] < 1.9
    motion_analysis = _inspect(capsys, str(C3D / "sample21.c3d"))
    assert motion_analysis["producer"].startswith("Motion Analysis Corp. EVa RealTime")
    assert motion_analysis["labels"].count("RTHI") == 2  # as in the file (the reader makes them unique)


@pytest.mark.parametrize(("text", "found"), [
    ("HIERARCHY\nROOT Hips\n{\n", "end of file"),
    ("not a bvh at all\n", "expected a MOTION section"),
])
def test_unreadable_file_is_one_line_exit_2(tmp_path: Path, capsys, text: str, found: str) -> None:
    clip = tmp_path / "bad.bvh"
    clip.write_text(text)
    template = tmp_path / "t.json"
    assert main(["motion", "inspect", str(clip), "--json", "--mapping-template", str(template)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert str(clip) in captured.err and found in captured.err and not template.exists()


def _session(tmp_path: Path) -> Path:
    return Path(shutil.copytree(SESSION, tmp_path / SESSION.name,
                                ignore=shutil.ignore_patterns("video.avi", "serial", "work.csv")))


def test_attach_refuses_an_unmapped_clip_then_keeps_unit_and_mapping(tmp_path: Path, capsys) -> None:
    session = _session(tmp_path)
    assert main(["motion", "attach", str(session), str(WALK), "--offset", "40"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"{WALK}: skeleton joints:" in err
    assert not (session / "motion").exists()
    feet = _write(tmp_path / "feet.json", FEET)
    assert main(["motion", "attach", str(session), str(WALK), "--offset", "40", "--mapping", str(feet),
                 "--unit-m", "0.01"]) == 0
    doc = json.loads((session / "motion" / "motion.json").read_text())
    assert doc["version"] == 2
    entry = doc["files"][0]
    assert entry["unit_m"] == 0.01 and entry["mapping"] == FEET and "up" not in entry
    # work --mapping applies to clips attached without one only: a mapping that fits nothing leaves this clip alone
    nothing = _write(tmp_path / "nothing.json", {"version": 2, "left_foot": ["NoSuchJoint", "NoSuchToe"]})
    assert main(["work", str(session), "--mapping", str(nothing)]) == 0
    assert "motion 5 s" in capsys.readouterr().out  # 40-44.2 s: the seconds 40, 41, 42, 43, 44


def test_attach_refuses_a_bad_mapping_file_and_leaves_motion_json_unchanged(tmp_path: Path, capsys) -> None:
    session = _session(tmp_path)
    assert main(["motion", "attach", str(session), str(PYMO), "--offset", "20"]) == 0
    before = (session / "motion" / "motion.json").read_text()
    wrong = _write(tmp_path / "wrong.json", {"version": 2, "left_foot": ["LeftFoot", "NoSuchToe"]})
    assert main(["motion", "attach", str(session), str(WALK), "--offset", "40", "--mapping", str(wrong)]) == 2
    err = capsys.readouterr().err
    assert f"{WALK}: skeleton joints:" in err and f"mapping file {wrong}" in err and "left_foot" in err
    assert (session / "motion" / "motion.json").read_text() == before
    assert not (session / "motion" / WALK.name).exists()


def test_work_names_the_clip_that_fails(tmp_path: Path, capsys) -> None:
    """A version 1 motion.json (an earlier release attached an unmapped clip): work refuses naming the clip."""
    session = _session(tmp_path)
    (session / "motion").mkdir()
    shutil.copyfile(WALK, session / "motion" / WALK.name)
    _write(session / "motion" / "motion.json", {"files": [{"path": WALK.name, "offset_s": 40}]})
    assert main(["work", str(session)]) == 2
    err = capsys.readouterr().err
    assert f"{session / 'motion' / WALK.name}: skeleton joints:" in err and len(err.strip().splitlines()) == 1
    assert not (session / "work.csv").exists()
    _write(session / "motion" / "motion.json", {"files": [{"path": WALK.name, "offset_s": 40,
                                                           "mapping": {"version": 2, **FEET}}]})
    assert main(["work", str(session)]) == 0


@pytest.mark.parametrize(("doc", "message"), [
    ({"version": 3, "files": []}, r"motion.json: version: expected 1 or 2, found 3$"),
    ({"version": 2, "files": [{"path": "a.bvh", "unit_m": -1}]},
     r"motion.json: files\[0\].unit_m: expected a length in metres above 0, found -1$"),
    ({"version": 2, "files": [{"path": "a.bvh", "up": "up"}]},
     r"motion.json: files\[0\].up: expected one of x, y, z, -x, -y, -z, found 'up'$"),
    ({"version": 2, "files": [{"path": "a.bvh", "mapping": ["LeftFoot"]}]},
     r"motion.json: files\[0\].mapping: expected a mapping \{segment: \[proximal, distal\]\}, found \['LeftFoot'\]$"),
])
def test_motion_json_entries_are_checked(tmp_path: Path, doc: dict, message: str) -> None:
    from effortface.synth.work import WorkError, read_motion_index

    path = _write(tmp_path / "motion.json", doc)
    with pytest.raises(WorkError, match=message):
        read_motion_index(path)


def test_motion_json_version_1_entries_still_read(tmp_path: Path) -> None:
    from effortface.synth.work import read_motion_index

    old = {"files": [{"path": "a.bvh", "offset_s": 3, "mapping": {"head": ["Head_end", "Neck"]}}]}
    entry = read_motion_index(_write(tmp_path / "motion.json", old))[0]
    assert (entry["offset_s"], entry["unit_m"], entry["up"]) == (3.0, None, None)
    assert mapping_from_json(entry["mapping"], "x")["head"] == ("Head_end", "Neck")  # v1: as written


def test_inspect_and_attach_use_the_plausibility_gate(tmp_path: Path, capsys) -> None:
    """The gate's figures in inspect; attach passes a plausible walk."""
    from effortface.synth import plausibility as gate

    found = _inspect(capsys, str(PYMO))
    figures = gate.check_plausible(read_motion(PYMO), trust=True)
    assert found["plausibility"]["ok"] is True and found["height_m"] == pytest.approx(figures["height_m"])
    session = _session(tmp_path)
    assert main(["motion", "attach", str(session), str(PYMO), "--offset", "20"]) == 0


def test_a_bvh_whose_unit_cannot_be_decided_is_still_inspected(tmp_path: Path, capsys) -> None:
    """The bvh-toolbox walk with every OFFSET and root position shrunk 1,000 times (no unit gives a human): its joints,
    mapping and the reader's refusal are shown (exit 0); with --unit-m it reads."""
    import re

    head, frames = WALK.read_text().split("Frame Time:")
    head = re.sub(r"OFFSET\s+(\S+)\s+(\S+)\s+(\S+)",
                  lambda m: "OFFSET " + " ".join(f"{float(v) * 1e-3:.8f}" for v in m.groups()), head)
    lines = frames.splitlines()
    rows = [" ".join([f"{float(v) * 1e-3:.8f}" for v in row.split()[:3]] + row.split()[3:]) for row in lines[1:]]
    text = head + "Frame Time:" + "\n".join([lines[0], *rows]) + "\n"  # the root's position channels too
    clip = tmp_path / "tiny.bvh"
    clip.write_text(text)
    found = _inspect(capsys, str(clip))
    assert found["unit_m"] is None and found["height_m"] is None and found["unit_from"] == "not decided: give --unit-m"
    assert found["read_error"].startswith(f"{clip}: expected a skeleton whose rest pose is 1.1-2.3 m tall")
    assert len(found["labels"]) == 24 and found["unmapped"] == ["left_foot", "right_foot"]
    scaled = _inspect(capsys, str(clip), "--unit-m", "10")
    assert scaled["unit_m"] == 10 and 1.6 < scaled["height_m"] < 1.9 and scaled["read_error"] is None
