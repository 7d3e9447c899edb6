"""The sample lab's faces are real faces a real face model reads as the weights intend (issue 23 item 6).

Runs MediaPipe's Face Landmarker (installed without its dependencies here; skipped where it or the
bundle ``../shared/models/face_landmarker.task`` is missing) on every 2nd frame of the committed
lab's sessions, through ``benchmarks/measure_sample_faces.py``: a face on at least 90 % of the frames
and, per blendshape, the raw ARKit scores following the human raters' mean with r >= 0.5.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "sample_sessions"
sys.path.insert(0, str(ROOT / "benchmarks"))

measure = pytest.importorskip("measure_sample_faces")
if importlib.util.find_spec("mediapipe") is None or not measure.DEFAULT_MODEL.is_file():
    pytest.skip("mediapipe or the Face Landmarker bundle is not here", allow_module_level=True)

SESSIONS = sorted(p for p in LAB.iterdir() if (p / "video.avi").is_file())


@pytest.fixture(scope="module")
def landmarker():
    detector = measure._landmarker(measure.DEFAULT_MODEL)
    yield detector
    detector.close()  # not left to the interpreter's exit, where MediaPipe's __del__ fails noisily


@pytest.mark.slow
@pytest.mark.parametrize("session", SESSIONS, ids=[s.name for s in SESSIONS])
def test_a_face_model_finds_the_face_and_follows_the_raters(session: Path, landmarker) -> None:
    frames, machine = measure.rate_video(session / "video.avi", landmarker, every=2)
    mean, _ = measure.human_mean(session, frames)
    found = np.isfinite(machine[:, 0]).mean()
    rs = [measure._r(machine[:, j], mean[:, j]) for j in range(4)]
    print(f"{session.name}: face {100 * found:.1f} %, r {np.round(rs, 2)}")
    assert found >= 0.9
    assert min(rs) >= 0.5, rs


def test_a_real_face_warped_open_scores_more_jaw_open_than_closed(landmarker) -> None:
    """Directions on single frames of every participant's face: the jaw drop raises jawOpen."""
    import mediapipe as mp

    from effortface.samplelab.simlab import facewarp

    for index in range(len(facewarp.FACE_NAMES)):
        face = facewarp.load_face(index)
        scores = []
        for weights in ([0.0, 0.0, 0.0, 0.0], [0.0, 0.7, 0.0, 0.0]):
            img = facewarp.render(face, np.array(weights), (200, 150), np.zeros(3), 1.0, np.random.default_rng(0))
            res = landmarker.detect(mp.Image(image_format=mp.ImageFormat.SRGB,
                                             data=np.ascontiguousarray(img[:, :, ::-1])))
            assert res.face_blendshapes, facewarp.FACE_NAMES[index]
            scores.append({c.category_name: c.score for c in res.face_blendshapes[0]}["jawOpen"])
        assert scores[1] > scores[0] + 0.1, (facewarp.FACE_NAMES[index], scores)
