"""Generated BVH fixtures for the reader's tests (written by the tests, never kept as files).

:func:`bandai_layout_bvh` writes a walk in the channel layout of the Bandai Namco Research motion
dataset (CC BY-NC 4.0, so not in this repository): every joint, the root included, has 6 channels
(``Xposition Yposition Zposition Zrotation Xrotation Yrotation``) whose positions repeat the joint's
OFFSET; a ``joint_Root`` at the floor above which ``Hips`` moves by its position channels; a rest
pose lying along x (the bones point along their joint's x axis; the Hips' rotation stands the body
up); centimetres; the head's End Site at the head joint. The skeleton's lengths are this file's own
(a 1.6 m adult), not the dataset's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

CHANNELS_6 = "Xposition Yposition Zposition Zrotation Xrotation Yrotation"

#: (name, parent, OFFSET in cm): bones along their joint's x axis, legs and arms along -x (they hang
#: once the Hips turn +x up), shoulders and hips apart along z (the left ones at -z: the body faces
#: +x, where it walks)
BANDAI_LAYOUT: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("joint_Root", None, (0.0, 0.0, 0.0)),
    ("Hips", "joint_Root", (0.0, 93.0, 0.0)),
    ("Spine", "Hips", (15.0, 0.0, 0.0)),
    ("Chest", "Spine", (10.0, 0.0, 0.0)),
    ("Neck", "Chest", (18.0, 0.0, 0.0)),
    ("Head", "Neck", (7.0, 0.0, 0.0)),
    *((f"Shoulder_{s}", "Chest", (14.0, 0.0, z * 4.0)) for s, z in (("L", -1), ("R", 1))),
    *((f"UpperArm_{s}", f"Shoulder_{s}", (0.0, 0.0, z * 13.0)) for s, z in (("L", -1), ("R", 1))),
    *((f"LowerArm_{s}", f"UpperArm_{s}", (-28.0, 0.0, 0.0)) for s in "LR"),
    *((f"Hand_{s}", f"LowerArm_{s}", (-25.0, 0.0, 0.0)) for s in "LR"),
    *((f"UpperLeg_{s}", "Hips", (0.0, 0.0, z * 9.0)) for s, z in (("L", -1), ("R", 1))),
    *((f"LowerLeg_{s}", f"UpperLeg_{s}", (-42.0, 0.0, 0.0)) for s in "LR"),
    *((f"Foot_{s}", f"LowerLeg_{s}", (-42.0, 0.0, 0.0)) for s in "LR"),
    *((f"Toes_{s}", f"Foot_{s}", (-8.0, 12.0, 0.0)) for s in "LR"),
)
#: End Site OFFSETs (cm) of the leaf joints
END_SITES = {"Head": (0.0, 0.0, 0.0), "Hand_L": (-8.0, 0.0, 0.0), "Hand_R": (-8.0, 0.0, 0.0),
             "Toes_L": (0.0, 5.0, 0.0), "Toes_R": (0.0, 5.0, 0.0)}


def _hierarchy(scale: float) -> tuple[str, list[str]]:
    """The HIERARCHY text and the joints in channel order."""
    children: dict[str | None, list[tuple[str, tuple[float, float, float]]]] = {}
    for name, parent, offset in BANDAI_LAYOUT:
        children.setdefault(parent, []).append((name, offset))
    order: list[str] = []
    lines = ["HIERARCHY"]

    def joint(name: str, offset: tuple[float, float, float], depth: int, root: bool) -> None:
        pad = "  " * depth
        order.append(name)
        lines.append(f"{pad}{'ROOT' if root else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {' '.join(f'{v * scale:g}' for v in offset)}")
        lines.append(f"{pad}  CHANNELS 6 {CHANNELS_6}")
        for child, child_offset in children.get(name, []):
            joint(child, child_offset, depth + 1, False)
        if name in END_SITES:
            lines.extend([f"{pad}  End Site", f"{pad}  {{",
                          f"{pad}    OFFSET {' '.join(f'{v * scale:g}' for v in END_SITES[name])}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    (root, root_offset), = children[None]
    joint(root, root_offset, 0, True)
    return "\n".join(lines), order


def _rotations_deg(name: str, phase: float) -> tuple[float, float, float]:
    """(Z, X, Y) rotation channels of a joint at a walk's phase (radians): the Hips stand the body up
    (Z 90: +x to +y); hips, knees, shoulders and elbows swing in the sagittal plane (about z)."""
    swing = math.sin(phase)
    side = 1.0 if name.endswith("_L") else -1.0
    if name == "Hips":
        return 90.0, 0.0, 0.0
    if name.startswith("UpperLeg"):
        return 25.0 * side * swing, 0.0, 0.0
    if name.startswith("LowerLeg"):
        return -30.0 * max(0.0, -side * swing) - 5.0, 0.0, 0.0
    if name.startswith("Foot"):
        return 10.0 * side * swing, 0.0, 0.0
    if name.startswith("UpperArm"):
        return -20.0 * side * swing, 0.0, 0.0
    if name.startswith("LowerArm"):
        return 15.0, 0.0, 0.0
    return 0.0, 0.0, 0.0


def bandai_layout_bvh(path: Path, *, scale: float = 1.0, n_frames: int = 120, fps: float = 30.0,
                      speed_cm_s: float = 130.0, root_rotation_zxy: tuple[float, float, float] = (0, 0, 0)) -> Path:
    """Write a walk in the Bandai Namco dataset's BVH layout (see the module docstring).

    Parameters
    ----------
    path : Path
        The file to write.
    scale : float
        Multiplies every length (2: the doubled bones the old reader made of such a file; 0.7: a child).
    n_frames, fps : int, float
        The clip's frames and rate (a stride of 1.1 s).
    speed_cm_s : float
        Walking speed along x, cm/s (before ``scale``).
    root_rotation_zxy : tuple of float
        The ``joint_Root`` rotation channels (degrees): (0, 90, 0) stands the body along +z (a Z-up file).

    Returns
    -------
    Path
    """
    text, order = _hierarchy(scale)
    offsets = {name: offset for name, _, offset in BANDAI_LAYOUT}
    rows = []
    for k in range(n_frames):
        t_s = k / fps
        phase = 2 * math.pi * t_s / 1.1
        values: list[float] = []
        for name in order:
            if name == "Hips":
                position = (speed_cm_s * t_s, offsets["Hips"][1] + 1.5 * math.cos(2 * phase), 0.0)
            else:
                position = offsets[name]
            rotation = root_rotation_zxy if name == "joint_Root" else _rotations_deg(name, phase)
            values += [v * scale for v in position] + list(rotation)
        rows.append(" ".join(f"{v:.6g}" for v in values))
    path.write_text(f"{text}\nMOTION\nFrames: {n_frames}\nFrame Time: {1 / fps:.7f}\n" + "\n".join(rows) + "\n")
    return path


def doubled_positions(path: Path, out: Path) -> Path:
    """The old reader's body of a 6-channel file as a file of its own: every OFFSET and position
    channel doubled (offset + channel, the reading before issue 34)."""
    lines = path.read_text().splitlines()
    body: list[str] = []
    motion = False
    for line in lines:
        if line.strip().startswith("OFFSET"):
            values = [2 * float(v) for v in line.split()[1:]]
            line = line.split("OFFSET")[0] + "OFFSET " + " ".join(f"{v:g}" for v in values)
        elif motion and line and line[0] not in "FM":
            numbers = np.array(line.split(), dtype=float).reshape(-1, 6)
            numbers[:, :3] *= 2
            line = " ".join(f"{v:.6g}" for v in numbers.ravel())
        motion = motion or line.strip() == "MOTION"
        body.append(line)
    out.write_text("\n".join(body) + "\n")
    return out
