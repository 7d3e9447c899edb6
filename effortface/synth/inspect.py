"""What a motion file holds and how effortface reads it (``effortface motion inspect``, the File info panel).

:func:`inspect_motion` reads a clip the way every command does (:func:`effortface.synth.work.read_clip`
with the caller's ``--unit-m`` / ``--up`` / ``--mapping``) and reports: the producer (a C3D's
``MANUFACTURER``), frames, rate and duration, the length unit and up axis and how each was decided
(:attr:`Motion.reading` when the reader states it, else the rule this build applies), the standing
height, every joint or marker label as the file spells it (subject prefixes kept), the segment
mapping found (which convention; each segment's proximal and distal ends as names of the file),
the unmapped segments, the gaps of every C3D marker and the longest window where every marker is
present. A clip that cannot be mapped, or a C3D whose markers cannot be turned into joints, is
still inspected (the reason is in ``read_error``); a file that cannot be read at all raises.

No Qt here: ``effortface/synth/gui/synth_stage.py`` shows :meth:`Inspection.lines`.
"""

from __future__ import annotations

import dataclasses
import json
import os
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text
from effortface.synth.motion import Motion
from effortface.synth.read_options import MotionReadOptions
from effortface.synth.segments import (CONVENTIONS, REQUIRED_SEGMENTS, MappingFound, SegmentMapping,
                                       end_names, find_mapping, mapping_to_json, read_mapping)
from effortface.synth.work import read_clip

#: the ``--json`` keys every inspection has (None where the file does not tell)
JSON_KEYS = ("file", "format", "producer", "fps", "n_frames", "duration_s", "unit_m", "unit_from", "up_axis",
             "up_from", "height_m", "labels", "joints", "marker_set", "convention", "mapping", "unmapped",
             "gaps", "window", "reading", "plausibility", "read_error")
#: C3D parameters that name the software that wrote the file, in the order they are joined
PRODUCER_PARAMETERS = ("MANUFACTURER:COMPANY", "MANUFACTURER:SOFTWARE", "MANUFACTURER:VERSION")


@dataclasses.dataclass(frozen=True)
class Inspection:
    """What :func:`inspect_motion` found; :meth:`to_json` has the keys :data:`JSON_KEYS`."""

    file: str
    format: str
    producer: str | None
    fps: float
    n_frames: int
    unit_m: float | None
    unit_from: str
    up_axis: str | None
    up_from: str
    height_m: float | None
    labels: tuple[str, ...]
    joints: tuple[str, ...]
    marker_set: str | None
    convention: str | None
    mapping: dict[str, dict[str, list[str]]]
    unmapped: tuple[str, ...]
    gaps: dict[str, dict[str, float]]
    window: dict[str, float]
    reading: dict[str, Any]
    plausibility: dict[str, Any] | None
    read_error: str | None

    @property
    def duration_s(self) -> float:
        """Frames over rate, seconds."""
        return self.n_frames / self.fps if self.fps > 0 else 0.0

    def to_json(self) -> dict[str, Any]:
        """One JSON object (plain types) with every key of :data:`JSON_KEYS`."""
        out = {k: getattr(self, k) for k in JSON_KEYS}
        out["duration_s"] = round(self.duration_s, 4)
        for key in ("labels", "joints", "unmapped"):
            out[key] = list(out[key])
        return _plain(out)

    def lines(self) -> list[str]:
        """The compact aligned text report (``motion inspect`` without ``--json``)."""
        rows = [("file", self.file), ("format", self.format), ("producer", self.producer or "not stated"),
                ("frames", f"{self.n_frames} at {self.fps:g} Hz ({self.duration_s:.2f} s)"),
                ("unit", f"{_fmt(self.unit_m, 'g')} m per file unit ({self.unit_from})"),
                ("up axis", f"{self.up_axis or '?'} ({self.up_from})"),
                ("height", f"{_fmt(self.height_m, '.2f')} m ({_height_how(self.plausibility)})"),
                ("window", _window_text(self.window, self.fps))]
        if self.marker_set:
            rows.append(("marker set", self.marker_set))
        rows.append(("mapping", self.convention or "none"))
        if self.read_error:
            rows.append(("not read", self.read_error))
        if self.plausibility is not None:
            rows.append(("plausible", _plausibility_text(self.plausibility)))
        for key, value in self.reading.items():
            if key not in ("unit_m", "unit_from", "up_axis", "up_from", "producer", "window"):
                rows.append((f"reading.{key}", str(value)))
        out = [line for k, v in rows  # long values (how the up axis was decided...) wrap under themselves
               for line in textwrap.wrap(f"{k:<11} {v}", REPORT_WIDTH + 2, subsequent_indent=" " * 12,
                                         break_on_hyphens=False, break_long_words=False)]
        shown = [k or "''" for k in self.labels]  # an empty label shown as ''
        out.extend(_wrapped(f"labels ({len(self.labels)}, as in the file):", shown))
        if self.joints != self.labels:
            out.extend(_wrapped(f"joints ({len(self.joints)}, as read):", list(self.joints)))
        out.append("segments   proximal -> distal")
        width = max(len(s) for s in REQUIRED_SEGMENTS)
        for seg in REQUIRED_SEGMENTS:
            ends = self.mapping.get(seg)
            text = f"{' + '.join(ends['proximal'])} -> {' + '.join(ends['distal'])}" if ends else "UNMAPPED"
            out.append(f"  {seg:<{width}} {text}")
        out.append(f"unmapped   {', '.join(self.unmapped) or 'none'}")
        out.extend(_gap_lines(self.gaps))
        return out


def inspect_motion(path: str | os.PathLike[str], options: MotionReadOptions = MotionReadOptions()) -> Inspection:
    """Inspect a motion file (see the module docstring).

    Parameters
    ----------
    path : path-like
        A ``.bvh``, ``.c3d``, ``.csv`` or ``.npz`` clip (or a registered format).
    options : MotionReadOptions
        The caller's unit, up axis and mapping file (``trust_skeleton`` only changes what the
        plausibility figures say).

    Returns
    -------
    Inspection

    Raises
    ------
    UserError
        The file cannot be read at all (one line naming it), or the mapping file is not a mapping.
    """
    path = Path(path)
    user = None if options.mapping is None else dict(options.mapping) if isinstance(options.mapping, Mapping) \
        else read_mapping(options.mapping)
    if path.suffix.lower() == ".c3d":
        return _inspect_c3d(path, options, user)
    try:
        motion = read_clip(path, unit_m=options.unit_m, up=options.up)
    except UserError as exc:
        return _inspect_unscaled(path, options, user, exc)
    found = find_mapping(motion.joint_names, user)
    unit_m, unit_from = _unit(path, motion, options)
    up_axis, up_from = _up(path, motion, options)
    figures = plausibility(motion, options.trust_skeleton, user)
    return Inspection(
        file=str(path), format=path.suffix.lower().lstrip("."), producer=motion.reading.get("producer"),
        fps=motion.fps, n_frames=motion.n_frames, unit_m=unit_m, unit_from=unit_from, up_axis=up_axis,
        up_from=up_from, height_m=figures["height_m"], labels=motion.joint_names, joints=motion.joint_names,
        marker_set=motion.reading.get("marker_set"), convention=_convention(found),
        mapping=_mapping_names(found, motion.joint_names), unmapped=found.unmapped, gaps={},
        window=motion.reading.get("window") or {"first_frame": 0, "n_frames": motion.n_frames,
                                                 "of_frames": motion.n_frames},
        reading=dict(motion.reading), plausibility=figures, read_error=None)


def _inspect_unscaled(path: Path, options: MotionReadOptions, user: SegmentMapping | None,
                      error: UserError) -> Inspection:
    """A BVH whose length unit cannot be decided (``error``): its joints and mapping, read in file units,
    no unit or height; any other file that does not read: ``error`` raised."""
    if path.suffix.lower() != ".bvh" or options.unit_m is not None:
        raise error
    try:
        motion = read_clip(path, unit_m=1.0, up=options.up)  # the joints only: lengths stay in file units
    except UserError:
        raise error from None
    found = find_mapping(motion.joint_names, user)
    up_axis, up_from = _up(path, motion, options)
    return Inspection(
        file=str(path), format="bvh", producer=None, fps=motion.fps, n_frames=motion.n_frames, unit_m=None,
        unit_from="not decided: give --unit-m", up_axis=up_axis, up_from=up_from, height_m=None,
        labels=motion.joint_names, joints=motion.joint_names, marker_set=None, convention=_convention(found),
        mapping=_mapping_names(found, motion.joint_names), unmapped=found.unmapped, gaps={},
        window={"first_frame": 0, "n_frames": motion.n_frames, "of_frames": motion.n_frames},
        reading={}, plausibility=None, read_error=str(error))


def _inspect_c3d(path: Path, options: MotionReadOptions, user: SegmentMapping | None) -> Inspection:
    """:func:`inspect_motion` of a C3D: its points always, its joints when the reader turns them into any."""
    from effortface.synth.c3d_motion import marker_set, read_c3d_points

    points = read_c3d_points(path)  # a file neither reader reads: raised, one line
    header = c3d_header(path)
    motion: Motion | None = None
    error = None
    try:
        motion = read_clip(path, unit_m=options.unit_m, up=options.up)
    except UserError as exc:
        error = str(exc)
    names = motion.joint_names if motion is not None else points.labels
    found = find_mapping(names, user)
    figures = plausibility(motion, options.trust_skeleton, user) if motion is not None else None
    reading = dict(motion.reading) if motion is not None else {}
    unit_m, unit_from = (reading["unit_m"], str(reading.get("unit_from", ""))) if "unit_m" in reading else \
        (options.unit_m, "--unit-m") if options.unit_m is not None else header["unit"]
    up_axis, up_from = (reading["up_axis"], str(reading.get("up_from", ""))) if "up_axis" in reading else \
        (options.up, "--up") if options.up is not None else \
        ("z", f"assumed Z up (Vicon, Qualisys, Motion Analysis default){header['screen']}")
    return Inspection(
        file=str(path), format="c3d", producer=reading.get("producer") or header["producer"], fps=points.rate_hz,
        n_frames=len(points.missing), unit_m=unit_m, unit_from=unit_from, up_axis=up_axis, up_from=up_from,
        height_m=figures["height_m"] if figures is not None else None, labels=tuple(header["labels"]),
        joints=names, marker_set=reading.get("marker_set") or marker_set(points.labels),
        convention=_convention(found), mapping=_mapping_names(found, names), unmapped=found.unmapped,
        gaps=marker_gaps(points.labels, points.missing, points.rate_hz),
        window=reading.get("window") or complete_window(points.missing), reading=reading,
        plausibility=figures, read_error=error)


def c3d_header(path: Path) -> dict[str, Any]:
    """A C3D's producer (``MANUFACTURER``), labels as written (prefixes kept), ``POINT:UNITS`` and screen axes.

    Returns
    -------
    dict
        ``producer`` (str or None), ``labels`` (list of str), ``unit`` ((metres, how decided)),
        ``screen`` (``"; POINT:X_SCREEN +X, Y_SCREEN +Z"`` or ``""``).
    """
    from effortface.synth.c3d_motion import C3D_UNITS_M

    params = _c3d_parameters(path)
    words = [w for k in PRODUCER_PARAMETERS for v in params.get(k, [])[:1] for w in v.split() if w.isprintable()]
    producer = " ".join(words) or None
    labels = [v for k in ("POINT:LABELS", *(f"POINT:LABELS{i}" for i in range(2, 10))) for v in params.get(k, [])]
    units = " ".join(params.get("POINT:UNITS", [])).split()
    unit_m = C3D_UNITS_M.get(units[0].lower()) if units else C3D_UNITS_M["mm"]
    unit = (unit_m, f"POINT:UNITS {units[0]!r}" if units else "no POINT:UNITS: millimetres (the C3D default)")
    screen = ", ".join(f"{k.split(':')[1]} {params[k][0]}" for k in ("POINT:X_SCREEN", "POINT:Y_SCREEN")
                       if params.get(k))
    return {"producer": producer, "labels": labels, "unit": unit, "screen": f"; POINT:{screen}" if screen else ""}


def _c3d_parameters(path: Path) -> dict[str, list[str]]:
    """The string parameters :func:`c3d_header` needs, ``GROUP:NAME -> values`` (c3d package, else ezc3d)."""
    wanted = (*PRODUCER_PARAMETERS, "POINT:UNITS", "POINT:X_SCREEN", "POINT:Y_SCREEN", "POINT:LABELS",
              *(f"POINT:LABELS{i}" for i in range(2, 10)))
    try:
        import c3d

        class Parameters(c3d.Reader):  # type: ignore[misc,unused-ignore]
            def _check_metadata(self) -> None:  # the parameters only: no frame is read
                pass

        with open(path, "rb") as fh:
            reader = Parameters(fh)
            out = {}
            for key in wanted:
                param = reader.get(key)
                if param is not None:
                    values = param.string_array if param.dimensions and len(param.dimensions) > 1 \
                        else [param.string_value]
                    out[key] = [_clean(v) for v in values]
            return out
    except Exception:  # a file the c3d package refuses: ezc3d (read_c3d_points read it already)
        import ezc3d

        params = ezc3d.c3d(str(path))["parameters"]
        return {k: [_clean(v) for v in params[g][n]["value"]] for k in wanted
                for g, n in [k.split(":")] if g in params and n in params[g]}


def _clean(value: object) -> str:
    """A C3D string without NUL and space padding."""
    return str(value).replace("\x00", " ").strip()


def _unit(path: Path, motion: Motion, options: MotionReadOptions) -> tuple[float | None, str]:
    """The clip's metres per file unit and how it was decided (the reader's word: every built-in reader
    fills :attr:`Motion.reading`; a registered reader may not)."""
    if "unit_m" in motion.reading:
        return float(motion.reading["unit_m"]), str(motion.reading.get("unit_from", ""))
    if options.unit_m is not None:
        return options.unit_m, "--unit-m"
    return None, f"not stated by the {path.suffix.lower()} reader"


def _up(path: Path, motion: Motion, options: MotionReadOptions) -> tuple[str | None, str]:
    """The file's up axis and how it was decided (the reader's word, as :func:`_unit`)."""
    if "up_axis" in motion.reading:
        return str(motion.reading["up_axis"]), str(motion.reading.get("up_from", ""))
    if options.up is not None:
        return options.up, "--up"
    return None, f"not stated by the {path.suffix.lower()} reader"


def plausibility(motion: Motion, trust: bool = False, mapping: SegmentMapping | None = None) -> dict[str, Any]:
    """The plausibility gate's figures (:func:`effortface.synth.plausibility.measure_body`) and verdict:
    ``{"height_m", "segments_m", "ground_m", ...}`` plus ``"ok"`` (False with ``"refusal"``, the one
    line the gate gives, when it refuses) and ``"trusted"``."""
    from effortface.synth.plausibility import check_plausible

    try:
        figures: dict[str, Any] = dict(check_plausible(motion, trust=trust, mapping=mapping))
        figures["ok"] = True
    except UserError as exc:
        figures = {**check_plausible(motion, trust=True, mapping=mapping), "ok": False, "refusal": str(exc)}
    return figures


def check_plausible_clip(motion: Motion, trust: bool = False, mapping: SegmentMapping | None = None) -> None:
    """Refuse (UserError, one line) a clip outside the human ranges unless ``trust``."""
    from effortface.synth.plausibility import check_plausible

    check_plausible(motion, trust=trust, mapping=mapping)


def marker_gaps(labels: Sequence[str], missing: np.ndarray, rate_hz: float) -> dict[str, dict[str, float]]:
    """Per marker with a missing frame: ``missing_frames``, ``gaps`` (runs) and ``longest_gap_s``."""
    from effortface.synth.c3d_motion import _runs  # the gap runs fill_gaps uses

    out = {}
    for i, label in enumerate(labels):
        runs = _runs(np.asarray(missing[:, i]))
        if runs:
            out[label] = {"missing_frames": int(missing[:, i].sum()), "gaps": len(runs),
                          "longest_gap_s": round(max(n for _, n in runs) / rate_hz, 4)}
    return out


def complete_window(missing: np.ndarray) -> dict[str, float]:
    """The longest run of frames where every marker present in some frame is present: ``first_frame``,
    ``n_frames``, ``of_frames`` (markers missing in every frame are not counted)."""
    from effortface.synth.c3d_motion import _runs

    used = ~missing.all(axis=0)
    runs = _runs(np.asarray(~missing[:, used].any(axis=1))) if used.any() else []
    first, n = max(runs, key=lambda r: (r[1], -r[0])) if runs else (0, 0)
    return {"first_frame": first, "n_frames": n, "of_frames": int(len(missing))}


def _convention(found: MappingFound) -> str | None:
    """The convention, with how complete it is."""
    done = len(REQUIRED_SEGMENTS) - len(found.unmapped)
    if done == 0:
        return None
    return found.convention if not found.unmapped else f"{found.convention} (partial: {done} of 14 segments)"


def _mapping_names(found: MappingFound, names: Sequence[str]) -> dict[str, dict[str, list[str]]]:
    """Mapped segments' ends as the file's names, from the trunk outwards (the mapping file version 2 order)."""
    out = {}
    for seg in REQUIRED_SEGMENTS:
        if seg in found.segments:
            prox, dist = ([names[i] for i in end] for end in found.segments[seg])
            if seg == "head":
                prox, dist = dist, prox
            out[seg] = {"proximal": prox, "distal": dist}
    return out


#: what each end of a segment is, for the template's placeholders (from the trunk outwards)
END_PLACES = {"head": ("head top (vertex)", "neck base (C7)"),  # internal order: the head from its top
              "trunk": ("neck base (C7)", "hip joint"), "upper_arm": ("shoulder", "elbow"),
              "forearm": ("elbow", "wrist"), "hand": ("wrist", "hand end (middle knuckle or End Site)"),
              "thigh": ("hip joint", "knee"), "shank": ("knee", "ankle"),
              "foot": ("ankle", "toe (toe joint or its End Site)")}


def mapping_template(inspection: Inspection) -> dict[str, object]:
    """A complete mapping file (version 2) for this clip: all 14 segments, each end as the file's
    names where the mapping found it (or the best convention's end resolves), else a placeholder
    ``"<...>"`` naming what the convention looks for (refused until replaced or the entry removed)."""
    name = (inspection.convention or "CMU").split(" (")[0].split(" ")[-1]
    fallback = CONVENTIONS.get(name, CONVENTIONS["CMU"])
    internal: dict[str, tuple[Any, Any]] = {}
    for seg in REQUIRED_SEGMENTS:
        ends = inspection.mapping.get(seg)
        if ends is not None:
            prox, dist = _one(ends["proximal"]), _one(ends["distal"])
            internal[seg] = (dist, prox) if seg == "head" else (prox, dist)
        else:
            what = END_PLACES[seg.split("_", 1)[-1]]
            side = seg.split("_", 1)[0] + " " if seg.startswith(("left_", "right_")) else ""
            filled = [_filled(e, inspection.joints, f"{side}{place}") for e, place in zip(fallback[seg], what)]
            internal[seg] = (filled[0], filled[1])
    return mapping_to_json(internal)


def _one(names: list[str]) -> str | list[str]:
    """An end point as written in a mapping file: one name, or the list whose mean it is."""
    return names[0] if len(names) == 1 else names


def _filled(end: Any, joints: Sequence[str], what: str) -> str | list[str]:
    """A convention's end point as this file's names, or a placeholder naming the place and the
    convention's name for it (``"<left toe: toe joint or its End Site, e.g. LeftToeBase_end>"``)."""
    names = end_names(end, joints)
    if names is not None:
        return _one(names)
    if isinstance(end, str):
        return f"<{what}, e.g. {end.split('|')[0]}>"
    return [str(_filled(e, joints, f"{side} {what}")) for e, side in zip(end, ("left", "right"))]


def write_mapping_template(inspection: Inspection, out: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write :func:`mapping_template` as JSON to ``out`` (atomically); refuse an existing file without ``force``.

    Raises
    ------
    UserError
        ``out`` exists and ``force`` is False (nothing written).
    """
    out = Path(out)
    if out.exists() and not force:
        raise UserError(f"{out}: expected a new file for the mapping template, found one (give --force to replace it)")
    rows = [f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in mapping_template(inspection).items()]
    atomic_write_text(out, "{\n" + ",\n".join(rows) + "\n}\n")  # one segment a line
    return out


#: the text report's width for name lists (the File info panel shows it whole at 1280 x 800)
REPORT_WIDTH = 96


def _wrapped(title: str, names: list[str]) -> list[str]:
    """``title`` then the names, comma-separated, in lines of :data:`REPORT_WIDTH` indented by 2."""
    return [title] + textwrap.wrap(", ".join(names), REPORT_WIDTH, initial_indent="  ", subsequent_indent="  ",
                                   break_on_hyphens=False)


def _fmt(value: float | None, spec: str) -> str:
    """``value`` formatted, or ``?``."""
    return "?" if value is None else format(value, spec)


def _window_text(window: dict[str, float], fps: float) -> str:
    """``frames 0-211 of 212 (1.77 s), every marker present``."""
    first, n, of = int(window["first_frame"]), int(window["n_frames"]), int(window["of_frames"])
    if n == 0:
        return f"no frame of {of} has every marker"
    return f"frames {first}-{first + n - 1} of {of} ({n / fps:.2f} s) complete"


def _height_how(figures: dict[str, Any] | None) -> str:
    """How the standing height was measured."""
    return "standing, by the plausibility gate" if figures and figures.get("height_m") is not None else \
        "standing: highest joint above the lowest, median over frames"


def _plausibility_text(figures: dict[str, Any]) -> str:
    """``yes`` or the gate's refusal."""
    return "yes" if figures.get("ok") else f"no: {figures.get('refusal', '')}"


def _gap_lines(gaps: dict[str, dict[str, float]]) -> list[str]:
    """``gaps       LASI 12 frames in 2 gaps (longest 0.05 s); ...``"""
    if not gaps:
        return ["gaps       none"]
    width = max(len(k) for k in gaps)
    return ["gaps       marker: missing frames, gaps, longest gap"] + [
        f"  {k:<{width}} {int(g['missing_frames'])} frames, {int(g['gaps'])} gaps, {g['longest_gap_s']:.3f} s"
        for k, g in gaps.items()]


def _plain(value: Any) -> Any:
    """``value`` with numpy scalars and tuples as JSON types (NaN as None)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    return value

