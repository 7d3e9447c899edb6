"""Three simulated annotators: key-frames that approximate the truth with designed errors, and
blind ratings of the shared pose set.

Each rater has a per-blendshape bias, a drift of that bias through a session (tiredness, a shifting
internal scale: ``drift_per_10min`` added per 10 minutes of session time), a noise level, a typical key spacing, a reaction lag and a
favourite interpolation, as people do. Keys sit at roughly regular spacing plus the truth's turning
points (annotators key the extremes they see); a key's weight is the truth ``lag_s`` earlier, plus
bias, drift and noise, rounded to the slider's 0.01 and clipped to [0, 1].
"""

from __future__ import annotations

import dataclasses

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET
from effortface.annotate.keyframes import KeyframeTrack, RaterAnnotations
from effortface.annotate.reliability import Pose, Rating


#: the longest session of the lab (s), for the designed error bound
MAX_SESSION_S = 720.0


@dataclasses.dataclass(frozen=True)
class RaterDesign:
    """One annotator's designed errors (recorded in the ground truth)."""

    rater: str
    bias: tuple[float, float, float, float]
    noise_sd: float
    key_spacing_s: float
    lag_s: float
    interp: str
    pose_noise_sd: float
    drift_per_10min: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def designed_mae(self, duration_s: float = MAX_SESSION_S) -> tuple[float, ...]:
        """Per blendshape, the largest mean absolute error of a track against the truth.

        ``|bias| + |drift| duration / 10 min`` (the bias at the session's end) ``+ 0.8 noise_sd``
        (a key's own error; E|N(0, s)| = 0.8 s) ``+ 0.04`` for what interpolation between keys
        cannot follow (breathing, expirations, repetition strain) (choice, checked on the generated
        lab by tests/samplelab/test_sample_sessions.py).
        """
        return tuple(round(abs(b) + abs(d) * duration_s / 600.0 + 0.8 * self.noise_sd + 0.04, 4)
                     for b, d in zip(self.bias, self.drift_per_10min))


RATERS = (
    RaterDesign("R1", (0.03, 0.02, 0.04, 0.03), 0.035, 2.5, 0.25, "smooth", 0.09, (0.04, 0.02, 0.04, 0.03)),
    RaterDesign("R2", (-0.04, -0.03, -0.02, -0.04), 0.045, 4.0, 0.6, "linear", 0.10, (-0.03, 0.04, -0.04, 0.0)),
    RaterDesign("R3", (0.01, 0.04, -0.03, 0.0), 0.05, 5.0, 0.4, "linear", 0.105, (0.0, -0.04, 0.03, 0.04)),
)


def _turning_points(y: np.ndarray, min_gap: int, prominence: float = 0.06) -> list[int]:
    """Local extrema of a smoothed ``y``, ``min_gap`` samples and ``prominence`` apart (what a
    person notices: breath-by-breath wiggles are smoothed away)."""
    k = max(3, min_gap) | 1
    ys = np.convolve(np.pad(y, k // 2, mode="edge"), np.ones(k) / k, mode="valid")
    d = np.sign(np.diff(ys))
    out: list[int] = []
    for i in np.flatnonzero(d[1:] * d[:-1] < 0) + 1:
        if not out or (i - out[-1] >= min_gap and abs(ys[i] - ys[out[-1]]) >= prominence):
            out.append(int(i))
    return out


def key_frames(frame_t_s: np.ndarray, truth: np.ndarray, design: RaterDesign,
               rng: np.random.Generator) -> list[int]:
    """Frames this rater keys for one blendshape: jittered regular spacing plus turning points."""
    n = frame_t_s.size
    fps = (n - 1) / (frame_t_s[-1] - frame_t_s[0])
    step = design.key_spacing_s * fps
    regular = np.cumsum(step * rng.uniform(0.7, 1.3, int(n / step) + 2))
    frames = {0, n - 1} | {int(f) for f in regular if f < n - 1}
    frames |= set(_turning_points(truth, int(step / 2)))
    return sorted(frames)


def annotate(session_id: str, frame_t_s: np.ndarray, truth: np.ndarray, design: RaterDesign,
             rng: np.random.Generator) -> RaterAnnotations:
    """One rater's key-frames for a session (truth: ``(n_frames, 4)`` true weights)."""
    ann = RaterAnnotations(design.rater, session_id, DEFAULT_SET)
    for j, name in enumerate(DEFAULT_SET.names):
        frames = key_frames(frame_t_s, truth[:, j], design, rng)
        seen = np.interp(frame_t_s[frames] - design.lag_s, frame_t_s, truth[:, j])
        bias = design.bias[j] + design.drift_per_10min[j] * frame_t_s[frames] / 600.0
        weights = np.clip(np.round(seen + bias + rng.normal(0, design.noise_sd, len(frames)), 2), 0, 1)
        track = KeyframeTrack()
        for f, w in zip(frames, weights):
            interp = "hold" if design.interp == "linear" and w == 0.0 else design.interp
            track.add(int(f), float(w), interp)
        ann.tracks[name] = track
    return ann


def choose_poses(session_id: str, frame_t_s: np.ndarray, nhr_at_frames: np.ndarray,
                 truth: np.ndarray, first_id: int) -> list[Pose]:
    """Three representative frames of a session: peak HR, peak expression elsewhere, calm."""
    n = frame_t_s.size
    margin = int(0.05 * n)
    picks = [int(np.argmax(nhr_at_frames[margin:-margin])) + margin]
    total = truth.sum(axis=1)
    far = np.abs(np.arange(n) - picks[0]) > 0.15 * n
    picks.append(int(np.argmax(np.where(far, total, -1.0))))
    calm = np.abs(np.arange(n)[:, None] - np.array(picks)[None, :]).min(axis=1) > 0.1 * n
    calm &= np.arange(n) > margin
    picks.append(int(np.argmin(np.where(calm, total + 0.2 * nhr_at_frames, np.inf))))
    return [Pose(f"pose{first_id + i:02d}", session_id, f, round(float(frame_t_s[f]), 4))
            for i, f in enumerate(picks)]


def rate_poses(poses: list[Pose], truth_by_pose: dict[str, np.ndarray], rng: np.random.Generator,
               ) -> list[Rating]:
    """Every rater rates every pose blind: truth + the rater's bias + pose noise, on the 0.01 slider."""
    out = []
    for design in RATERS:
        for pose in poses:
            true_w = truth_by_pose[pose.pose_id]
            for j, name in enumerate(DEFAULT_SET.names):
                w = true_w[j] + design.bias[j] + rng.normal(0.0, design.pose_noise_sd)
                out.append(Rating(pose.pose_id, design.rater, name, float(np.clip(round(w, 2), 0, 1))))
    return out
