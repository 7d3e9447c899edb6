"""Motion alongside a session: copy a clip into ``motion/`` and align it to the session clock.

Two alignments (``motion/motion.json`` records which, DESIGN.md):

* an offset: clip time 0 is session time ``offset_s`` (measured by the lab, e.g. a shared trigger);
* a sync jump: the operator logs ``sync,jump`` in events.csv (the hotkey) when the participant,
  standing, jumps at the start of the take; the jump is found in the clip's vertical root motion as
  a flight (the root in free fall) and its **apex** is matched to the event.

Jumps in the clip: peaks of the root height (6 Hz low-passed, as the energies) at least
:data:`MIN_JUMP_RISE_M` above the preceding low, reached at :data:`MIN_TAKEOFF_M_S` or faster, with the
root in free fall around the apex (mean vertical acceleration below :data:`FREE_FALL_FRACTION` g over
:data:`FREE_FALL_WINDOW_S`), which tells a jump from standing up out of a squat. The clip's first jump
is the sync jump: it is paired with each logged ``sync,jump`` in turn, and the offset under which the
most other clip jumps land within :data:`MATCH_TOLERANCE_S` of a logged one wins (then the smallest
residual); when several fit equally (one clip jump, several logged jumps) the operator names the one
to use (``--sync T``: the event nearest session time T). The residual is the RMS of the matched pairs' differences; with one pair it cannot be
measured (reported as such).
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
from pathlib import Path

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import write_json_atomic
from effortface.core.session.folder import read_session
from effortface.synth.energy import butterworth_sos, filter_frames
from effortface.synth.inspect import check_plausible_clip
from effortface.synth.motion import Motion
from effortface.synth.work import MOTION_DIR, MOTION_JSON, MOTION_JSON_VERSION, read_clip, read_motion_index

#: the kinds of clip ``motion attach`` copies (by suffix)
CLIP_FORMATS = {".bvh": "bvh", ".c3d": "c3d", ".csv": "joint positions csv", ".npz": "npz"}
SYNC_LABEL = "jump"
MIN_JUMP_RISE_M = 0.05
MIN_TAKEOFF_M_S = 0.8
FREE_FALL_FRACTION = 0.6
FREE_FALL_WINDOW_S = 0.16
MATCH_TOLERANCE_S = 0.25
CUTOFF_HZ = 6.0
_G = 9.81


class AttachError(UserError):
    """A clip that cannot be attached or aligned; the message names the clip, session or option."""


@dataclasses.dataclass(frozen=True)
class Alignment:
    """How a clip was put on the session clock.

    Attributes
    ----------
    offset_s : float
        Session time of the clip's first frame.
    method : str
        ``"offset"`` or ``"sync jump"``.
    matched : int
        Jumps matched to logged sync events (0 for an offset).
    residual_s : float or None
        RMS difference of the matched jumps after alignment; None when it cannot be measured.
    """

    offset_s: float
    method: str
    matched: int = 0
    residual_s: float | None = None

    def describe(self) -> str:
        """One line for the operator."""
        if self.method == "offset":
            return f"offset {self.offset_s:.3f} s (given)"
        residual = ("not measurable with one jump" if self.residual_s is None
                    else f"residual {self.residual_s:.3f} s")
        return f"offset {self.offset_s:.3f} s from the sync jump ({self.matched} matched, {residual})"


def root_height_m(motion: Motion) -> np.ndarray:
    """The root joint's height (m) per frame, 6 Hz zero-phase low-passed."""
    root = int(np.flatnonzero(np.asarray(motion.parents) < 0)[0])
    z = motion.positions_m[:, root, 2]
    if motion.fps <= 2 * CUTOFF_HZ or len(z) < 8:
        return z.copy()
    return filter_frames(z[:, None], butterworth_sos(CUTOFF_HZ, motion.fps), zero_phase=True)[:, 0]


def find_jumps(motion: Motion) -> np.ndarray:
    """Apex times (s from the clip's first frame) of the jumps in the root's vertical motion.

    Returns
    -------
    ndarray
        Sorted; empty when the clip has no flight.
    """
    z = root_height_m(motion)
    fps = motion.fps
    v = np.gradient(z) * fps
    a = np.gradient(v) * fps
    half = max(1, int(round(FREE_FALL_WINDOW_S * fps / 2)))
    apexes = []
    for k in range(1, len(z) - 1):
        if not (z[k] >= z[k - 1] and z[k] > z[k + 1]):
            continue
        low = _preceding_low(z, k)
        takeoff = v[low:k + 1].max() if k > low else 0.0
        falling = a[max(k - half, 0):k + half + 1].mean()
        if z[k] - z[low] >= MIN_JUMP_RISE_M and takeoff >= MIN_TAKEOFF_M_S and falling <= -FREE_FALL_FRACTION * _G:
            apexes.append(_refine_peak(z, k) / fps)
    return np.array(apexes)


def _preceding_low(z: np.ndarray, k: int) -> int:
    """Index of the lowest point between the previous peak (or the clip's start) and frame ``k``."""
    j = k - 1
    while j > 0 and not (z[j] >= z[j - 1] and z[j] > z[j + 1]):
        j -= 1
    return j + int(np.argmin(z[j:k + 1]))


def _refine_peak(z: np.ndarray, k: int) -> float:
    """Sub-frame apex by a parabola through frames k-1, k, k+1."""
    den = z[k - 1] - 2 * z[k] + z[k + 1]
    return k + (0.5 * (z[k - 1] - z[k + 1]) / den if den < 0 else 0.0)


def align_by_sync(clip_jumps_s: np.ndarray, sync_s: np.ndarray, clip: str, events: str,
                  near_s: float | None = None) -> Alignment:
    """Match the clip's first jump to a logged sync jump (see the module docstring).

    Parameters
    ----------
    clip_jumps_s : ndarray
        Apex times in the clip (:func:`find_jumps`).
    sync_s : ndarray
        Session times of the ``sync,jump`` events.
    clip, events : str
        The clip and events.csv, for messages.
    near_s : float, optional
        Pair the clip's first jump with the sync event nearest this session time (``--sync T``).

    Raises
    ------
    AttachError
        No jump in the clip, no ``sync,jump`` event, or several events that fit equally well.
    """
    if len(clip_jumps_s) == 0:
        raise AttachError(f"{clip}: expected a jump (the root rising {MIN_JUMP_RISE_M} m or more in free fall) "
                          f"in the clip's vertical root motion to align with the sync event, found none; "
                          f"give --offset S instead")
    if len(sync_s) == 0:
        raise AttachError(f"{events}: expected a sync row labelled {SYNC_LABEL!r} (t_s,sync,{SYNC_LABEL},) "
                          f"to align the clip with, found none; give --offset S instead")
    firsts = sync_s if near_s is None else sync_s[[int(np.argmin(np.abs(sync_s - near_s)))]]
    scored = sorted((_score(clip_jumps_s, sync_s, float(e - clip_jumps_s[0])) for e in firsts), reverse=True)
    if len(scored) > 1 and scored[0][:2] == scored[1][:2]:
        tied = [f"{t:.3f}" for t in sorted(o + clip_jumps_s[0] for n, r, o in scored if (n, r) == scored[0][:2])]
        raise AttachError(f"{events}: expected one sync jump that fits the clip's jumps best, found {len(tied)} "
                          f"fitting equally (at {', '.join(tied)} s); give --sync T with the one to use")
    n, neg_rms, offset = scored[0]
    return Alignment(offset, "sync jump", n, -neg_rms if n > 1 else None)


def _score(clip_jumps_s: np.ndarray, sync_s: np.ndarray, offset_s: float) -> tuple[int, float, float]:
    """(jumps matched, -RMS of their differences, offset) of one candidate offset."""
    diffs = [_nearest(sync_s, j + offset_s) for j in clip_jumps_s]
    matched = [d for d in diffs if abs(d) <= MATCH_TOLERANCE_S]
    rms = math.sqrt(sum(d * d for d in matched) / len(matched))
    return len(matched), round(-rms, 9), offset_s


def _nearest(times: np.ndarray, t: float) -> float:
    """Signed difference from ``t`` to the nearest of ``times``."""
    i = int(np.argmin(np.abs(times - t)))
    return float(times[i] - t)


def attach_clip(session: str | os.PathLike, clip: str | os.PathLike, *, offset_s: float | None = None,
                sync: bool = False, sync_near_s: float | None = None,
                mapping: str | os.PathLike | None = None, unit_m: float | None = None, up: str | None = None,
                trust_skeleton: bool = False) -> Alignment:
    """Copy ``clip`` (with a joint-positions CSV's ``<stem>.skeleton.json``, its tree) into
    ``session/motion/`` and record its alignment in ``motion.json``.

    Parameters
    ----------
    session : path-like
        The session folder.
    clip : path-like
        A BVH, C3D, joint-positions CSV or npz clip (read and checked before anything is written).
    offset_s : float, optional
        Session time of the clip's first frame.
    sync : bool
        Align by the sync jump instead (exactly one of ``offset_s`` and ``sync``).
    sync_near_s : float, optional
        With ``sync``: use the sync event nearest this session time (when several fit equally).
    mapping : path-like, optional
        A joint-to-segment mapping file (partial ones are filled by the built-in conventions):
        kept in the clip's motion.json entry (``"mapping"``, version 2), so ``effortface work`` uses it.
    unit_m, up : optional
        The clip's length unit (m) and up axis (``--unit-m``, ``--up``; None: the file's own), used
        to read it here and kept in its entry for ``effortface work``.
    trust_skeleton : bool
        Attach a body outside the plausibility gate's human ranges (kept in the entry).

    Returns
    -------
    Alignment

    Raises
    ------
    AttachError
        Unknown format, a clip (or a joint-positions CSV's skeleton file, which is copied with it) of
        that name already in motion/ (never overwritten), a non-finite
        offset, or a sync jump that cannot be found or is ambiguous; nothing is written then.
    UserError
        A clip that cannot be read, whose joints cannot be mapped to the 14 segments (the clip and
        the mapping file named), or outside the plausibility gate: nothing is copied, motion.json
        is unchanged.
    """
    s = read_session(session)
    clip = Path(clip)
    if clip.suffix.lower() not in CLIP_FORMATS:
        raise AttachError(f"{clip}: expected a clip ending in {', '.join(CLIP_FORMATS)}, found {clip.suffix!r}")
    if (offset_s is None) == (not sync):
        raise AttachError("--offset / --sync: expected exactly one of the two, found "
                          + ("both" if sync else "neither"))
    motion = read_clip(clip, unit_m=unit_m, up=up)
    segments = _checked_mapping(motion, clip, mapping)
    check_plausible_clip(motion, trust_skeleton, _read_mapping(mapping))
    folder = s.path / MOTION_DIR
    target = folder / clip.name
    if target.exists():
        raise AttachError(f"{target}: expected a new clip name in motion/, found one (not overwritten)")
    companions = _companions(clip, folder)
    if sync:
        events = np.array([e.t_s for e in s.events if e.kind == "sync" and e.label == SYNC_LABEL])
        alignment = align_by_sync(find_jumps(motion), events, str(clip), str(s.path / "events.csv"), sync_near_s)
    else:
        if not math.isfinite(offset_s):  # type: ignore[arg-type]
            raise AttachError(f"--offset: expected a finite number of seconds, found {offset_s}")
        alignment = Alignment(float(offset_s), "offset")  # type: ignore[arg-type]
    entries = read_motion_index(folder / MOTION_JSON) if (folder / MOTION_JSON).exists() else []
    entries.append(_entry(clip, motion, alignment))
    read_as = {"unit_m": unit_m, "up": up, "mapping": segments, "trust_skeleton": trust_skeleton or None}
    entries[-1].update({k: v for k, v in read_as.items() if v is not None})
    folder.mkdir(exist_ok=True)
    copied: list[Path] = []
    try:
        for source, copy in [*companions, (clip, target)]:
            shutil.copyfile(source, copy)
            copied.append(copy)
        write_json_atomic(folder / MOTION_JSON, {"version": MOTION_JSON_VERSION, "files": entries})
    except BaseException:
        for copy in copied:
            copy.unlink(missing_ok=True)
        raise
    return alignment


def _companions(clip: Path, folder: Path) -> list[tuple[Path, Path]]:
    """The files the clip is read with that travel with it into ``folder``: a joint-positions CSV's
    skeleton file (``<stem>.skeleton.json``, its tree); AttachError if one of that name is there."""
    from effortface.synth.motion_csv import skeleton_beside

    skeleton = skeleton_beside(clip)
    if clip.suffix.lower() != ".csv" or not skeleton.is_file():
        return []
    target = folder / skeleton.name
    if target.exists():
        raise AttachError(f"{target}: expected a new skeleton file name in motion/ for {clip.name}, found one "
                          f"(not overwritten)")
    return [(skeleton, target)]


def _read_mapping(mapping: str | os.PathLike | None) -> dict | None:
    """The ``--mapping`` file read (None: the built-in conventions)."""
    from effortface.synth.segments import read_mapping

    return read_mapping(Path(mapping)) if mapping is not None else None


def _checked_mapping(motion: Motion, clip: Path, mapping: str | os.PathLike | None) -> dict | None:
    """Map the clip's joints (the mapping file filling or overriding the built-in conventions) or raise
    a UserError naming the clip and the mapping file; the file's JSON form (version 2) for motion.json."""
    from effortface.synth.segments import build_body, mapping_to_json, read_mapping

    segments = read_mapping(Path(mapping)) if mapping is not None else None
    build_body(motion.joint_names, motion.parents, 70.0, "male", mapping=Path(mapping) if mapping else None,
               source=clip)
    return mapping_to_json(segments) if segments is not None else None


def _entry(clip: Path, motion: Motion, alignment: Alignment) -> dict:
    """The motion.json entry of an attached clip."""
    entry = {"path": clip.name, "offset_s": round(alignment.offset_s, 4),
             "format": CLIP_FORMATS[clip.suffix.lower()], "aligned": alignment.method,
             "duration_s": round(motion.n_frames / motion.fps, 3)}
    if alignment.method == "sync jump":
        entry["sync"] = {"matched": alignment.matched, "residual_s": alignment.residual_s}
    return entry
