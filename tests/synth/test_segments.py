"""de Leva tables, skeleton mapping (CMU, Mixamo, Unreal, Unity, AMP, user file), loads, body model."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from effortface.core.errors import UserError
from effortface.synth.motion import Motion, read_motion
from effortface.synth.segments import (
    REQUIRED_SEGMENTS,
    Loads,
    SegmentMappingError,
    build_body,
    map_skeleton,
    read_deleva_table,
    stack_bodies,
)


@pytest.mark.parametrize("sex", ["male", "female"])
def test_deleva_mass_fractions_sum_to_one(sex: str) -> None:
    """The 14-segment model (head+neck, trunk, 2 x 6 limb segments) accounts for the whole body."""
    table = read_deleva_table(sex)
    parts = ["head_neck_alt", "trunk_alt"] + 2 * ["upper_arm", "forearm", "hand", "thigh", "shank", "foot"]
    assert sum(table[p].mass_frac for p in parts) == pytest.approx(1.0, abs=2e-3)
    assert table["thigh"].mass_frac == (0.1416 if sex == "male" else 0.1478)


@pytest.mark.parametrize(
    ("clip", "convention"),
    [("cmu_13_29_squats_120fps.bvh", "CMU"), ("amp_humanoid_walk.npz", "AMP")],
)
def test_real_skeletons_map_and_scale(shared_data: Path, clip: str, convention: str) -> None:
    """Masses sum to M, lengths are the skeleton's own and near de Leva's, CMs lie on the bones."""
    motion = read_motion(shared_data / "motion" / clip)
    body = build_body(motion.joint_names, motion.parents, 72.0, "male", reference_positions_m=motion.positions_m)
    assert body.convention == convention
    assert body.segment_mass_kg.sum() == pytest.approx(72.0, rel=2e-3)
    thigh = body.segment_names.index("left_thigh")
    bone = np.linalg.norm(motion.positions_m[:, body.hip_joints[0]] - motion.positions_m[:, _knee(motion)], axis=1)
    assert body.length_m[thigh] == pytest.approx(np.median(bone), rel=1e-9)
    assert np.all((body.length_m > 0.04) & (body.length_m < 0.7))
    np.testing.assert_allclose(body.com_weights.sum(axis=1), 1.0)


def _knee(motion: Motion) -> int:
    names = [n.lower() for n in motion.joint_names]
    return names.index("leftleg") if "leftleg" in names else names.index("left_shin")


def _names(convention: str) -> list[str]:
    """Joint names a skeleton of that convention exports (end sites as <parent>_end)."""
    if convention == "Mixamo":
        base = ["Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "HeadTop_End"]
        limbs = ["{S}Shoulder", "{S}Arm", "{S}ForeArm", "{S}Hand", "{S}HandMiddle1", "{S}UpLeg", "{S}Leg",
                 "{S}Foot", "{S}ToeBase", "{S}Toe_End"]
        return [f"mixamorig:{n}" for n in base + [x.replace("{S}", s) for s in ("Left", "Right") for x in limbs]]
    if convention == "Unreal":
        base = ["pelvis", "spine_01", "spine_02", "spine_03", "neck_01", "head"]
        limbs = ["clavicle_{S}", "upperarm_{S}", "lowerarm_{S}", "hand_{S}", "middle_01_{S}", "thigh_{S}",
                 "calf_{S}", "foot_{S}", "ball_{S}"]
        return base + [x.replace("{S}", s) for s in ("l", "r") for x in limbs]
    base = ["Hips", "Spine", "Chest", "UpperChest", "Neck", "Head", "Head_end"]
    limbs = ["{S}Shoulder", "{S}UpperArm", "{S}LowerArm", "{S}Hand", "{S}MiddleProximal", "{S}UpperLeg",
             "{S}LowerLeg", "{S}Foot", "{S}Toes"]
    return base + [x.replace("{S}", s) for s in ("Left", "Right") for x in limbs]


@pytest.mark.parametrize("convention", ["Mixamo", "Unreal", "Unity"])
def test_game_skeleton_conventions(convention: str) -> None:
    names = _names(convention)
    found, segments = map_skeleton(names)
    assert found == convention
    assert set(segments) == set(REQUIRED_SEGMENTS)
    lhand = segments["left_hand"][0][0]
    assert "hand" in names[lhand].lower() and "l" in names[lhand].lower()


def _custom_skeleton() -> tuple[list[str], dict[str, list]]:
    """Joint names no built-in convention knows, and the user mapping that maps them."""
    names = ["root", "chest", "skull", "skull_top"] + [
        f"{s}_{p}" for s in "LR" for p in ("sh", "el", "wr", "fi", "hip", "kn", "an", "toe")]
    mapping: dict[str, list] = {"head": ["skull_top", "skull"], "trunk": ["chest", ["L_hip", "R_hip"]]}
    for side, s in (("left", "L"), ("right", "R")):
        for seg, a, b in (("upper_arm", "sh", "el"), ("forearm", "el", "wr"), ("hand", "wr", "fi"),
                          ("thigh", "hip", "kn"), ("shank", "kn", "an"), ("foot", "an", "toe")):
            mapping[f"{side}_{seg}"] = [f"{s}_{a}", f"{s}_{b}"]
    return names, mapping


def test_user_mapping_file(tmp_path: Path) -> None:
    """A JSON file maps an unknown naming; lists average joints (the trunk's hip mid-point)."""
    names, mapping = _custom_skeleton()
    path = tmp_path / "map.json"
    path.write_text(json.dumps(mapping))
    parents = [-1, 0, 1, 2] + [1, 4, 5, 6, 0, 8, 9, 10] + [1, 12, 13, 14, 0, 16, 17, 18]
    body = build_body(names, parents, 60.0, "female", mapping=path)
    assert body.convention == "user"
    trunk = body.segment_names.index("trunk")
    assert body.distal_weights[trunk, names.index("L_hip")] == 0.5
    assert body.frame_joint[trunk] == 0  # common ancestor of chest and both hips


def test_unknown_joints_name_every_unmapped_segment() -> None:
    names = [n for n in _names("Unreal") if n not in ("hand_l", "foot_r", "neck_01")]
    with pytest.raises(SegmentMappingError, match=(
            r"best Unreal\); unmapped segments: head, trunk, left_forearm, left_hand, right_shank, right_foot\. "
            r"Map them with --mapping FILE.json: \{\"version\": 2, \"head\": \[")):
        map_skeleton(names)


def test_user_mapping_missing_segment_is_named(tmp_path: Path) -> None:
    """A partial mapping the conventions cannot complete: the clip, the mapping file and the segments named."""
    path = tmp_path / "partial.json"
    path.write_text(json.dumps({"head": ["Head_end", "Neck"]}))
    with pytest.raises(SegmentMappingError, match=(
            rf"^clip.bvh: skeleton joints: expected every segment mapped \(mapping file {re.escape(str(path))} and "
            r"the CMU, .* conventions tried, best user\); unmapped segments: trunk, ")):
        map_skeleton(["Head_end", "Neck"], path, source="clip.bvh")


def test_loads_are_point_masses(shared_data: Path) -> None:
    motion = read_motion(shared_data / "motion/amp_humanoid_walk.npz")
    body = build_body(motion.joint_names, motion.parents, 70, "male", loads=Loads(5, 7.5, 12))
    assert body.load_kg[body.segment_names.index("left_hand")] == 5
    assert body.load_kg[body.segment_names.index("right_hand")] == 7.5
    assert body.back_load_kg == 12 and body.mass_kg == 70  # M does not include loads


UNITY_NAMES = _names("Unity")
BAD_BODY = {
    r"mass_kg: expected a body mass above 0 kg, got -70": dict(mass_kg=-70),
    r"mass_kg: expected a body mass above 0 kg, got 0": dict(mass_kg=0),
    r"sex: expected 'male' or 'female', got 'robot'": dict(sex="robot"),
}


@pytest.mark.parametrize(("match", "kw"), list(BAD_BODY.items()), ids=["negative", "zero", "sex"])
def test_bad_body_parameters(match: str, kw: dict) -> None:
    args = dict(mass_kg=70.0, sex="male") | kw
    with pytest.raises(UserError, match=match):
        build_body(UNITY_NAMES, [-1] + [0] * (len(UNITY_NAMES) - 1), **args)


BAD_LOADS = {
    r"left_hand_kg: expected a load of 0 kg or more, got -1": dict(left_hand_kg=-1),
    r"right_hand_kg: expected a load of 0 kg or more, got nan": dict(right_hand_kg=float("nan")),
    r"back_kg: expected a load of 0 kg or more, got '5'": dict(back_kg="5"),
}


@pytest.mark.parametrize(("match", "kw"), list(BAD_LOADS.items()), ids=["negative", "nan", "text"])
def test_bad_loads(match: str, kw: dict) -> None:
    with pytest.raises(UserError, match=match):
        Loads(**kw)


def test_stack_bodies_refuses_mixed_skeletons(shared_data: Path) -> None:
    amp = read_motion(shared_data / "motion/amp_humanoid_run.npz")
    cmu = read_motion(shared_data / "motion/cmu_13_29_jumping_jacks_120fps.bvh")
    bodies = [build_body(m.joint_names, m.parents, 70, "male") for m in (amp, cmu)]
    with pytest.raises(UserError, match=r"bodies: expected single bodies on one skeleton and mapping, body 1 differs"):
        stack_bodies(bodies)
    with pytest.raises(UserError, match=r"bodies: expected at least one body, got none"):
        stack_bodies([])


BAD_MAPPING_VALUES = {"ints": [1, 2], "int": 5, "null": None, "short": ["Hips"],
                      "nested": ["Hips", [["a"]]], "empty-list": ["Hips", []], "dict": {"a": "b"}}


@pytest.mark.parametrize("value", BAD_MAPPING_VALUES.values(), ids=list(BAD_MAPPING_VALUES))
def test_mapping_file_value_types_are_named(tmp_path: Path, value) -> None:
    """{"trunk": [1, 2]} raised TypeError in _resolve_end; now the file and segment are named."""
    path = tmp_path / "map.json"
    path.write_text(json.dumps({"trunk": value}))
    with pytest.raises(SegmentMappingError, match=r"map\.json: expected \[proximal, distal\] joint names "
                                                  r".*bad entries: trunk$"):
        map_skeleton(_names("Unreal"), path)


@pytest.mark.parametrize("value", [(1, 2), ("pelvis", 3), ("pelvis",), None], ids=["ints", "int", "short", "none"])
def test_mapping_dict_value_types_are_named(value) -> None:
    if value is None:
        with pytest.raises(SegmentMappingError, match=r"mapping: expected a mapping segment"):
            map_skeleton(_names("Unreal"), ["trunk"])  # type: ignore[arg-type]
        return
    with pytest.raises(SegmentMappingError, match=r"mapping: trunk: expected \(proximal, distal\) joint names"):
        map_skeleton(_names("Unreal"), {"trunk": value})


@pytest.mark.parametrize("parents", [[0, 0, 1, 2], [-1, 2, 1, 2], [-1, 0, 99, 2]], ids=["self", "cycle", "range"])
def test_build_body_refuses_a_parent_cycle(tmp_path: Path, parents: list[int]) -> None:
    """A cyclic parent list looped forever in _ancestors (the parentsself.npz hang)."""
    names, mapping = _custom_skeleton()
    full = parents + [1, 4, 5, 6, 0, 8, 9, 10] + [1, 12, 13, 14, 0, 16, 17, 18]
    with pytest.raises(UserError, match=r"skeleton: parent_indices: expected -1 or the index of an earlier joint"):
        build_body(names, full, 60.0, "female", mapping=mapping)
