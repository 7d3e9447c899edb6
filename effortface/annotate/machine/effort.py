"""The effort mapping: MediaPipe's 52 scores -> our four blendshapes, each apart from its look-alikes.

The definition mapping of :mod:`effortface.annotate.machine.mapping` averages the ARKit scores a
blendshape's definition names. Measured on real talking faces that echoes MediaPipe where it
confuses effort with something else (docs/guide/machine-rater-effort-mapping.md). This mapping
(``effort v2``, the default since track format 2) takes the same scores and:

- **eye_squint is held across blinks.** A closure (``eyeBlink`` above the eyes' open level by
  :data:`CLOSED_RISE`, reaching :data:`CLOSED_MIN`) that lasts less than :data:`BLINK_MAX_S` is a
  blink: over it (and :data:`BLINK_PAD` frames each side, where MediaPipe's smoothing spreads the
  lids' movement) eye_squint is the straight line between the frames before and after. A closure held
  longer (squeezing the eyes shut, a held squint, a laugh's cheek raise) is kept as it is. The
  alternative, squint minus the lids' closure, would also remove the closure of a deliberate squint,
  which is part of what a rater keys.
- **mouth_stretch is the stretch a smile does not explain**: ``max(stretch - max(smile - smile0, 0), 0)``
  with ``stretch`` and ``smile`` the means of ``mouthStretchLeft/Right`` and ``mouthSmileLeft/Right``
  and ``smile0`` the smile of the neutral reference (0 without one). A smile pulls the lip corners up
  and out, which MediaPipe also scores as stretch; the grimace of exertion pulls them out and down.
  Only a smile *beyond the person's neutral* is taken off: a face that rests smiling (a smiling
  portrait, a participant's resting mouth) keeps the stretch its grimace adds.
- **baselines are removed by a neutral reference** where the session has one: the frames of its
  first ``rest`` phase (``events.csv``). Per blendshape the median there, ``b``, maps to 0 and the
  weight is ``clip((w - b) / (1 - b), 0, 1)``. Without a rest phase (or with fewer than
  :data:`MIN_NEUTRAL_FRAMES` face frames in it) nothing is removed, and the sidecar says so.

mouth_open (``jawOpen``) and brow_lower (``browDownLeft/Right``) keep their definition.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from effortface.annotate.machine.landmarker import ARKIT_NAMES
from effortface.annotate.machine.track import FOUR

#: the mapping's name in the sidecar
EFFORT_MAPPING = "effort v2"
#: a closure shorter than this (first to last closed frame) is a blink, held across
BLINK_MAX_S = 0.4
#: a frame is closed when eyeBlink exceeds the eyes' open level (median over the face frames) by this
CLOSED_RISE = 0.15
#: and a closure reaches at least this eyeBlink (or the open level + 2 x CLOSED_RISE, the higher)
CLOSED_MIN = 0.35
#: a blink's hold reaches out to the frames where eyeBlink is back within this of the open level
#: (MediaPipe's landmark smoothing spreads the lids' movement over the frames around a blink)
REOPEN_RISE = 0.05
#: and one frame more each side
BLINK_PAD = 1
#: a closure whose lids are not back within REOPEN_RISE of the open level within this span is part of
#: a longer narrowing of the eyes (a laugh, a held squint) and is kept
BLINK_SPAN_MAX_S = 1.0
#: the fewest face frames in the rest phase that make a neutral reference
MIN_NEUTRAL_FRAMES = 3
#: our four blendshapes, in the track's column order
NAMES = FOUR

_INDEX = {a: i for i, a in enumerate(ARKIT_NAMES)}


def _mean(scores: np.ndarray, *names: str) -> np.ndarray:
    return np.asarray(scores[:, [_INDEX[a] for a in names]].mean(axis=1), dtype=float)


def blinks(blink: np.ndarray, t_s: np.ndarray) -> list[tuple[int, int]]:
    """The frames to hold across blinks: inclusive ``(first, last)`` frame indices, one run per blink.

    A closure is a run of frames whose eyeBlink exceeds the open level (its median over the face
    frames) by :data:`CLOSED_RISE` and peaks at :data:`CLOSED_MIN` or more; it is a blink when it
    lasts less than :data:`BLINK_MAX_S` (first to last closed frame) and the lids are back within
    :data:`REOPEN_RISE` of the open level within :data:`BLINK_SPAN_MAX_S` (the run held: from the
    first to the last frame above that level).

    Parameters
    ----------
    blink : numpy.ndarray
        (n,) mean eyeBlink per frame, NaN where no face (a frame without a face ends a closure).
    t_s : numpy.ndarray
        (n,) frame times in seconds.
    """
    ok = np.isfinite(blink)
    if not ok.any():
        return []
    open_level = float(np.median(blink[ok]))
    value = np.nan_to_num(blink, nan=0.0)
    closed = ok & (value >= open_level + CLOSED_RISE)
    moving = ok & (value >= open_level + REOPEN_RISE)
    peak = max(CLOSED_MIN, open_level + 2 * CLOSED_RISE)
    out: list[tuple[int, int]] = []
    for first, last in _runs(closed):
        if np.nanmax(blink[first:last + 1]) < peak or t_s[last] - t_s[first] >= BLINK_MAX_S:
            continue
        while first > 0 and moving[first - 1]:
            first -= 1
        while last + 1 < len(blink) and moving[last + 1]:
            last += 1
        if t_s[last] - t_s[first] > BLINK_SPAN_MAX_S:
            continue
        if out and first <= out[-1][1] + 1:
            first = out.pop()[0]
        out.append((first, last))
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive ``(first, last)`` index runs of True."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


def hold_across(values: np.ndarray, runs: list[tuple[int, int]], pad: int = BLINK_PAD) -> np.ndarray:
    """``values`` with each run (widened by ``pad`` frames) replaced by the line between its neighbours.

    A run at an end of the track, or next to a frame without a face, holds the one neighbour it has;
    with neither it is left as it is.
    """
    out = np.asarray(values, dtype=float).copy()
    n = len(out)
    for first, last in runs:
        a, b = max(first - pad, 0), min(last + pad, n - 1)
        before = a - 1 if a > 0 and np.isfinite(values[a - 1]) else None
        after = b + 1 if b + 1 < n and np.isfinite(values[b + 1]) else None
        span = np.arange(a, b + 1)
        ends = [k for k in (before, after) if k is not None]
        if not ends:
            continue
        held = np.interp(span, ends, [values[k] for k in ends])
        face = np.isfinite(out[span])
        out[span[face]] = held[face]
    return out


def neutral_frames(session_dir: Path | None, t_s: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Frames of the session's first ``rest`` phase (a mask over ``t_s``) and a description; None without one."""
    if session_dir is None:
        return None, "none: no session"
    from effortface.core.errors import UserError
    from effortface.core.session.folder import read_events

    path = Path(session_dir) / "events.csv"
    if not path.is_file():
        return None, "none: no events.csv"
    try:
        events = read_events(path)
    except UserError:
        return None, "none: events.csv unreadable"
    phases = [e for e in events if e.kind in ("phase_start", "phase_end")]
    for k, event in enumerate(phases):
        if event.kind == "phase_start" and event.label == "rest":
            end = next((e.t_s for e in phases[k + 1:]), float(t_s[-1]) if len(t_s) else event.t_s)
            mask = (t_s >= event.t_s) & (t_s <= end)
            return mask, f"first rest phase, {event.t_s:.2f}-{end:.2f} s"
    return None, "none: no rest phase in events.csv"


def remove_baseline(weights: np.ndarray, baseline: np.ndarray) -> np.ndarray:
    """``clip((w - b) / (1 - b), 0, 1)`` per column (a baseline of 1 or more leaves the column 0)."""
    scale = np.where(baseline < 1.0, 1.0 - baseline, np.inf)
    return np.asarray(np.clip((weights - baseline) / scale, 0.0, 1.0), dtype=float)


def _neutral_rows(neutral: np.ndarray | None, face_values: np.ndarray) -> np.ndarray | None:
    """The neutral mask restricted to face frames; None when fewer than :data:`MIN_NEUTRAL_FRAMES`."""
    if neutral is None:
        return None
    rows = np.asarray(neutral, dtype=bool) & np.isfinite(face_values)
    return rows if rows.sum() >= MIN_NEUTRAL_FRAMES else None


def effort_weights(scores: np.ndarray, t_s: np.ndarray,
                   neutral: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """The effort mapping of (n, 52) scores: (n, 4) weights in :data:`NAMES` order and what was done.

    Parameters
    ----------
    scores : numpy.ndarray
        (n, 52) MediaPipe scores in ``ARKIT_NAMES`` order, NaN rows where no face.
    t_s : numpy.ndarray
        (n,) frame times in seconds.
    neutral : numpy.ndarray, optional
        (n,) bool mask of the neutral reference's frames (:func:`neutral_frames`).

    Returns
    -------
    weights : numpy.ndarray
        (n, 4), NaN where no face.
    report : dict
        ``blinks_held`` (count), ``blink_frames_held``, ``baseline`` (per blendshape, or None).
    """
    t_s = np.asarray(t_s, dtype=float)
    squint = _mean(scores, "eyeSquintLeft", "eyeSquintRight")
    runs = blinks(_mean(scores, "eyeBlinkLeft", "eyeBlinkRight"), t_s)
    smile = _mean(scores, "mouthSmileLeft", "mouthSmileRight")
    rest = _neutral_rows(neutral, smile)
    smile_rise = np.maximum(smile - (float(np.median(smile[rest])) if rest is not None else 0.0), 0.0)
    stretch = _mean(scores, "mouthStretchLeft", "mouthStretchRight") - smile_rise
    weights = np.column_stack([np.where(np.isnan(stretch), np.nan, np.maximum(stretch, 0.0)),
                               _mean(scores, "jawOpen"), hold_across(squint, runs),
                               _mean(scores, "browDownLeft", "browDownRight")])
    report: dict[str, Any] = {"blinks_held": len(runs),
                              "blink_frames_held": int(sum(b - a + 1 for a, b in runs)), "baseline": None}
    if rest is not None:
        baseline = np.median(weights[rest], axis=0)
        weights = remove_baseline(weights, baseline)
        report["baseline"] = {n: round(float(b), 4) for n, b in zip(NAMES, baseline)}
        report["neutral_smile"] = round(float(np.median(smile[rest])), 4)
        report["neutral_frames"] = int(rest.sum())
    return weights, report


def session_weights(session_dir: Path | None, scores: np.ndarray,
                    t_s: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """A session's effort-mapped weights (its first rest phase as the neutral reference) and the sidecar's record.

    Returns
    -------
    weights : numpy.ndarray
        (n, 4) in :data:`NAMES` order, NaN where no face.
    mapping : dict
        The sidecar's ``mapping`` object: ``kind``, the rules and their constants, the neutral
        reference used, the blinks held.
    """
    t_s = np.asarray(t_s, dtype=float)
    neutral, where = neutral_frames(session_dir, t_s)
    weights, report = effort_weights(scores, t_s, neutral)
    if report["baseline"] is None and neutral is not None:
        where = f"none: fewer than {MIN_NEUTRAL_FRAMES} face frames in the {where}"
    mapping = {
        "kind": EFFORT_MAPPING,
        "rule": "eye_squint held across blinks; mouth_stretch minus mouthSmile; baselines removed by a neutral "
                "reference (docs/guide/machine-rater-effort-mapping.md)",
        "blendshapes": {"mouth_stretch": "max(mean(mouthStretchLeft, mouthStretchRight) - max(mean(mouthSmileLeft, "
                                         "mouthSmileRight) - the neutral's, 0), 0)",
                        "mouth_open": "jawOpen",
                        "eye_squint": "mean(eyeSquintLeft, eyeSquintRight), held across blinks "
                                      "(mean(eyeBlinkLeft, eyeBlinkRight))",
                        "brow_lower": "mean(browDownLeft, browDownRight)"},
        "blink": {"max_s": BLINK_MAX_S, "closed_rise": CLOSED_RISE, "closed_min": CLOSED_MIN,
                  "reopen_rise": REOPEN_RISE, "pad_frames": BLINK_PAD, "span_max_s": BLINK_SPAN_MAX_S,
                  "held": report["blinks_held"], "frames_held": report["blink_frames_held"]},
        "neutral": {"reference": where,
                    "frames": report.get("neutral_frames", 0), "baseline": report["baseline"],
                    "smile": report.get("neutral_smile")},
    }
    return weights, mapping


__all__ = ["EFFORT_MAPPING", "BLINK_MAX_S", "blinks", "hold_across", "neutral_frames", "remove_baseline",
           "effort_weights", "session_weights"]
