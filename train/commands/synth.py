"""``effortface synth``: a motion clip + a character -> per-frame face curves (CSV or Live Link Face).

``MODEL_DIR`` is a model bundle folder or ``default`` (the built-in rule model). The CSV has the
columns ``t_s,w_per_kg,p_per_kg,nhr,hr_bpm,vo2,resp_rate,epoc`` and one per blendshape;
``--format livelink`` writes the Live Link Face CSV that Unreal's importer reads (``Timecode``,
``BlendShapeCount``, the 52 ARKit blendshapes in the app's column order, then the nine head and eye
rotations), with our blendshapes written under their ARKit names and every other column 0.
An existing ``--out`` is never replaced without ``--force``.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from effortface.core import bounds
from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text, check_apart
from effortface.train.motion import read_motion
from effortface.train.runtime import Character, FaceModel, load_model

#: Live Link Face CSV columns after Timecode and BlendShapeCount: the 52 ARKit blendshapes in the
#: app's order, then head and eye rotations (BlendShapeCount = 61 counts all of them).
LIVELINK_BLENDSHAPES = (
    "EyeBlinkLeft", "EyeLookDownLeft", "EyeLookInLeft", "EyeLookOutLeft", "EyeLookUpLeft",
    "EyeSquintLeft", "EyeWideLeft", "EyeBlinkRight", "EyeLookDownRight", "EyeLookInRight",
    "EyeLookOutRight", "EyeLookUpRight", "EyeSquintRight", "EyeWideRight", "JawForward", "JawRight",
    "JawLeft", "JawOpen", "MouthClose", "MouthFunnel", "MouthPucker", "MouthRight", "MouthLeft",
    "MouthSmileLeft", "MouthSmileRight", "MouthFrownLeft", "MouthFrownRight", "MouthDimpleLeft",
    "MouthDimpleRight", "MouthStretchLeft", "MouthStretchRight", "MouthRollLower", "MouthRollUpper",
    "MouthShrugLower", "MouthShrugUpper", "MouthPressLeft", "MouthPressRight", "MouthLowerDownLeft",
    "MouthLowerDownRight", "MouthUpperUpLeft", "MouthUpperUpRight", "BrowDownLeft", "BrowDownRight",
    "BrowInnerUp", "BrowOuterUpLeft", "BrowOuterUpRight", "CheekPuff", "CheekSquintLeft",
    "CheekSquintRight", "NoseSneerLeft", "NoseSneerRight", "TongueOut",
)
LIVELINK_ROTATIONS = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch",
                      "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll")
#: Live Link Face timecode rate (frames per second of the HH:MM:SS:FF.fff stamp; the app's default).
LIVELINK_TIMECODE_FPS = 60


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's synth line."""
    parser.add_argument("model_dir", metavar="MODEL_DIR", help="model bundle folder, or 'default'")
    parser.add_argument("motion", metavar="MOTION", help="motion clip (.bvh or .npz)")
    parser.add_argument("--out", required=True, metavar="CSV", help="output CSV file")
    parser.add_argument("--format", choices=("csv", "livelink"), default="csv",
                        help="per-frame curves (default) or a Live Link Face CSV")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--age", type=float, default=30.0, help="years (default 30)")
    parser.add_argument("--sex", default="male", help="male or female (default male)")
    parser.add_argument("--height", type=float, default=1.78, metavar="M", help="metres (default 1.78)")
    parser.add_argument("--mass", type=float, default=75.0, metavar="KG", help="kilograms (default 75)")
    parser.add_argument("--training-level", type=float, default=5.0, metavar="TL",
                        help="0-10 (default 5)")
    parser.add_argument("--expressiveness", default=None, metavar="A,B,C,D",
                        help="one factor per blendshape (default all 1)")
    parser.add_argument("--load-left", type=float, default=0.0, metavar="KG", help="left hand")
    parser.add_argument("--load-right", type=float, default=0.0, metavar="KG", help="right hand")
    parser.add_argument("--load-back", type=float, default=0.0, metavar="KG", help="on the back")
    parser.add_argument("--mapping", default=None, metavar="JSON",
                        help="joint-to-segment mapping file (default: built-in conventions)")
    parser.add_argument("--unit-m", type=float, default=None, metavar="M",
                        help="BVH length unit in metres (default: detected from the rest pose; "
                             "CMU cgspeed 0.05644)")


def _expressiveness(text: str | None, n: int) -> tuple[float, ...]:
    if text is None:
        return (1.0,) * n
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--expressiveness: expected {n} comma-separated numbers, found {text!r}") from None


def _character(args: argparse.Namespace, model: FaceModel) -> Character:
    n_blendshapes = len(model.blendshapes)
    try:
        character = Character(age=args.age, sex=args.sex, height_m=args.height, mass_kg=args.mass,
                         training_level=args.training_level,
                         expressiveness=_expressiveness(args.expressiveness, n_blendshapes),
                         load_left_kg=args.load_left, load_right_kg=args.load_right,
                         load_back_kg=args.load_back)
        model.expressiveness(character)
    except UserError as exc:
        raise UserError(f"character options: {exc}") from None
    return character


def curves_csv(curves: Mapping[str, np.ndarray], columns: Sequence[str]) -> str:
    """The per-frame CSV text (header + one row per frame)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    table = np.column_stack([curves[c] for c in columns])
    writer.writerows([[f"{v:.10g}" for v in row] for row in table])
    return buf.getvalue()


def livelink_timecode(t_s: float, fps: int = LIVELINK_TIMECODE_FPS) -> str:
    """``HH:MM:SS:FF.fff``: FF is the frame within the second at ``fps``, .fff the sub-frame."""
    frames = t_s * fps
    whole = int(np.floor(frames + 1e-9))
    sub = max(frames - whole, 0.0)
    seconds, ff = divmod(whole, fps)
    minutes, ss = divmod(seconds, 60)
    hh, mm = divmod(minutes, 60)
    return f"{hh:02d}:{mm:02d}:{ss:02d}:{ff:02d}.{int(round(sub * 1000)) % 1000:03d}"


def livelink_csv(curves: Mapping[str, np.ndarray], blendshapes: BlendshapeSet) -> str:
    """A Live Link Face CSV: our blendshapes under their ARKit names, every other column 0."""
    n = len(curves["t_s"])
    values = {name: np.zeros(n) for name in LIVELINK_BLENDSHAPES + LIVELINK_ROTATIONS}
    for shape in blendshapes.shapes:
        for arkit in shape.arkit:
            column = arkit[:1].upper() + arkit[1:]
            if column not in values:
                raise UserError(f"blendshape {shape.name}: expected ARKit names, found {arkit!r}")
            values[column] = curves[shape.name]
    header = ["Timecode", "BlendShapeCount", *LIVELINK_BLENDSHAPES, *LIVELINK_ROTATIONS]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    count = len(LIVELINK_BLENDSHAPES) + len(LIVELINK_ROTATIONS)
    table = np.column_stack([values[c] for c in header[2:]])
    for t, row in zip(curves["t_s"], table):
        writer.writerow([livelink_timecode(float(t)), count, *(f"{v:.6f}" for v in row)])
    return buf.getvalue()


def check_output(path: Path, force: bool) -> None:
    """Raise a UserError naming ``--out`` unless ``path`` can be (re)written as a file.

    Parameters
    ----------
    path : Path
        The ``--out`` file.
    force : bool
        Whether an existing file may be replaced.
    """
    if path.is_dir():
        raise UserError(f"--out {path}: expected a file path, found a folder")
    if path.exists() and not force:
        raise UserError(f"--out {path}: expected a new file, found an existing one "
                        "(use --force to replace it)")
    if not path.parent.is_dir():
        raise UserError(f"--out {path}: expected an existing folder, found no {path.parent}")


def write_output(path: Path, text: str, force: bool) -> None:
    """Write an output file atomically; refuse an existing file unless ``force`` (UserError).

    Parameters
    ----------
    path : Path
        The ``--out`` file.
    text : str
        The file's content.
    force : bool
        Whether an existing file may be replaced.

    Raises
    ------
    UserError
        A folder, an existing file without ``force``, a missing folder or a failed write (one
        line naming ``--out``).
    """
    check_output(path, force)
    try:
        atomic_write_text(path, text)
    except OSError as exc:
        raise UserError(f"--out {path}: expected a writable file, found {exc.strerror or exc}") from None


def run(args: argparse.Namespace) -> int:
    """Synthesize and write the curves; return 0."""
    out = Path(args.out)
    model_dir = None if args.model_dir == "default" else args.model_dir
    check_apart("--out", out, [model_dir, args.motion, args.mapping])
    check_output(out, args.force)  # fail before the work
    model = load_model(args.model_dir)
    character = _character(args, model)
    if args.unit_m is not None and not (math.isfinite(args.unit_m) and args.unit_m > 0):
        raise UserError(f"--unit-m: expected a length in metres above 0, found {args.unit_m:g}")
    if args.unit_m is not None:
        bounds.check("unit_m", args.unit_m, "--unit-m")
    motion = read_motion(args.motion, unit_m=args.unit_m)
    curves = model.synthesize(motion, character, mapping=args.mapping)
    text = (livelink_csv(curves, model.blendshapes) if args.format == "livelink"
            else curves_csv(curves, model.columns))
    write_output(out, text, args.force)
    return 0
