"""Test data: machine tracks derived from a session's real key-frames (mean of its raters) plus noise
and stretches without a face, written through the machine-track API (not a model's output)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from effortface.annotate.keyframes import read_annotations
from effortface.annotate.machine.track import ARKIT_NAMES, FOUR, MachineTrack, write_machine_track
from effortface.core.session.folder import read_session

#: fraction of frames in each of the two stretches without a face
NO_FACE_FRACTION = 0.05


def fake_machine_track(session_dir: Path, *, noise: float = 0.05, seed: int = 0,
                       no_face: bool = True) -> MachineTrack:
    """A track of the raters' mean curves plus Gaussian noise (sd ``noise``), two no-face stretches."""
    session = read_session(session_dir)
    t_s = np.asarray(session.frame_times_s, dtype=float)
    n = t_s.size
    frames = np.arange(n)
    curves = [read_annotations(p).weights(frames) for p in sorted((Path(session_dir) / "annotations").glob("*.json"))]
    mean = np.nanmean(np.stack(curves), axis=0) if curves else np.full((n, len(FOUR)), 0.2)
    rng = np.random.default_rng(seed)
    weights = np.clip(np.nan_to_num(mean, nan=0.1) + rng.normal(0, noise, mean.shape), 0, 1)
    face = np.ones(n, bool)
    if no_face:
        k = max(1, int(NO_FACE_FRACTION * n))
        face[n // 5: n // 5 + k] = False
        face[(3 * n) // 5: (3 * n) // 5 + k] = False
    scores = np.full((n, len(ARKIT_NAMES)), 0.05)
    col = {name: i for i, name in enumerate(ARKIT_NAMES)}
    for j, names in enumerate((("mouthStretchLeft", "mouthStretchRight"), ("jawOpen",),
                               ("eyeSquintLeft", "eyeSquintRight"), ("browDownLeft", "browDownRight"))):
        for name in names:
            scores[:, col[name]] = weights[:, j]
    weights[~face] = np.nan
    scores[~face] = np.nan
    return MachineTrack(frames, t_s, face, weights, scores,
                        {"source": "test: raters' mean + noise", "noise_sd": noise, "seed": seed})


def write_fake_machine(session_dir: Path, **kwargs) -> Path:
    """Write :func:`fake_machine_track` into the session (refuses to replace one)."""
    return write_machine_track(Path(session_dir), fake_machine_track(session_dir, **kwargs))
