"""The face video: a real face (a public-domain photograph warped by the true weights, see
:mod:`simlab.facewarp`), frame arrival times with real jitter, head motion, lighting, MJPG encoding.

A webcam never delivers its nominal rate exactly: here the camera runs 0.3 % slow, each frame's
arrival jitters by a few ms, and now and then a frame is late (USB hiccup, about 1 in 150) which
pushes the next ones back. Frame numbers therefore come from ``video_frames.csv``, never from
time x fps.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from effortface.samplelab.simlab import facewarp
from effortface.samplelab.simlab.avi import write_mjpg_avi

#: 200x150: the face model finds the warped faces and reads their lips (at 160x120 it read a dropped
#: jaw as closed); about 3 kB a frame with optimised Huffman tables, so the whole lab stays under 45 MB
WIDTH, HEIGHT, FPS = 200, 150, 1.5
JPEG_QUALITY = 30


def frame_times(duration_s: float, rng: np.random.Generator, fps: float = FPS) -> np.ndarray:
    """Arrival times (s) of the frames of a ``duration_s`` recording, strictly increasing."""
    period = 1.0 / (fps * 0.997)
    n = int(duration_s * fps * 0.997)
    late = np.cumsum(rng.random(n) < 1 / 150) * 0.5 * period  # each hiccup delays the rest
    t = 0.12 + np.arange(n) * period + late + rng.normal(0.0, 0.003, n)
    t = np.maximum.accumulate(t + np.arange(n) * 1e-6)
    return t[t < duration_s]


def head_motion(t_s: np.ndarray, work_w_per_kg: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(dx, dy, roll_deg)`` per frame: slow sway plus bobbing that grows with the work rate."""
    phase = rng.uniform(0, 2 * np.pi, 4)
    bob = np.clip(work_w_per_kg / 20.0, 0.0, 1.0)
    dx = 0.02 * np.sin(2 * np.pi * t_s / 7.3 + phase[0]) + 0.012 * bob * np.sin(2 * np.pi * 1.3 * t_s + phase[1])
    dy = 0.012 * np.sin(2 * np.pi * t_s / 5.1 + phase[2]) + 0.018 * bob * np.abs(np.sin(2 * np.pi * 1.3 * t_s))
    roll = 3.0 * np.sin(2 * np.pi * t_s / 9.7 + phase[3]) + 2.0 * bob * np.sin(2 * np.pi * 0.65 * t_s)
    return np.column_stack([dx, dy, roll])


def lighting(t_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Brightness per frame: slow drift (clouds, the lab's lights) plus small flicker."""
    drift = 0.06 * np.sin(2 * np.pi * t_s / 41.0 + rng.uniform(0, 2 * np.pi))
    return 1.0 + drift + rng.normal(0.0, 0.01, t_s.size)


def write_video(path: Path, weights: np.ndarray, poses: np.ndarray, light: np.ndarray,
                face_index: int, rng: np.random.Generator) -> int:
    """Warp participant ``face_index``'s photograph for every frame and write an MJPG ``.avi``;
    return the number of frames.

    Raises
    ------
    FileExistsError
        If ``path`` exists.
    """
    face = facewarp.load_face(face_index)
    frames = (facewarp.render(face, w, (WIDTH, HEIGHT), pose, float(lux), rng)
              for w, pose, lux in zip(weights, poses, light))
    return write_mjpg_avi(path, frames, FPS, JPEG_QUALITY)
