"""C3D marker sets and lab axes: which convention named the markers, and which way is up.

Used by :mod:`effortface.synth.c3d_motion` (the one C3D reader); numpy only.

**Marker sets.** Each built-in set (:data:`MARKER_SETS`) names, for every *role* the joint-centre
rules use (Plug-in Gait's names: ``LASI``, ``LKNE``...), the labels that play it in that set, as
alternatives ``A|B`` (the first present wins) where ``A+B`` stands for the mid-point of both (a
joint centre between a lateral and a medial landmark). A *medial* role (``LKNEM``, ``LANKM``,
``LELBM``) turns the rule's "lateral marker moved medially by half the width" into the mid-point of
the two landmarks. The sets:

* **Plug-in Gait** (Vicon): the roles are the labels.
* **Qualisys sports** (QTM's labels, ``WaistLFront``, ``LShoulderTop``...).
* **CAST / ISB anatomical landmarks** (the names of Qualisys's PAF gait module and of Visual3D:
  Cappozzo et al. 1995, Wu et al. 2002/2005): ``L_IAS``/``L_IPS`` (ASIS/PSIS: hip centres by Bell et
  al. 1990, as for Plug-in Gait), ``L_FLE``+``L_FME`` (knee: mid-point of the femoral epicondyles),
  ``L_FAL``+``L_TAM`` (ankle: mid-point of the malleoli), ``L_HLE``+``L_HME`` (elbow: mid-point of
  the humeral epicondyles), ``L_RSP``+``L_USP`` or ``L_UHE`` (wrist: mid-point of the styloids),
  ``L_HM2`` (hand), ``L_FM2`` or ``L_FM1``+``L_FM5`` (toe), ``L_SAE`` or ``L_SAJ`` (acromion,
  shoulder as Plug-in Gait's LSHO), ``CV7``, ``SJN`` (also ``SNJ``), ``TV10``/``TV8``, ``SXS``; the
  head the centroid of its markers (``L_HEAD``, ``R_HEAD``, ``SGL``, ``L_HDF``...).

**Labels with prefixes.** A label is matched without its subject or rigid-body prefix: ``Matt:LASI``
and OptiTrack Motive's ``Skeleton:LShoulderTop`` by the part after the colon, Motive's
``Name_Hip``-style ``Skeleton_LShoulderTop`` or ``251112_KUO_LASI`` by the part after an underscore
that is a marker of a set, when the whole label is none (so ``L_IAS`` stays ``L_IAS``). Messages name the label as it is in the
file.

**Up axis** (:func:`decide_up`): the caller's ``up``; else the file's ``POINT:Y_SCREEN`` (the axis
drawn upwards on screen: ``+Z`` for Vicon and most Z-up labs, ``+Y`` for Y-up ones); checked against
the markers, the axis along which the head markers are above the foot markers (median over the
frames): when the markers are clear and disagree with the file, the markers win and the
disagreement is stated; with neither, Z up (the C3D habit). A negative ``Y_SCREEN`` the markers
cannot check gives the axis only, upwards: Qualisys Track Manager writes ``X_SCREEN -X``,
``Y_SCREEN -Z`` on Z-up captures (measured: 21 of 21 QTM exports, versions 2.17 to 2020.3, whose
head markers are above their feet along +Z), the screen's downward axis.
:func:`up_rotation` turns the file's up to effortface's +Z by a proper rotation (a cyclic
permutation of the axes, then a half turn about X for a negative axis), never a reflection.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

#: Plug-in Gait marker labels used (T10, STRN, SACR, the PSIS are optional helpers)
PLUG_IN_GAIT = ("LFHD", "RFHD", "LBHD", "RBHD", "C7", "CLAV", "LSHO", "RSHO", "LELB", "RELB",
                "LWRA", "LWRB", "RWRA", "RWRB", "LFIN", "RFIN", "LASI", "RASI", "LKNE", "RKNE",
                "LANK", "RANK", "LTOE", "RTOE")
#: Plug-in Gait modelled joint centres -> our joint names (used when present)
JOINT_CENTRES = {"LHJC": "LeftUpLeg", "RHJC": "RightUpLeg", "LKJC": "LeftLeg", "RKJC": "RightLeg",
                 "LAJC": "LeftFoot", "RAJC": "RightFoot", "LSJC": "LeftArm", "RSJC": "RightArm",
                 "LEJC": "LeftForeArm", "REJC": "RightForeArm", "LWJC": "LeftHand", "RWJC": "RightHand"}
#: the lower-body Plug-in Gait markers (a file with all of them and few others is a lower-body set)
PIG_LOWER = ("LASI", "RASI", "LKNE", "RKNE", "LANK", "RANK", "LTOE", "RTOE")
#: Plug-in Gait's head markers (a head from three of them: ``head_centre``)
HEAD_MARKERS = ("LFHD", "RFHD", "LBHD", "RBHD")
#: optional Plug-in Gait helpers used when present
PIG_HELPERS = ("SACR", "LPSI", "RPSI", "T10", "STRN")
#: markers of the trunk and arms: a set with none of them is lower-body only
UPPER_BODY = ("C7", "CLAV", "LSHO", "RSHO", "LELB", "RELB", "LWRA", "RWRA")
#: the roles every built-in set must fill (the Plug-in Gait markers but the head)
REQUIRED_ROLES = tuple(k for k in PLUG_IN_GAIT if k not in HEAD_MARKERS)
#: roles used when present: helpers, modelled joint centres, medial landmarks
OPTIONAL_ROLES = (*PIG_HELPERS, *JOINT_CENTRES, "LKNEM", "RKNEM", "LANKM", "RANKM", "LELBM", "RELBM")
#: the Qualisys sports marker set (QTM's labels) as the Plug-in Gait markers the rules use:
#: ``PiG name -> label|alternative``; its head is the centroid of :data:`QUALISYS_HEAD`
QUALISYS_SPORTS = {
    "LASI": "WaistLFront", "RASI": "WaistRFront", "LPSI": "WaistLBack", "RPSI": "WaistRBack",
    "C7": "SpineThoracic2|BackTop", "CLAV": "Chest|ChestTop", "T10": "SpineThoracic12", "STRN": "Chest|ChestLow",
    **{f"{s}{pig}": "|".join(f"{s}{q}" for q in qs.split("|")) for s in ("L", "R") for pig, qs in {
        "SHO": "ShoulderTop", "ELB": "ElbowOut", "WRA": "WristOut", "WRB": "WristIn",
        "FIN": "HandOut|Hand2|HandIn", "KNE": "KneeOut", "ANK": "AnkleOut", "TOE": "Forefoot2|ToeTip|Forefoot5",
    }.items()}}
QUALISYS_HEAD = ("HeadL", "HeadR", "HeadFront", "HeadTop")
#: CAST / ISB anatomical landmarks (Qualisys PAF, Visual3D) as the roles of the rules (module docstring)
CAST_ISB = {
    "C7": "CV7|C7", "CLAV": "SJN|SNJ|IJ", "T10": "TV10|TV8", "STRN": "SXS|PX",
    **{f"{s}{role}": "|".join(f"{s}_{a}" if "+" not in a else "+".join(f"{s}_{b}" for b in a.split("+"))
                              for a in alts.split("|"))
       for s in ("L", "R") for role, alts in {
           "ASI": "IAS", "PSI": "IPS", "SHO": "SAE|SAJ", "ELB": "HLE", "ELBM": "HME", "WRA": "RSP",
           "WRB": "USP|UHE", "FIN": "HM2|HM5", "KNE": "FLE", "KNEM": "FME", "ANK": "FAL", "ANKM": "TAM",
           "TOE": "FM2|FM1+FM5|FM1",
       }.items()}}
CAST_HEAD = ("L_HEAD", "R_HEAD", "SGL", "L_HDF", "R_HDF", "L_HDB", "R_HDB", "HEAD", "HEAD_TOP")
#: head-like and foot-like labels (any set, lower case after the prefix): the markers that say
#: which way is up when no built-in set names them
HEAD_LIKE = re.compile(r"head|^[lr]?[fb]hd$|^[lr]_hd[fb]$|vertex|^sgl$|^c7$|^cv7$|^t1$|^top$", re.I)
FOOT_LIKE = re.compile(r"toe|heel|^[lr]?_?hee$|^[lr]?_?cal$|fcc$|_fm\d$|^[lr]?mt\d$|^[lr]?_?met$|^[lr] met$|foot",
                       re.I)


@dataclasses.dataclass(frozen=True)
class MarkerSet:
    """A built-in marker convention: its roles' labels (module docstring) and its head markers.

    Attributes
    ----------
    key : str
        Short name (``"plug-in-gait"``), as :attr:`Motion.reading` ``marker_set`` starts.
    name : str
        For messages (``"Plug-in Gait"``).
    roles : dict of str to str
        Role (a Plug-in Gait name) -> ``A|B`` alternatives, ``A+B`` a mid-point.
    head : tuple of str
        Head marker labels (a head from at least three).
    """

    key: str
    name: str
    roles: dict[str, str]
    head: tuple[str, ...]


PIG_SET = MarkerSet("plug-in-gait", "Plug-in Gait",
                    {k: k for k in (*REQUIRED_ROLES, *PIG_HELPERS, *JOINT_CENTRES)}, HEAD_MARKERS)
QUALISYS_SET = MarkerSet("qualisys-sports", "Qualisys sports", QUALISYS_SPORTS, QUALISYS_HEAD)
CAST_SET = MarkerSet("cast-isb", "CAST/ISB anatomical landmarks", CAST_ISB, CAST_HEAD)
#: the built-in sets, in the order they are tried
MARKER_SETS = (PIG_SET, QUALISYS_SET, CAST_SET)


def match_names(names: tuple[str, ...] | list[str]) -> dict[str, str]:
    """``marker name -> point name`` for the points ``names`` (prefix after a colon already dropped
    where unambiguous): each name as it is, then, for a name that is no marker of a built-in set, the
    first part after an underscore that is one (Motive's ``Skeleton_LShoulderTop``,
    ``251112_KUO_LASI``) when no other point has it."""
    known = {label for s in MARKER_SETS for alts in s.roles.values() for a in alts.split("|")
             for label in a.split("+")} | {k for s in MARKER_SETS for k in s.head}
    out = {name.rsplit(":", 1)[-1]: name for name in names}
    for name in names:
        short = name.rsplit(":", 1)[-1]
        tails = [short.split("_", k)[-1] for k in range(1, short.count("_") + 1)] if short not in known else []
        tail = next((t for t in tails if t in known), "")  # "251112_KUO_LASI" -> "LASI"
        if tail and tail not in out:
            out[tail] = name
    return out


def pick(alternatives: str, found: dict[str, str]) -> list[str] | None:
    """The point names of the first alternative of ``A|B+C`` whose markers are all in ``found``
    (:func:`match_names`), or None."""
    for alt in alternatives.split("|"):
        parts = alt.split("+")
        if all(p in found for p in parts):
            return [found[p] for p in parts]
    return None


def choose_set(names: tuple[str, ...] | list[str]) -> MarkerSet | None:
    """The built-in set the points hold at least half of the roles of (the one holding the largest
    share; Plug-in Gait also with all of :data:`PIG_LOWER`), or None (labelled points)."""
    found = match_names(names)
    best, share = None, 0.0
    for mset in MARKER_SETS:
        required = [r for r in REQUIRED_ROLES if r in mset.roles] + ["HEAD"]
        have = sum(pick(mset.roles[r], found) is not None for r in required[:-1])
        have += sum(k in found for k in mset.head) >= 3
        if mset is PIG_SET and all(k in found for k in PIG_LOWER):
            have = max(have, len(required) // 2)
        if have >= len(required) // 2 and have / len(required) > share:
            best, share = mset, have / len(required)
    return best


def up_rotation(up: str) -> np.ndarray:
    """The proper rotation (3, 3) taking the file's ``up`` axis (``x``, ``-y``...) to +Z: rows are
    the new axes in the file's coordinates (a cyclic permutation; a half turn about the new X for a
    negative axis). ``positions @ R.T`` turns the file's points to Z up."""
    axis = up.lstrip("+-")
    order = {"x": (1, 2, 0), "y": (2, 0, 1), "z": (0, 1, 2)}[axis]
    rot = np.eye(3)[list(order)]
    if up.startswith("-"):
        rot = np.diag([1.0, -1.0, -1.0]) @ rot
    return rot


def screen_up(text: str) -> str | None:
    """``POINT:Y_SCREEN`` (``+Y``, ``-Z``, ``Y``...) as an up axis (``y``, ``-z``), or None."""
    m = re.fullmatch(r"\s*([+-]?)\s*([XYZxyz])\s*", text or "")
    return None if m is None else ("-" if m[1] == "-" else "") + m[2].lower()


def markers_up(positions: np.ndarray, missing: np.ndarray, head: list[int], feet: list[int],
               min_rise_m: float = 0.3) -> str | None:
    """The axis (``z``, ``-y``...) along which the head points are above the foot points: the
    median over the frames where some of each are present of the difference of their means, when
    one axis carries it (at least ``min_rise_m`` and twice either other axis); else None."""
    if not head or not feet:
        return None
    def mean(idx: list[int]) -> np.ndarray:
        pres = ~missing[:, idx]
        total = np.where(pres[..., None], positions[:, idx], 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            out: np.ndarray = total / pres.sum(axis=1)[:, None]
        return out
    diff = mean(head) - mean(feet)
    diff = diff[np.isfinite(diff).all(axis=1)]
    if not len(diff):
        return None
    d = np.median(diff, axis=0)
    i = int(np.argmax(np.abs(d)))
    others = np.abs(np.delete(d, i))
    if abs(d[i]) < min_rise_m or (others * 2 > abs(d[i])).any():
        return None
    return ("-" if d[i] < 0 else "") + "xyz"[i]


def decide_up(up: str | None, y_screen: str, from_markers: str | None) -> tuple[str, str]:
    """``(up_axis, up_from)``: the caller's ``up``; else ``POINT:Y_SCREEN`` unless the markers
    clearly disagree; else the markers; else Z (module docstring). ``up_axis`` has no ``+``."""
    if up is not None:
        return up.lstrip("+"), "--up"
    stated = screen_up(y_screen)
    shown = f"POINT:Y_SCREEN {y_screen.strip()}"
    marks = f"markers: head above feet along {_signed(from_markers)}" if from_markers else ""
    if stated and from_markers and from_markers != stated:
        return from_markers, f"{marks} ({shown} disagrees)"
    if stated and from_markers:
        return stated, shown + " (the markers agree)"
    if stated and stated.startswith("-"):  # QTM writes -Z on Z-up captures: the axis, not the sign
        return stated[1:], f"{shown}: its axis, upwards (a negative Y_SCREEN is the downward axis in QTM's files)"
    if stated:
        return stated, shown
    if from_markers:
        return from_markers, marks + " (no POINT:Y_SCREEN)"
    return "z", "the C3D habit: Z up (no POINT:Y_SCREEN, no head and foot markers to tell)"


def _signed(axis: str) -> str:
    return axis if axis.startswith("-") else "+" + axis
