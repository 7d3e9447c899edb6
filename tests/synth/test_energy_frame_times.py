"""Live work that does not depend on the game's frame times (SCIENCE_NOTES "Live work on a fixed internal tick").

A game's frames come at 30, 60 or 120 fps with jitter; the stream resamples them to a fixed tick
(the parabola through the last three frames) and runs its filter at that tick. References here are
written apart from the code: a rigid body gliding at a steady speed or falling freely does no work
(its total energy per segment is constant), and the same clip streamed at steady frame times.

The AMP clips hold every pose for two frames (60 fps files of 30 fps motion): the clips are played
from their distinct poses only, at their true 30 Hz, through a cubic spline, so that a stream at any
frame time sees the motion itself and not the file's steps.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from effortface.synth.energy import G_M_PER_S2, EnergyCrowd, EnergyStream, work_and_power
from effortface.synth.motion import Motion, motion_from_positions, read_motion
from effortface.synth.segments import BodyModel, build_body

JITTER = 0.3
CLIPS = ["amp_humanoid_walk.npz", "amp_humanoid_run.npz", "cmu_13_29_jumping_jacks_120fps.bvh"]


def _rod_body(mass_kg: float = 70.0) -> BodyModel:
    """One rigid segment from joint 0 to joint 1, CM at mid-length."""
    return BodyModel(
        segment_names=("rod",), mass_kg=mass_kg, segment_mass_kg=np.array([mass_kg]),
        length_m=np.array([0.4]), com_frac=np.array([0.5]), radii=np.array([(0.3, 0.25, 0.1)]),
        proximal_weights=np.array([[1.0, 0.0]]), distal_weights=np.array([[0.0, 1.0]]),
        frame_joint=np.array([0]), hip_joints=(0, 1), load_kg=np.zeros(1),
    )


def frame_times(fps: float, jitter: float, duration_s: float, seed: int = 28) -> tuple[np.ndarray, np.ndarray]:
    """Frame times t_s from 0 and each frame's dt_s, the nominal 1 / fps times 1 +- ``jitter`` (uniform)."""
    rng = np.random.default_rng(seed)
    dt_s = (1.0 + rng.uniform(-jitter, jitter, int(duration_s * fps * 1.5) + 2)) / fps
    t_s = np.concatenate([[0.0], np.cumsum(dt_s[1:])])
    keep = t_s <= duration_s
    return t_s[keep], dt_s[keep]


def streamed_w(stream: EnergyStream, positions_at: Callable[[np.ndarray], np.ndarray],
               t_s: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """w (W/kg) returned by each step of ``stream`` fed the positions at ``t_s``."""
    pos = positions_at(t_s)
    return np.array([stream.step(pos[k], dt_s[k])[0] for k in range(t_s.size)])


def _rod(com_m: np.ndarray) -> np.ndarray:
    half = np.array([0.0, 0.2, 0.0])
    return np.stack([com_m - half, com_m + half], axis=1)


def glide(t_s: np.ndarray) -> np.ndarray:
    """A rod gliding at 3.4 m/s along x at 1 m height."""
    com = np.zeros((t_s.size, 3))
    com[:, 0], com[:, 2] = 3.4 * t_s, 1.0
    return _rod(com)


def free_fall(t_s: np.ndarray) -> np.ndarray:
    """A rod falling freely from 30 m."""
    com = np.zeros((t_s.size, 3))
    com[:, 2] = 30.0 - 0.5 * G_M_PER_S2 * t_s**2
    return _rod(com)


@pytest.mark.parametrize("motion_fn", [glide, free_fall], ids=["glide 3.4 m/s", "free fall"])
@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
@pytest.mark.parametrize("tick", ["skeleton 60 Hz", "game rate"])
def test_glide_and_free_fall_do_no_work_with_jittering_frames(motion_fn: Callable[[np.ndarray], np.ndarray],
                                                              fps: float, tick: str) -> None:
    """Before the tick resampler (filter re-tuned from each frame's dt) the glide read 16.3 / 3.9 /
    1.0 W/kg at 30 / 60 / 120 fps with +-30 % jitter, the 30 m fall hundreds of W/kg."""
    t_s, dt_s = frame_times(fps, JITTER, 2.5)
    stream = EnergyStream(_rod_body(), 60.0 if tick == "skeleton 60 Hz" else fps)
    w = streamed_w(stream, motion_fn, t_s, dt_s)
    settled = t_s >= 1.5  # the filter starts at rest: the first second holds its start-up
    print(f"{motion_fn.__name__} {fps:g} fps +-30 % ({tick}): largest w {w[settled].max():.2e} W/kg")
    assert w[settled].max() < 0.01  # the issue asks < 0.1 W/kg


def test_a_crowd_is_resampled_like_each_character() -> None:
    """Two characters in one crowd, jittering frames: each gets its own stream's numbers."""
    t_s, dt_s = frame_times(30.0, JITTER, 2.0)
    crowd = EnergyCrowd([_rod_body(60.0), _rod_body(80.0)], 60.0)
    bob = _rod(np.column_stack([np.zeros_like(t_s), np.zeros_like(t_s), 1.0 + 0.05 * np.sin(4 * np.pi * t_s)]))
    pos = np.stack([glide(t_s), bob], axis=1)
    together = np.array([crowd.step(pos[k], dt_s[k])[0] for k in range(t_s.size)])
    for i, mass in enumerate((60.0, 80.0)):
        alone = streamed_w(EnergyStream(_rod_body(mass), 60.0), lambda t, i=i: pos[:, i], t_s, dt_s)
        np.testing.assert_allclose(together[:, i], alone, rtol=1e-12, atol=1e-12)
    assert together[-1, 1] > 1.0  # the bobbing one works


def test_a_hitch_and_tiny_frames_keep_the_glide_still() -> None:
    """A 0.2 s hitch and frames a tenth as long as the next: still no false work on a glide."""
    dt_s = np.r_[np.full(60, 1 / 60), 0.2, np.tile([0.0015, 1 / 60], 40), np.full(60, 1 / 60)]
    t_s = np.concatenate([[0.0], np.cumsum(dt_s[1:])])
    w = streamed_w(EnergyStream(_rod_body(), 60.0), glide, t_s, dt_s)
    assert w[t_s >= 1.5].max() < 0.01


def distinct_poses(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Times and positions of the clip's distinct poses: every other frame when each pose is held twice."""
    pos = motion.positions_m
    n_pairs = motion.n_frames // 2
    held = n_pairs > 0 and bool(np.all(np.abs(pos[1:2 * n_pairs:2] - pos[0:2 * n_pairs:2]) < 1e-9))
    idx = np.arange(0, motion.n_frames, 2) if held else np.arange(motion.n_frames)
    return idx / motion.fps, pos[idx]


@pytest.fixture(scope="module")
def clip_streams(shared_data: Path) -> dict[str, dict[str, float]]:
    """Mean w after 1 s of each clip: streamed steady at 60 fps, at 30 / 60 fps +-30 %, and offline."""
    out: dict[str, dict[str, float]] = {}
    for name in CLIPS:
        motion = read_motion(shared_data / "motion" / name)
        t_pose, pose = distinct_poses(motion)
        spline = CubicSpline(t_pose, pose, axis=0)
        end_s = float(t_pose[-1])
        body = build_body(motion.joint_names, motion.parents, 70.0, "female",
                          reference_positions_m=motion.positions_m)
        figures: dict[str, float] = {}
        for label, fps, jitter in (("steady 60", 60.0, 0.0), ("30 +-30%", 30.0, JITTER),
                                   ("60 +-30%", 60.0, JITTER)):
            t_s, dt_s = frame_times(fps, jitter, end_s)
            w = streamed_w(EnergyStream(body, 60.0), spline, t_s, dt_s)
            figures[label] = float(np.average(w[t_s >= 1.0], weights=dt_s[t_s >= 1.0]))
        t60 = np.arange(int(end_s * 60) + 1) / 60.0
        resampled = motion_from_positions(spline(t60), motion.joint_names, motion.parents, 60.0)
        for label, zero_phase in (("offline causal", False), ("offline zero-phase", True)):
            w = work_and_power(resampled, body, zero_phase=zero_phase, use_rotations=False).w_per_kg
            span = (t60 >= 1.0) & (t60 <= (end_s if not zero_phase else end_s - 0.2))
            figures[label] = float(w[span].mean())
        print(name, {k: round(v, 3) for k, v in figures.items()})
        out[name] = figures
    return out


@pytest.mark.parametrize("clip", CLIPS)
@pytest.mark.parametrize("label", ["30 +-30%", "60 +-30%", "offline causal"])
def test_real_clip_streamed_with_jitter_within_5_percent_of_steady(clip_streams: dict[str, dict[str, float]],
                                                                    clip: str, label: str) -> None:
    """Walk, run, jumping jacks at 30 and 60 fps +-30 %: within 5 % of the steady 60 fps stream.

    Before: the walk at 30 fps +-30 % gave 1.40x the steady stream, the run 1.09x.
    """
    figures = clip_streams[clip]
    assert figures[label] == pytest.approx(figures["steady 60"], rel=0.05)


@pytest.mark.parametrize("clip", ["amp_humanoid_walk.npz", "cmu_13_29_jumping_jacks_120fps.bvh"])
def test_real_clip_streamed_with_jitter_near_the_zero_phase_file_path(
        clip_streams: dict[str, dict[str, float]], clip: str) -> None:
    """Against the zero-phase file path: within 10 %. The causal filter passes |H| where the
    forward-backward one passes |H|^2, so the stream keeps a little more of the 4-6 Hz content
    of a walk (about 7 % more work on this clip, with or without jitter)."""
    figures = clip_streams[clip]
    for label in ("30 +-30%", "60 +-30%"):
        assert figures[label] == pytest.approx(figures["offline zero-phase"], rel=0.10), label
