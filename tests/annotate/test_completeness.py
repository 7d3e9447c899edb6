"""The completeness rule: which rater tracks training may use (issue 16 item 7)."""

from __future__ import annotations

import numpy as np
import pytest

from effortface.annotate.completeness import MAX_KEY_GAP_S, rater_status, track_status
from effortface.annotate.keyframes import KeyframeTrack, RaterAnnotations

T_S = np.arange(0.0, 200.0, 0.1)  # 2000 frames at 10 Hz


def _keys(times_s) -> KeyframeTrack:
    track = KeyframeTrack()
    for t in times_s:
        track.add(int(round(t * 10)), 0.5)
    return track


@pytest.mark.parametrize("times_s, done, complete, reason", [
    ((), True, False, "no keys"),
    ((0.0, 5.0), True, False, "no key from 5 s to 200 s"),  # two keys, then the rater stopped
    (tuple(np.arange(0, 200, 10.0)), True, True, ""),
    (tuple(np.arange(0, 200, 10.0)), False, False, "pass not finished"),
    (tuple(np.arange(0, 200, 10.0)), None, True, ""),  # an older file: coverage decides
    ((*np.arange(0, 80, 10.0), *np.arange(80 + MAX_KEY_GAP_S + 1, 200, 10.0)), True, False, "no key from 70 s"),
    (tuple(np.arange(MAX_KEY_GAP_S + 1, 200, 10.0)), True, False, "no key from 0 s"),  # the start unkeyed
])
def test_rule(times_s, done, complete, reason) -> None:
    status = track_status(_keys(times_s), T_S, done)
    assert status.complete is complete and status.reason.startswith(reason)


def test_rater_status_reads_the_passes() -> None:
    full = _keys(np.arange(0, 200, 10.0))
    ann = RaterAnnotations("R1", "s", tracks={"mouth_stretch": full, "mouth_open": full.copy(),
                                              "eye_squint": _keys((0.0, 5.0))}, passes_done={"mouth_stretch"})
    got = {n: s.complete for n, s in rater_status(ann, T_S).items()}
    assert got == {"mouth_stretch": True, "mouth_open": False, "eye_squint": False, "brow_lower": False}
