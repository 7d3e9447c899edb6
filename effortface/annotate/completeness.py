"""When is a rater's track of one blendshape finished? The rule training uses (Qt-free).

A half-finished track (two keys, then the rater stopped) evaluates to a constant over the whole
session; averaged into the raters' mean it would teach the model a made-up flat curve. So a track
counts only when it is **complete**:

1. it has a key within :data:`MAX_KEY_GAP_S` of the first video frame and one within
   :data:`MAX_KEY_GAP_S` of the last (the keys cover the annotated span, the whole video);
2. no two consecutive keys are more than :data:`MAX_KEY_GAP_S` apart in session time;
3. the rater finished a pass over the video on that blendshape (the Annotate stage marks it when
   the rater reaches the last frame with keys on the track; it is saved as ``passes_done`` in
   ``annotations/<rater>.json``). Files written before ``passes_done`` existed do not record
   passes; for them rules 1 and 2 decide.

The Annotate stage shows each rater's completeness per blendshape in its session list, the Train
stage in its session table, and training (:mod:`effortface.train.dataset`) leaves incomplete tracks
out of every rater policy (``mean`` and a named rater); the model card states the rule.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from effortface.annotate.keyframes import KeyframeTrack, RaterAnnotations, read_annotations

#: longest stretch of session time without a key (and from the video's ends to the nearest key)
#: that a complete track may have, in seconds (choice: the sample raters key every 2.5-6.5 s)
MAX_KEY_GAP_S = 30.0
#: the rule in one line, for the guide, the status lines and the model card
RULE_TEXT = (f"a track is complete when its keys cover the video with no gap over {MAX_KEY_GAP_S:g} s "
             "(first and last keys within that of the video's ends) and the rater finished the pass "
             "(files without passes_done: coverage only); incomplete tracks are left out of training")


@dataclasses.dataclass(frozen=True)
class TrackStatus:
    """Completeness of one track: ``complete`` and, when not, ``reason`` (one short phrase)."""

    complete: bool
    reason: str = ""


def track_status(track: KeyframeTrack, frame_times_s: Sequence[float] | np.ndarray,
                 pass_done: bool | None) -> TrackStatus:
    """Apply the completeness rule (module docstring) to one track.

    Parameters
    ----------
    track : KeyframeTrack
        The rater's keys of one blendshape.
    frame_times_s : sequence of float
        Session time of every video frame (``video_frames.csv``).
    pass_done : bool or None
        Whether the rater finished a pass on this blendshape; None when the file does not say.

    Returns
    -------
    TrackStatus
    """
    if len(track) == 0:
        return TrackStatus(False, "no keys")
    t_s = np.asarray(frame_times_s, dtype=float)
    frames, _, _ = track.arrays()
    key_t_s = t_s[np.clip(frames, 0, len(t_s) - 1)]
    edges_t_s = np.concatenate(([t_s[0]], key_t_s, [t_s[-1]]))
    gaps_s = np.diff(edges_t_s)
    worst = int(np.argmax(gaps_s))
    if gaps_s[worst] > MAX_KEY_GAP_S:
        return TrackStatus(False, f"no key from {edges_t_s[worst]:.0f} s to {edges_t_s[worst + 1]:.0f} s")
    if pass_done is False:
        return TrackStatus(False, "pass not finished")
    return TrackStatus(True)


def rater_status(annotations: RaterAnnotations,
                 frame_times_s: Sequence[float] | np.ndarray) -> dict[str, TrackStatus]:
    """Completeness of each of a rater's tracks, in the set's order."""
    done = annotations.passes_done
    return {name: track_status(annotations.tracks[name], frame_times_s,
                               None if done is None else name in done)
            for name in annotations.blendshapes.names}


def session_status(session_folder: str | os.PathLike,
                   frame_times_s: Sequence[float] | np.ndarray) -> dict[str, dict[str, TrackStatus]]:
    """Every rater's completeness in ``<session>/annotations/*.json``: rater -> blendshape -> status.

    Raises
    ------
    AnnotationFormatError
        If an annotation file is malformed.
    """
    files = sorted((Path(session_folder) / "annotations").glob("*.json"))
    return {f.stem: rater_status(read_annotations(f), frame_times_s) for f in files}


def summary(status: dict[str, TrackStatus]) -> str:
    """``"4/4"`` style: complete tracks over tracks."""
    return f"{sum(s.complete for s in status.values())}/{len(status)}"
