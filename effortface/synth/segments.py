"""Body segments: de Leva (1996) inertia tables, skeleton-to-segment mapping, loads, the body model.

The body has 14 segments (head with neck, trunk, and each side's upper arm, forearm, hand, thigh,
shank and foot), whose de Leva mass fractions sum to 1. Each segment runs from a proximal to a
distal end point; an end point is one joint or the mean of several joints (the trunk ends at the
mid-point of the hip joints). Masses scale with the character's mass; lengths are the skeleton's
own bone lengths. numpy only (the runtime imports this module).
"""

from __future__ import annotations

import csv
import dataclasses
import numbers
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from effortface.core import bounds
from effortface.core.errors import UserError
from effortface.core.fileio import read_json
from effortface.synth.motion import check_parents

TABLES_CSV = Path(__file__).with_name("data") / "segment_inertia_tables.csv"

#: model segment -> de Leva table row. Head and trunk use the cervicale (C7) variants, because
#: skeletons have a neck-base joint but rarely a suprasternale or mid-gonion point.
SEGMENT_ROWS: dict[str, str] = {
    "head": "head_neck_alt",
    "trunk": "trunk_alt",
    **{f"{side}_{part}": part for side in ("left", "right")
       for part in ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")},
}
REQUIRED_SEGMENTS: tuple[str, ...] = tuple(SEGMENT_ROWS)

#: Back-load offset behind the trunk centre of mass, metres **(choice)**.
BACK_LOAD_OFFSET_M = 0.15

#: An end point: a joint name, ``"A|B"`` (the first of A, B present), or a list (their mean).
EndPoint = str | Sequence[str]
SegmentMapping = Mapping[str, tuple[EndPoint, EndPoint]]


def _limbs(
    parts: Mapping[str, tuple[str, str]], left: str, right: str
) -> dict[str, tuple[EndPoint, EndPoint]]:
    """Expand ``part -> (proximal, distal)`` templates with ``{S}`` into left_/right_ segments."""
    out: dict[str, tuple[EndPoint, EndPoint]] = {}
    for side, spelling in (("left", left), ("right", right)):
        for part, (prox, dist) in parts.items():
            out[f"{side}_{part}"] = (prox.replace("{S}", spelling), dist.replace("{S}", spelling))
    return out


#: Built-in skeleton conventions: segment -> (proximal end, distal end).
CONVENTIONS: dict[str, dict[str, tuple[EndPoint, EndPoint]]] = {
    "CMU": {
        # cgspeed's Neck sits mid-thorax; Neck1 (10 cm higher) is the closer match to C7. Skeletons
        # without a neck (PyMO's Spine -> Head) start the head at its Head joint.
        "head": ("Head_end", "Neck1|Neck|Head"),
        "trunk": ("Neck1|Neck|Head", ["LeftUpLeg", "RightUpLeg"]),
        **_limbs({
            "upper_arm": ("{S}Arm", "{S}ForeArm"), "forearm": ("{S}ForeArm", "{S}Hand"),
            "hand": ("{S}Hand", "{S}HandIndex1_end|{S}HandIndex1|{S}Hand_End|{S}Hand_end"),
            "thigh": ("{S}UpLeg", "{S}Leg"), "shank": ("{S}Leg", "{S}Foot"),
            "foot": ("{S}Foot", "{S}ToeBase_end|{S}ToeBase"),
        }, "Left", "Right"),
    },
    "Mixamo": {
        "head": ("HeadTop_End|Head_end", "Neck"),
        "trunk": ("Neck", ["LeftUpLeg", "RightUpLeg"]),
        **_limbs({
            "upper_arm": ("{S}Arm", "{S}ForeArm"), "forearm": ("{S}ForeArm", "{S}Hand"),
            "hand": ("{S}Hand", "{S}HandMiddle1|{S}HandIndex1"),
            "thigh": ("{S}UpLeg", "{S}Leg"), "shank": ("{S}Leg", "{S}Foot"),
            "foot": ("{S}Foot", "{S}Toe_End|{S}ToeBase_end|{S}ToeBase"),
        }, "Left", "Right"),
    },
    "Unreal": {
        "head": ("head_end|head", "neck_01"),
        "trunk": ("neck_01", ["thigh_l", "thigh_r"]),
        **_limbs({
            "upper_arm": ("upperarm_{S}", "lowerarm_{S}"), "forearm": ("lowerarm_{S}", "hand_{S}"),
            "hand": ("hand_{S}", "middle_01_{S}|hand_{S}_end"),
            "thigh": ("thigh_{S}", "calf_{S}"), "shank": ("calf_{S}", "foot_{S}"),
            "foot": ("foot_{S}", "ball_{S}_end|ball_{S}"),
        }, "l", "r"),
    },
    "Unity": {
        "head": ("Head_end|Head", "Neck"),
        "trunk": ("Neck", ["LeftUpperLeg", "RightUpperLeg"]),
        **_limbs({
            "upper_arm": ("{S}UpperArm", "{S}LowerArm"), "forearm": ("{S}LowerArm", "{S}Hand"),
            "hand": ("{S}Hand", "{S}MiddleProximal|{S}Hand_end"),
            "thigh": ("{S}UpperLeg", "{S}LowerLeg"), "shank": ("{S}LowerLeg", "{S}Foot"),
            "foot": ("{S}Foot", "{S}Toes_end|{S}Toes"),
        }, "Left", "Right"),
    },
    # classic Biovision BVH (the format's own examples): Hips, Chest, Neck, Head, LeftCollar,
    # LeftUpArm, LeftLowArm, LeftHand, LeftUpLeg, LeftLowLeg, LeftFoot, end sites <joint>_end
    "Biovision": {
        "head": ("Head_end|Head", "Neck"),
        "trunk": ("Neck", ["LeftUpLeg", "RightUpLeg"]),
        **_limbs({
            "upper_arm": ("{S}UpArm", "{S}LowArm"), "forearm": ("{S}LowArm", "{S}Hand"),
            "hand": ("{S}Hand", "{S}Hand_end"),
            "thigh": ("{S}UpLeg", "{S}LowLeg"), "shank": ("{S}LowLeg", "{S}Foot"),
            "foot": ("{S}Foot", "{S}Foot_end|{S}Toe|{S}Toe_end"),
        }, "Left", "Right"),
    },
    # SMPL / SMPL-X joint names (and the anatomical left_/right_ names of keypoint sets built on them)
    "SMPL": {
        "head": ("head_end|head", "neck"),
        "trunk": ("neck", ["left_hip", "right_hip"]),
        **_limbs({
            "upper_arm": ("{S}_shoulder", "{S}_elbow"), "forearm": ("{S}_elbow", "{S}_wrist"),
            "hand": ("{S}_wrist", "{S}_hand|{S}_index1|{S}_wrist_end"),
            "thigh": ("{S}_hip", "{S}_knee"), "shank": ("{S}_knee", "{S}_ankle"),
            "foot": ("{S}_ankle", "{S}_foot|{S}_ankle_end"),
        }, "left", "right"),
    },
    # Xsens MVN (anatomical segment names): Pelvis, L5 ... T8, Neck, Head, RightShoulder,
    # RightUpperArm, RightForeArm, RightHand, RightUpperLeg, RightLowerLeg, RightFoot, RightToe
    "Xsens": {
        "head": ("Head_end|Head", "Neck"),
        "trunk": ("Neck", ["LeftUpperLeg", "RightUpperLeg"]),
        **_limbs({
            "upper_arm": ("{S}UpperArm", "{S}ForeArm"), "forearm": ("{S}ForeArm", "{S}Hand"),
            "hand": ("{S}Hand", "{S}Hand_end"),
            "thigh": ("{S}UpperLeg", "{S}LowerLeg"), "shank": ("{S}LowerLeg", "{S}Foot"),
            "foot": ("{S}Foot", "{S}Toe_end|{S}Toe"),
        }, "Left", "Right"),
    },
    # Bandai Namco Research motion dataset (6 channels on every joint): Hips, Spine, Chest, Neck, Head,
    # Shoulder_L, UpperArm_L, LowerArm_L, Hand_L, UpperLeg_L, LowerLeg_L, Foot_L, Toes_L (its head's
    # End Site sits at the Head joint: the head segment runs from there)
    "Bandai Namco": {
        "head": ("Head_end|Head", "Neck"),
        "trunk": ("Neck", ["UpperLeg_L", "UpperLeg_R"]),
        **_limbs({
            "upper_arm": ("UpperArm_{S}", "LowerArm_{S}"), "forearm": ("LowerArm_{S}", "Hand_{S}"),
            "hand": ("Hand_{S}", "Hand_{S}_end"),
            "thigh": ("UpperLeg_{S}", "LowerLeg_{S}"), "shank": ("LowerLeg_{S}", "Foot_{S}"),
            "foot": ("Foot_{S}", "Toes_{S}_end|Toes_{S}"),
        }, "L", "R"),
    },
    "AMP": {
        "head": ("head_end", "head"),
        "trunk": ("head", ["left_thigh", "right_thigh"]),
        **_limbs({
            "upper_arm": ("{S}_upper_arm", "{S}_lower_arm"), "forearm": ("{S}_lower_arm", "{S}_hand"),
            "hand": ("{S}_hand", "{S}_hand_end"),
            "thigh": ("{S}_thigh", "{S}_shin"), "shank": ("{S}_shin", "{S}_foot"),
            "foot": ("{S}_foot_heel|{S}_foot", "{S}_foot_toe"),
        }, "left", "right"),
    },
}


class SegmentMappingError(UserError):
    """Skeleton joints could not be mapped to the required body segments."""


# --------------------------------------------------------------------------------------------
# tables


@dataclasses.dataclass(frozen=True)
class SegmentParams:
    """One de Leva row: fractions of body mass and of segment length (CM from the proximal end)."""

    mass_frac: float
    com_frac: float
    r_sag: float
    r_trans: float
    r_long: float
    mean_length_m: float


def read_deleva_table(sex: str, path: str | Path = TABLES_CSV) -> dict[str, SegmentParams]:
    """The de Leva (1996) table for one sex, keyed by table segment name.

    Parameters
    ----------
    sex : {'male', 'female'}
    path : str or Path
        The inertia-table CSV (comment lines start with '#').

    Returns
    -------
    dict of str to SegmentParams

    Raises
    ------
    UserError
        Unknown sex.
    """
    sex = _check_sex(sex)
    with open(path, newline="", encoding="utf-8") as fh:
        rows = csv.DictReader(line for line in fh if not line.startswith("#"))
        return {
            r["segment"]: SegmentParams(*(float(r[k]) for k in (
                "mass_frac", "com_frac", "rg_sag", "rg_trans", "rg_long", "mean_length_m")))
            for r in rows if r["table"] == "deLeva1996" and r["sex"] == sex
        }


def _check_sex(sex: str) -> str:
    """Normalise 'male'/'female' (also 'm'/'f') or raise naming the parameter."""
    value = str(sex).strip().lower()
    value = {"m": "male", "f": "female"}.get(value, value)
    if value not in ("male", "female"):
        raise UserError(f"sex: expected 'male' or 'female', got {sex!r}")
    return value


# --------------------------------------------------------------------------------------------
# loads


def _finite_number(value: object) -> float | None:
    """``value`` as a float if it is a finite real number (not a bool or a string), else None."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    number = float(value)
    return number if np.isfinite(number) else None


@dataclasses.dataclass(frozen=True)
class Loads:
    """Carried loads in kg: one point mass per hand (at the hand CM) and one on the back.

    Raises
    ------
    UserError
        A negative or non-finite load (the message names the field).
    """

    left_hand_kg: float = 0.0
    right_hand_kg: float = 0.0
    back_kg: float = 0.0

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            number = _finite_number(value)
            if number is None or number < 0:
                raise UserError(f"{field.name}: expected a load of 0 kg or more, got {value!r}")
            bounds.check("load_kg", number, field.name)


# --------------------------------------------------------------------------------------------
# mapping


#: the mapping file format :func:`mapping_to_json` writes (``"version": 2``). Version 2 lists every
#: segment's ends from the trunk outwards: the head ``[neck, head top]`` like a limb ``[hip, knee]``.
#: Version 1 (a file without ``"version"``, the format before issue 34) lists the head ``[head top,
#: neck]``; it is still read. The trunk is ``[neck, hips]`` in both.
MAPPING_VERSION = 2
#: a template's stand-in for a name the file lacks: ``"<...>"`` (refused until it is replaced or its entry removed)
PLACEHOLDER_START = "<"


def read_mapping(path: str | Path) -> dict[str, tuple[EndPoint, EndPoint]]:
    """Read a user mapping file: JSON ``{"version": 2, segment: [proximal, distal], ...}``.

    An end point may be a joint name, ``"A|B"`` (the first present) or a list of names (their mean);
    a BVH End Site is ``<joint>_end``. A file may name only some segments: the built-in conventions
    fill the rest (:func:`map_skeleton`). See :func:`mapping_from_json` for the versions.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
        segment -> (proximal, distal) in the internal order (the head from its top, as de Leva).

    Raises
    ------
    SegmentMappingError
        Unreadable JSON, an unknown version, entries that are not ``[proximal, distal]`` pairs or
        still hold a template placeholder (named, with the file).
    """
    path = Path(path)
    data = read_json(path, "a JSON mapping segment -> [proximal, distal]", SegmentMappingError)
    return mapping_from_json(data, path)


def mapping_from_json(data: object, source: str | Path) -> dict[str, tuple[EndPoint, EndPoint]]:
    """A mapping in the internal order from its JSON form (a mapping file, a motion.json entry).

    ``"version": 2`` (:data:`MAPPING_VERSION`): the head is ``[neck, head top]``, from the trunk
    outwards like the limbs. No ``"version"`` (version 1): the head is ``[head top, neck]``. The
    internal order keeps the head from its top, the end de Leva (1996) measures its centre of
    mass from.

    Raises
    ------
    SegmentMappingError
        Naming ``source``: not an object, an unknown version, bad or unknown entries, placeholders.
    """
    if not isinstance(data, dict):
        raise SegmentMappingError(
            f"{source}: expected a JSON object segment -> [proximal, distal], got {type(data).__name__}")
    version = data.get("version", 1)
    if version not in (1, MAPPING_VERSION) or isinstance(version, bool):
        raise SegmentMappingError(f"{source}: version: expected 1 or {MAPPING_VERSION}, found {version!r}")
    entries = {k: v for k, v in data.items() if k != "version"}
    bad = [k for k, v in entries.items() if not _is_pair(v)]
    unknown = [k for k in entries if k not in SEGMENT_ROWS]
    if bad or unknown:
        raise SegmentMappingError(
            f"{source}: expected [proximal, distal] joint names (a name or a list of names each) for "
            f"segments among {', '.join(REQUIRED_SEGMENTS)}; bad entries: {', '.join(bad + unknown)}"
        )
    holes = [k for k, v in entries.items() if any(n.startswith(PLACEHOLDER_START) for n in _names(v))]
    if holes:
        raise SegmentMappingError(
            f"{source}: expected joint names, found template placeholders '<...>' in {', '.join(holes)}: "
            f"replace them with names of the file (effortface motion inspect lists them) or delete the entries")
    out = {k: (v[0], v[1]) for k, v in entries.items()}
    if version == MAPPING_VERSION and "head" in out:
        out["head"] = (out["head"][1], out["head"][0])
    return out


def mapping_to_json(mapping: SegmentMapping) -> dict[str, object]:
    """The JSON form (:data:`MAPPING_VERSION`) of a mapping in the internal order (the inverse of
    :func:`mapping_from_json`): ``{"version": 2, segment: [proximal, distal], ...}``."""
    out: dict[str, object] = {"version": MAPPING_VERSION}
    for seg, (prox, dist) in mapping.items():
        ends = [dist, prox] if seg == "head" else [prox, dist]
        out[seg] = [e if isinstance(e, str) else list(e) for e in ends]
    return out


def _names(ends: Sequence[EndPoint]) -> list[str]:
    """Every joint name of a (proximal, distal) pair, ``A|B`` alternatives split."""
    return [n for end in ends for e in ([end] if isinstance(end, str) else end) for n in e.split("|")]


def _is_end(end: object) -> bool:
    """True if ``end`` is a joint name or a non-empty list/tuple of joint names."""
    if isinstance(end, str):
        return True
    return isinstance(end, (list, tuple)) and bool(end) and all(isinstance(e, str) for e in end)


def _is_pair(ends: object) -> bool:
    """True if ``ends`` is a ``[proximal, distal]`` pair of end points."""
    return isinstance(ends, (list, tuple)) and len(ends) == 2 and all(_is_end(e) for e in ends)


def _joint_key(name: str) -> str:
    """Joint name for matching: namespace ('mixamorig:') stripped, lower case."""
    return name.rsplit(":", 1)[-1].lower()


def _resolve_end(end: EndPoint, index: Mapping[str, int]) -> tuple[int, ...] | None:
    """Joint indices of one end point, or None if it cannot be found."""
    if isinstance(end, str):
        for option in end.split("|"):
            if _joint_key(option) in index:
                return (index[_joint_key(option)],)
        return None
    found = [_resolve_end(e, index) for e in end]
    if any(f is None for f in found) or not found:
        return None
    return tuple(i for f in found for i in f)  # type: ignore[union-attr]  # no None: checked above


def end_names(end: EndPoint, joint_names: Sequence[str]) -> list[str] | None:
    """The joint names of ``joint_names`` one end point resolves to (``A|B``: the first present; a
    list: all of them), or None if it cannot be found."""
    found = _resolve_end(end, {_joint_key(n): i for i, n in enumerate(joint_names)})
    return None if found is None else [joint_names[i] for i in found]


def resolve_mapping(
    joint_names: Sequence[str], mapping: SegmentMapping
) -> tuple[dict[str, tuple[tuple[int, ...], tuple[int, ...]]], list[str]]:
    """Joint indices of every mapped segment and the list of required segments left unmapped."""
    if not isinstance(mapping, Mapping):
        raise SegmentMappingError(
            f"mapping: expected a mapping segment -> (proximal, distal), found {type(mapping).__name__}")
    index = {_joint_key(n): i for i, n in enumerate(joint_names)}
    resolved, missing = {}, []
    for seg in REQUIRED_SEGMENTS:
        ends = mapping.get(seg)
        if ends is not None and not _is_pair(ends):
            raise SegmentMappingError(
                f"mapping: {seg}: expected (proximal, distal) joint names (a name or a list of names "
                f"each), found {ends!r}")
        prox = _resolve_end(ends[0], index) if ends else None
        dist = _resolve_end(ends[1], index) if ends else None
        if prox is None or dist is None:
            missing.append(seg)
        else:
            resolved[seg] = (prox, dist)
    return resolved, missing


@dataclasses.dataclass(frozen=True)
class MappingFound:
    """The best mapping of a skeleton's joints to the 14 segments, complete or not.

    Attributes
    ----------
    convention : str
        What mapped it: a built-in convention (``"CMU"``), ``"user"`` (a complete user mapping) or
        ``"user + CMU"`` (a partial user mapping, the convention filling the rest).
    segments : dict
        segment -> (proximal joint indices, distal joint indices), the mapped segments only.
    unmapped : tuple of str
        The required segments left unmapped.
    user_segments : tuple of str
        The segments the user mapping named.
    """

    convention: str
    segments: dict[str, tuple[tuple[int, ...], tuple[int, ...]]]
    unmapped: tuple[str, ...]
    user_segments: tuple[str, ...] = ()


def find_mapping(joint_names: Sequence[str], mapping: SegmentMapping | None = None) -> MappingFound:
    """The mapping with the fewest unmapped segments: a user mapping, alone or filled by a convention.

    A user mapping complete on its own is ``"user"``; a partial one is merged over each built-in
    convention (the segments it names override the convention's) and the merge with the fewest
    unmapped segments wins (the first in :data:`CONVENTIONS` order on a tie). Without a user
    mapping, the convention with the fewest unmapped segments. Never raises for unmapped segments
    (``motion inspect`` shows them); :func:`map_skeleton` does.
    """
    if mapping is not None and not isinstance(mapping, Mapping):
        raise SegmentMappingError(
            f"mapping: expected a mapping segment -> (proximal, distal), found {type(mapping).__name__}")
    user = dict(mapping) if mapping is not None else None
    candidates: dict[str, SegmentMapping] = {}
    if user is not None:
        candidates["user"] = user
        candidates.update({f"user + {name}": {**conv, **user} for name, conv in CONVENTIONS.items()})
    else:
        candidates.update(CONVENTIONS)
    best: MappingFound | None = None
    for name, conv in candidates.items():
        resolved, missing = resolve_mapping(joint_names, conv)
        found = MappingFound(name, resolved, tuple(missing), tuple(s for s in REQUIRED_SEGMENTS if user and s in user))
        if not missing:
            return found
        if best is None or len(missing) < len(best.unmapped):
            best = found
    assert best is not None
    return best


def map_skeleton(
    joint_names: Sequence[str], mapping: SegmentMapping | str | Path | None = None, *, source: str | Path = "",
) -> tuple[str, dict[str, tuple[tuple[int, ...], tuple[int, ...]]]]:
    """Map a skeleton's joints to the 14 segments.

    Parameters
    ----------
    joint_names : sequence of str
        The skeleton's joints (names match case-insensitively, namespaces such as 'mixamorig:' ignored).
    mapping : mapping, str or Path, optional
        A user mapping (or JSON file, see :func:`read_mapping`), complete or partial: the built-in
        conventions (CMU, Mixamo, Unreal, Unity, Biovision, SMPL, Xsens,
        Bandai Namco, AMP) fill the segments it
        does not name (:func:`find_mapping`). When omitted, the first complete convention is used.
    source : str or Path
        The clip, named in the refusal.

    Returns
    -------
    convention : str
        What mapped it (see :attr:`MappingFound.convention`).
    segments : dict
        segment -> (proximal joint indices, distal joint indices).

    Raises
    ------
    SegmentMappingError
        Some required segments are left unmapped; the message names the clip, the mapping file
        and every unmapped segment.
    """
    mapping_file = mapping if isinstance(mapping, (str, Path)) else None
    if mapping_file is not None:
        mapping = read_mapping(mapping_file)
    found = find_mapping(joint_names, mapping)  # type: ignore[arg-type]  # a file was read above
    if not found.unmapped:
        return found.convention, found.segments
    where = f"{source}: " if str(source) else ""
    tried = f"mapping file {mapping_file} and the " if mapping_file is not None else \
        ("the mapping given and the " if mapping is not None else "")
    raise SegmentMappingError(
        f"{where}skeleton joints: expected every segment mapped ({tried}{', '.join(CONVENTIONS)} conventions "
        f"tried, best {found.convention}); unmapped segments: {', '.join(found.unmapped)}. Map them with "
        f'--mapping FILE.json: {{"version": 2, "{found.unmapped[0]}": ["<proximal joint>", "<distal joint>"], ...}} '
        f"naming only those (the conventions fill the rest; 'effortface motion inspect CLIP --mapping-template "
        f"FILE.json' writes one with the clip's names)"
    )


# --------------------------------------------------------------------------------------------
# body model


@dataclasses.dataclass(frozen=True)
class BodyModel:
    """Segments of one character, as arrays over segments S (ready for vectorised energies).

    Attributes
    ----------
    segment_names : tuple of str
        S segment names.
    mass_kg : float
        The character's body mass M (loads not included): the divisor of w and p.
    segment_mass_kg : ndarray, shape (S,)
    length_m : ndarray, shape (S,)
        Segment lengths (the skeleton's own).
    com_frac : ndarray, shape (S,)
        Centre of mass as a fraction of the length from the proximal end.
    radii : ndarray, shape (S, 3)
        Radii of gyration (sagittal, transverse, longitudinal) as fractions of the length.
    proximal_weights, distal_weights : ndarray, shape (S, J)
        End points as weighted means of joints: ``end = weights @ joint_positions``.
    frame_joint : ndarray, shape (S,)
        The joint whose rotation the segment follows (lowest common ancestor of its end joints).
    hip_joints : tuple of int
        (left, right) hip end points (first proximal joint of the thighs), for the body's forward axis.
    load_kg : ndarray, shape (S,)
        Point mass carried at each segment's CM (hands); ``back_load_kg`` sits on the trunk,
        :data:`BACK_LOAD_OFFSET_M` behind its CM.
    back_load_kg : float
    convention : str
        Which joint-name convention mapped the skeleton.

    Notes
    -----
    :func:`stack_bodies` gives the per-character fields a leading axis N (a crowd).
    """

    segment_names: tuple[str, ...]
    mass_kg: float
    segment_mass_kg: np.ndarray
    length_m: np.ndarray
    com_frac: np.ndarray
    radii: np.ndarray
    proximal_weights: np.ndarray
    distal_weights: np.ndarray
    frame_joint: np.ndarray
    hip_joints: tuple[int, int]
    load_kg: np.ndarray
    back_load_kg: float = 0.0
    convention: str = ""

    @property
    def com_weights(self) -> np.ndarray:
        """(S, J) weights giving each segment's CM from joint positions."""
        c = self.com_frac[..., None]
        return (1.0 - c) * self.proximal_weights + c * self.distal_weights

    @property
    def trunk_index(self) -> int:
        """Index of the trunk segment (-1 if the model has none)."""
        return self.segment_names.index("trunk") if "trunk" in self.segment_names else -1


def check_mass(mass_kg: float) -> float:
    """Return ``mass_kg`` as float, or raise UserError naming the parameter if not > 0."""
    number = _finite_number(mass_kg)
    if number is None or number <= 0:
        raise UserError(f"mass_kg: expected a body mass above 0 kg, got {mass_kg!r}")
    return bounds.check("mass_kg", number, "mass_kg")


def _end_weights(ends: Sequence[tuple[int, ...]], n_joints: int) -> np.ndarray:
    """(S, J) averaging weights for end points given as joint-index tuples."""
    w = np.zeros((len(ends), n_joints))
    for s, joints in enumerate(ends):
        for j in joints:
            w[s, j] += 1.0 / len(joints)
    return w


def _ancestors(j: int, parents: np.ndarray) -> list[int]:
    """``j`` and its ancestors, nearest first."""
    out: list[int] = []
    while j >= 0:  # ends: build_body checked that every parent comes before its child
        out.append(j)
        j = int(parents[j])
    return out


def lowest_common_ancestor(joints: Sequence[int], parents: np.ndarray) -> int:
    """The deepest joint that is an ancestor of (or equal to) every joint in ``joints``; -1 when they
    are in different trees (a skeleton of several roots)."""
    common = set(_ancestors(joints[0], parents))
    for j in joints[1:]:
        common &= set(_ancestors(j, parents))
    return next((a for a in _ancestors(joints[0], parents) if a in common), -1)


def _frame_joints(names: Sequence[str], resolved: Mapping[str, tuple[tuple[int, ...], tuple[int, ...]]],
                  parents: np.ndarray, joint_names: Sequence[str], source: str | Path) -> np.ndarray:
    """Each segment's frame joint (the lowest common ancestor of its end joints); UserError naming the
    clip and the segment when its ends are in different trees (a joint-positions CSV read without its
    skeleton file has every joint a root)."""
    out = []
    for seg in names:
        ends = resolved[seg][0] + resolved[seg][1]
        joint = lowest_common_ancestor(ends, parents)
        if joint < 0:
            from effortface.synth.motion_csv import SKELETON_SUFFIX  # the runtime does not load it otherwise

            csv_hint = (f"a joint-positions CSV needs its skeleton file {Path(source).stem}{SKELETON_SUFFIX} "
                        f"beside it (or a '# parents:' comment)" if str(source).lower().endswith(".csv")
                        else "the skeleton needs one tree")
            raise SegmentMappingError(f"{source or 'skeleton'}: {seg}: expected its joints "
                                      f"({', '.join(joint_names[j] for j in ends)}) in one skeleton tree, found them "
                                      f"in separate trees: {csv_hint}")
        out.append(joint)
    return np.array(out)


def _segment_lengths(prox_w: np.ndarray, dist_w: np.ndarray, reference_positions_m: np.ndarray) -> np.ndarray:
    """Median over reference frames of each segment's end-to-end distance, shape (S,)."""
    ref = np.asarray(reference_positions_m, dtype=float)
    ref = ref[None] if ref.ndim == 2 else ref
    return np.median(np.linalg.norm((dist_w - prox_w) @ ref, axis=-1), axis=0)


def build_body(
    joint_names: Sequence[str],
    parents: Sequence[int] | np.ndarray,
    mass_kg: float,
    sex: str,
    *,
    loads: Loads = Loads(),
    mapping: SegmentMapping | str | Path | None = None,
    reference_positions_m: np.ndarray | None = None,
    source: str | Path = "",
) -> BodyModel:
    """Build the 14-segment body of a character from its skeleton.

    Parameters
    ----------
    joint_names : sequence of str
        The skeleton's joints.
    parents : sequence of int
        Parent index of every joint (-1 for the root).
    mass_kg : float
        Body mass M in kg (> 0): segment masses are de Leva fractions of it.
    sex : {'male', 'female'}
        Which de Leva table.
    loads : Loads
        Carried loads (hands, back).
    mapping : mapping, str or Path, optional
        User mapping (dict or JSON file); the built-in conventions are tried when omitted.
    reference_positions_m : ndarray, shape (J, 3) or (T, J, 3), optional
        Joint positions giving the segment lengths (median over frames). When omitted the de Leva
        sample-mean lengths are used.
    source : str or Path
        The clip, named when its joints cannot be mapped.

    Returns
    -------
    BodyModel

    Raises
    ------
    UserError
        Non-positive mass, unknown sex, negative load, or unmapped segments (all named).
    """
    mass_kg = check_mass(mass_kg)
    table = read_deleva_table(sex)
    if not isinstance(loads, Loads):
        raise UserError(f"loads: expected a Loads instance, got {type(loads).__name__}")
    parents = check_parents(np.asarray(parents, dtype=int), "skeleton")
    convention, resolved = map_skeleton(joint_names, mapping, source=source)
    names = REQUIRED_SEGMENTS
    params = [table[SEGMENT_ROWS[s]] for s in names]
    prox_w = _end_weights([resolved[s][0] for s in names], len(joint_names))
    dist_w = _end_weights([resolved[s][1] for s in names], len(joint_names))
    if reference_positions_m is None:
        length_m = np.array([p.mean_length_m for p in params])
    else:
        length_m = _segment_lengths(prox_w, dist_w, reference_positions_m)
    load_kg = np.zeros(len(names))
    load_kg[names.index("left_hand")] = loads.left_hand_kg
    load_kg[names.index("right_hand")] = loads.right_hand_kg
    return BodyModel(
        segment_names=names,
        mass_kg=mass_kg,
        segment_mass_kg=mass_kg * np.array([p.mass_frac for p in params]),
        length_m=length_m,
        com_frac=np.array([p.com_frac for p in params]),
        radii=np.array([(p.r_sag, p.r_trans, p.r_long) for p in params]),
        proximal_weights=prox_w,
        distal_weights=dist_w,
        frame_joint=_frame_joints(names, resolved, parents, joint_names, source),
        hip_joints=(resolved["left_thigh"][0][0], resolved["right_thigh"][0][0]),
        load_kg=load_kg,
        back_load_kg=float(loads.back_kg),
        convention=convention,
    )


def stack_bodies(bodies: Sequence[BodyModel]) -> BodyModel:
    """Stack N bodies on the same skeleton into one, for energies vectorised over characters.

    Per-character fields (``mass_kg``, ``segment_mass_kg``, ``length_m``, ``com_frac``, ``radii``,
    ``load_kg``, ``back_load_kg``) gain a leading axis of length N (so men and women can mix);
    the skeleton fields are shared.

    Parameters
    ----------
    bodies : sequence of BodyModel
        At least one body; all with the same segments, end points, frame joints and hips.

    Returns
    -------
    BodyModel

    Raises
    ------
    UserError
        No bodies, or bodies built on different skeletons or mappings.
    """
    if not bodies:
        raise UserError("bodies: expected at least one body, got none")
    first = bodies[0]
    for i, b in enumerate(bodies):
        if b.segment_names != first.segment_names or b.hip_joints != first.hip_joints \
                or not np.array_equal(b.proximal_weights, first.proximal_weights) \
                or not np.array_equal(b.distal_weights, first.distal_weights) \
                or not np.array_equal(b.frame_joint, first.frame_joint) or np.ndim(b.mass_kg) != 0:
            raise UserError(f"bodies: expected single bodies on one skeleton and mapping, body {i} differs")
    return dataclasses.replace(
        first,
        mass_kg=np.array([b.mass_kg for b in bodies]),  # type: ignore[arg-type]  # (N,): one per body
        segment_mass_kg=np.stack([b.segment_mass_kg for b in bodies]),
        length_m=np.stack([b.length_m for b in bodies]),
        com_frac=np.stack([b.com_frac for b in bodies]),
        radii=np.stack([b.radii for b in bodies]),
        load_kg=np.stack([b.load_kg for b in bodies]),
        back_load_kg=np.array([b.back_load_kg for b in bodies]),  # type: ignore[arg-type]  # (N,)
    )
