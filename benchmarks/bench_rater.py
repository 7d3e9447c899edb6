"""The machine rater's speed in frames per second at 640 x 480, against MediaPipe's own Python API.

The frames are the real-face clip of the tests (tests/annotate/face_clip.py: three public-domain
photographs framed with pan and zoom, and stretches with no face), decoded once into memory so that
only the rating is timed. Both run in VIDEO mode (one face, tracked from frame to frame) in this
process on the same frames, alternately, the fastest of ``--repeat`` runs kept:

- ``ours``: :class:`effortface.annotate.machine.landmarker.FaceLandmarker` (ai-edge-litert), with
  ``--threads`` interpreter threads (``effortface preannotate`` uses the machine's cores for one session,
  one thread per session with ``--workers``);
- ``mediapipe``: ``mediapipe.tasks.python.vision.FaceLandmarker`` (the baseline; skipped, saying so,
  where ``mediapipe`` cannot be imported).

Real time is 30 frames per second. Run: ``python benchmarks/bench_rater.py [--repeat 3] [--threads 1 2]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from effortface.annotate.machine.landmarker import DEFAULT_MODEL, FaceLandmarker  # noqa: E402
from tests.annotate import face_clip  # noqa: E402

REAL_TIME_FPS = 30.0


def _frames() -> list[np.ndarray]:
    import cv2

    return [np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)) for bgr, _ in face_clip.frames()]


def _ours(frames: list[np.ndarray], threads: int) -> float:
    landmarker = FaceLandmarker(num_threads=threads)
    landmarker.process(frames[0])  # warm up
    landmarker.reset()
    start = time.perf_counter()
    for rgb in frames:
        landmarker.process(rgb)
    return len(frames) / (time.perf_counter() - start)


def _mediapipe(frames: list[np.ndarray]) -> float | None:
    try:
        import mediapipe as mp
        from mediapipe.tasks.python import BaseOptions, vision
    except Exception as exc:  # ImportError or a missing native library
        print(f"mediapipe: not importable here ({exc}); no baseline")
        return None
    options = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(DEFAULT_MODEL)),
                                           running_mode=vision.RunningMode.VIDEO, output_face_blendshapes=True,
                                           num_faces=1)
    landmarker = vision.FaceLandmarker.create_from_options(options)
    images = [mp.Image(image_format=mp.ImageFormat.SRGB, data=rgb) for rgb in frames]
    try:
        landmarker.detect_for_video(images[0], 0)  # warm up
        start = time.perf_counter()
        for i, image in enumerate(images, start=1):
            landmarker.detect_for_video(image, i * 33)
        return len(frames) / (time.perf_counter() - start)
    finally:
        landmarker.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs of each, the fastest kept (default 3)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="interpreter threads of ours")
    args = parser.parse_args()
    frames = _frames()
    print(f"{len(frames)} frames of {frames[0].shape[1]}x{frames[0].shape[0]} (real faces, with stretches of no face)")
    best: dict[str, float] = {}
    for _ in range(args.repeat):
        for threads in args.threads:
            key = f"ours ({threads} thread{'s' if threads > 1 else ''})"
            best[key] = max(best.get(key, 0.0), _ours(frames, threads))
        baseline = _mediapipe(frames)
        if baseline is not None:
            best["mediapipe (VIDEO mode)"] = max(best.get("mediapipe (VIDEO mode)", 0.0), baseline)
    reference = best.get("mediapipe (VIDEO mode)")
    for name, fps in best.items():
        ratio = f"  x{fps / reference:.2f} of mediapipe" if reference else ""
        print(f"{name:<24} {fps:7.1f} frames/s  x{fps / REAL_TIME_FPS:.2f} of real time (30 fps){ratio}")


if __name__ == "__main__":
    main()
