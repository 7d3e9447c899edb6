"""The plausibility gate: is the body a clip was read as a human body? (numpy only)

A reader can give confident wrong physics with no error: doubled bones (BVH position channels added
to the OFFSET), the wrong length unit, the wrong up axis. After reading, :func:`check_plausible`
measures the standing height, the main segment lengths and the ground under the feet, and refuses in
one line naming the file and the figure when one is outside the human ranges of
:data:`effortface.core.physio_limits.BODY_M`; ``trust=True`` (``--trust-skeleton``) measures and
proceeds (a child or a creature, on purpose). Every command that reads motion calls it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.core.physio_limits import BODY_M, GROUND_SPREAD_M, GROUND_TILT_DEG
from effortface.synth.motion import READING_KEYS, UP_FRAMES, Motion, MotionBlocks, read_motion, read_motion_blocks
from effortface.synth.read_options import MotionReadOptions
from effortface.synth.segments import SegmentMapping, SegmentMappingError, map_skeleton

#: frames measured at most (evenly spaced): the figures are medians and percentiles, a few thousand
#: frames give them to a millimetre
MEASURED_FRAMES = 2000
#: percentile of the per-frame height taken as the standing height: the clip's most upright frames
#: (a squat, a bow or a fall in the rest of the clip does not lower it; arms raised do not count, the
#: height is the head's)
STANDING_PERCENTILE = 90.0
#: a head segment (top of the head to the neck base) shorter than this has no head top (an End Site
#: at the head joint, as in the Bandai Namco dataset): the height is then taken from the neck base
SHORTEST_HEAD_M = 0.15
#: neck base (cervicale) height as a fraction of the standing height: 0.87 (Drillis and Contini's
#: body proportions; ANSUR II men 1519 / 1756 mm = 0.865)
NECK_BASE_FRACTION = 0.87
#: the segments whose lengths are checked (each side), keys of :data:`BODY_M`
CHECKED_SEGMENTS = ("thigh", "shank", "upper_arm", "forearm", "trunk")
#: what a refusal tells the user to check
ADVICE = ("check --unit-m / --up or the skeleton's position channels (or --trust-skeleton for a child, a creature "
          "or a clip that never stands up)")


class ImplausibleBodyError(UserError):
    """A clip's body is outside the human ranges; the message names the file and the figure."""


def _sampled(motion: Motion) -> np.ndarray:
    """At most :data:`MEASURED_FRAMES` evenly spaced frames of the positions, float64, (T, J, 3)."""
    step = max(1, math.ceil(motion.n_frames / MEASURED_FRAMES))
    return np.asarray(motion.positions_m[::step], dtype=float)


def _mapped(motion: Motion, mapping: SegmentMapping | str | Path | None
            ) -> dict[str, tuple[tuple[int, ...], tuple[int, ...]]]:
    """The clip's segments (segment -> (proximal joints, distal joints)), empty if they do not map."""
    try:
        return map_skeleton(motion.joint_names, mapping)[1]
    except SegmentMappingError:
        return {}


def _segment_lengths_m(pos: np.ndarray, segments: dict[str, tuple[tuple[int, ...], tuple[int, ...]]]
                       ) -> dict[str, float]:
    """Median length over the frames of every mapped segment (end points as joint means)."""
    out = {}
    for name, (prox, dist) in segments.items():
        ends = pos[:, list(dist)].mean(axis=1) - pos[:, list(prox)].mean(axis=1)
        out[name] = float(np.median(np.linalg.norm(ends, axis=-1)))
    return out


def _height_m(pos: np.ndarray, segments: dict[str, tuple[tuple[int, ...], tuple[int, ...]]],
              lengths_m: dict[str, float]) -> float:
    """Standing height: the top of the head above the frame's lowest joint, at
    :data:`STANDING_PERCENTILE` over the frames. A skeleton whose head ends at its head joint (a head
    shorter than :data:`SHORTEST_HEAD_M`) has its height from its neck base,
    ``/`` :data:`NECK_BASE_FRACTION`; an unmapped one, from its highest joint."""
    z = pos[..., 2]
    if "head" not in segments:
        top = z.max(axis=1)
    elif lengths_m["head"] >= SHORTEST_HEAD_M:
        top = z[:, list(segments["head"][0])].mean(axis=1)
    else:
        neck = z[:, list(segments["head"][1])].mean(axis=1)
        top = z.min(axis=1) + (neck - z.min(axis=1)) / NECK_BASE_FRACTION
    return float(np.percentile(top - z.min(axis=1), STANDING_PERCENTILE))


def _ground(pos: np.ndarray) -> dict[str, float]:
    """The plane under the lowest joint of every frame: its level (median), tilt and the median
    distance of the frames' lowest joints from it."""
    lowest = pos[np.arange(len(pos)), pos[..., 2].argmin(axis=1)]
    xy = lowest[:, :2] - lowest[:, :2].mean(axis=0)
    if len(lowest) >= 3 and np.ptp(xy, axis=0).max() > 1.0:  # a path to fit a slope on
        design = np.column_stack([xy, np.ones(len(xy))])
        coef = np.linalg.lstsq(design, lowest[:, 2], rcond=None)[0]
        residual = lowest[:, 2] - design @ coef
        tilt_deg = math.degrees(math.atan(math.hypot(coef[0], coef[1])))
    else:  # in place: a level floor
        residual = lowest[:, 2] - np.median(lowest[:, 2])
        tilt_deg = 0.0
    return {"ground_m": float(np.median(lowest[:, 2])), "ground_tilt_deg": tilt_deg,
            "ground_spread_m": float(np.median(np.abs(residual)))}


def measure_body(motion: Motion, mapping: SegmentMapping | str | Path | None = None) -> dict[str, Any]:
    """The figures the gate checks, measured on (up to :data:`MEASURED_FRAMES` frames of) a clip.

    Parameters
    ----------
    motion : Motion
        A clip as a reader returns it (metres, Z up).
    mapping : mapping, str or Path, optional
        The user's joint-to-segment mapping (default: the built-in conventions); a skeleton that does
        not map gets no segment lengths and the height of its highest joint.

    Returns
    -------
    dict
        ``height_m`` (standing height), ``segments_m`` (segment -> median length, the mapped ones),
        ``ground_m`` (the floor level), ``ground_tilt_deg``, ``ground_spread_m``.
    """
    pos = _sampled(motion)
    segments = _mapped(motion, mapping)
    lengths_m = _segment_lengths_m(pos, segments)
    return {"height_m": _height_m(pos, segments, lengths_m), "segments_m": lengths_m, **_ground(pos)}


def _outside(figures: dict[str, Any]) -> str | None:
    """The first figure outside its range, as ``'standing height 2.85 m: expected 1.2-2.2 m'``."""
    lo, hi = BODY_M["height_m"]
    if not lo <= figures["height_m"] <= hi:
        return f"standing height {figures['height_m']:.2f} m: expected {lo:g}-{hi:g} m"
    for name, length_m in figures["segments_m"].items():
        part = name.split("_", 1)[1] if name.startswith(("left_", "right_")) else name
        if part in CHECKED_SEGMENTS:
            lo, hi = BODY_M[part]
            if not lo <= length_m <= hi:
                return f"{name.replace('_', ' ')} {length_m:.2f} m: expected {lo:g}-{hi:g} m"
    if figures["ground_tilt_deg"] > GROUND_TILT_DEG:
        return (f"ground (the lowest joint over the clip) tilted {figures['ground_tilt_deg']:.0f} degrees: "
                f"expected at most {GROUND_TILT_DEG:g}")
    if figures["ground_spread_m"] > GROUND_SPREAD_M:
        return (f"ground: the lowest joint a median {figures['ground_spread_m']:.2f} m off one plane: "
                f"expected at most {GROUND_SPREAD_M:g} m")
    return None


def check_plausible(motion: Motion, *, trust: bool = False,
                    mapping: SegmentMapping | str | Path | None = None, name: str | None = None) -> dict[str, Any]:
    """Measure a clip's body and refuse it if it is not a plausible human one.

    Parameters
    ----------
    motion : Motion
        A clip as a reader returns it (metres, Z up); its ``source`` is named in the message.
    trust : bool
        ``--trust-skeleton``: measure, never refuse (a child, a creature).
    mapping : mapping, str or Path, optional
        The user's joint-to-segment mapping (default: the built-in conventions).
    name : str, optional
        The file named in the message (default: ``motion.source``, which may describe more).

    Returns
    -------
    dict
        :func:`measure_body`'s figures (``height_m``, ``segments_m``, ``ground_m``,
        ``ground_tilt_deg``, ``ground_spread_m``) and ``trusted`` (True when ``trust`` let a body
        outside the ranges through).

    Raises
    ------
    ImplausibleBodyError
        One line: ``'<file>: standing height 2.85 m: expected 1.2-2.2 m; check --unit-m / --up or the
        skeleton's position channels (or --trust-skeleton for a child, a creature or a clip that never
        stands up)'``. The standing height is the clip's most upright frames': a clip of push-ups only
        never stands and is refused like a body read with the wrong up axis (a choice: the two look
        alike); ``trust=True`` reads it.
    """
    figures = measure_body(motion, mapping)
    problem = _outside(figures)
    if problem is not None and not trust:
        raise ImplausibleBodyError(f"{name or motion.source or 'motion'}: {problem}; {ADVICE}")
    figures["trusted"] = problem is not None
    return figures


def check_read(motion: Motion, options: MotionReadOptions, name: str | None = None) -> dict[str, Any]:
    """A clip as a command reads it: mapped (the mapping's refusal first), then through the gate.

    Parameters
    ----------
    motion : Motion
        The clip (or a streamed clip's skeleton: its reference frames).
    options : MotionReadOptions
        The command's ``--mapping`` and ``--trust-skeleton``.
    name : str, optional
        The file named in a refusal (default: ``motion.source``).

    Returns
    -------
    dict
        :func:`check_plausible`'s figures.

    Raises
    ------
    SegmentMappingError
        The skeleton does not map (named as :func:`effortface.synth.segments.map_skeleton` names it).
    ImplausibleBodyError
        A body outside the human ranges without ``trust_skeleton``.
    """
    map_skeleton(motion.joint_names, options.mapping, source=name or motion.source)
    return check_plausible(motion, trust=options.trust_skeleton, mapping=options.mapping, name=name)


def read_checked(path: str | Path, options: MotionReadOptions) -> tuple[Motion, dict[str, Any]]:
    """:func:`effortface.synth.motion.read_motion` with the command's options, then :func:`check_read`."""
    motion = read_motion(path, unit_m=options.unit_m, up=options.up)
    return motion, check_read(motion, options, str(path))


def read_checked_blocks(path: str | Path, options: MotionReadOptions, *,
                        reference_frames: int = UP_FRAMES) -> tuple[MotionBlocks, dict[str, Any]]:
    """:func:`effortface.synth.motion.read_motion_blocks` with the command's options, then
    :func:`check_read` on its reference frames."""
    blocks = read_motion_blocks(path, unit_m=options.unit_m, up=options.up, reference_frames=reference_frames)
    return blocks, check_read(blocks.skeleton, options, str(path))


def reading_record(motion: Motion, body: dict[str, Any] | None = None) -> dict[str, Any]:
    """How a clip was read, for ``.units.json`` and the BIDS sidecar: :attr:`Motion.reading` (unit and
    up axis, each with how it was decided) and the gate's figures (``height_m``, ``segments_m``, ...)."""
    record: dict[str, Any] = {k: motion.reading[k] for k in READING_KEYS if k in motion.reading}
    if body is not None:
        record["body"] = {k: (round(v, 4) if isinstance(v, float) else
                              {s: round(x, 4) for s, x in v.items()} if isinstance(v, dict) else v)
                          for k, v in body.items()}
    return record


#: a body faces along a horizontal axis when its facing is within this angle of it (degrees) ...
FACING_WITHIN_DEG = 30.0
#: ... in at least this share of the frames (a walk that turns back and forth faces no one axis)
FACING_SHARE = 0.8


def spatial_axes(motion: Motion, mapping: SegmentMapping | str | Path | None = None) -> str:
    """The BIDS ``SpatialAxes`` of a clip as read (Z up): ``'A'``/``'P'``/``'L'``/``'R'`` for x and y
    when the body faces along one horizontal axis, ``'_'`` when not, and ``'S'`` for z.

    The facing is the horizontal direction at 90 degrees clockwise (seen from above) from the right
    hip to the left hip (the first proximal joints of the thighs); without mapped thighs, ``'__S'``.

    Parameters
    ----------
    motion : Motion
        A clip as a reader returns it (metres, Z up).
    mapping : mapping, str or Path, optional
        The user's joint-to-segment mapping.

    Returns
    -------
    str
        E.g. ``'ALS'`` (the body faces +x, its left is +y) or ``'__S'``.
    """
    segments = _mapped(motion, mapping)
    if "left_thigh" not in segments or "right_thigh" not in segments:
        return "__S"
    pos = _sampled(motion)
    left = pos[:, segments["left_thigh"][0][0], :2] - pos[:, segments["right_thigh"][0][0], :2]
    facing = np.column_stack([left[:, 1], -left[:, 0]])  # left turned 90 degrees clockwise
    facing /= np.maximum(np.linalg.norm(facing, axis=1, keepdims=True), 1e-12)
    for axis, sign, letters in ((0, 1, "ALS"), (0, -1, "PRS"), (1, 1, "RAS"), (1, -1, "LPS")):
        share = float(np.mean(sign * facing[:, axis] >= math.cos(math.radians(FACING_WITHIN_DEG))))
        if share >= FACING_SHARE:
            return letters
    return "__S"
