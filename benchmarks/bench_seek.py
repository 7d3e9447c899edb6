"""Random seek to an exact frame, and frame stepping with the arrow key held, on a 640x480 MJPG video.

A 640 x 480 MJPG session video is generated (the parametric face at changing weights, sensor noise
and the frame number burnt in, through the project's own AVI writer), with a ``video_frames.csv``
of jittered 30 fps arrival times. Measured in one process:

- **random seek** (the target: median under 30 ms): ``VideoIndex.get(frame)`` on a cold cache at
  random frames, against two baselines: ``effortface.capture_tool.camera.read_frame`` (open the file, seek,
  decode: what a naive viewer does) and plain sequential decoding (the decoder's floor per frame);
- **stepping with the arrow key held**: the real Annotate stage (offscreen) receives a Right key
  every 33.3 ms (30 Hz key repeat); each step decodes (or takes from the cache), shows the frame and
  redraws the face preview. Reported: steps per second held, per-step latency (median, p95) and the
  share of steps that fit in one repeat interval, with prefetch on and with a one-frame cache (no
  prefetch benefit) for the ratio; plus the unthrottled maximum rate.

Run: ``python benchmarks/bench_seek.py [--frames 450] [--seeks 300] [--steps 150]``
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from effortface.annotate.face import render_face  # noqa: E402
from effortface.annotate.video_index import VideoIndex  # noqa: E402
from effortface.capture_tool.camera import open_avi_writer, read_frame  # noqa: E402
from effortface.core.session.folder import FrameTimeWriter, Participant, SessionInfo, create_session  # noqa: E402

SIZE = (640, 480)
FPS = 30.0


def make_session(out_dir: Path, n_frames: int, seed: int = 0) -> Path:
    """A session folder with a 640x480 MJPG video of ``n_frames`` and jittered 30 fps frame times."""
    import cv2

    rng = np.random.default_rng(seed)
    info = SessionInfo("B01_20260101-120000_bench", Participant("B01"), complete=True)
    folder = create_session(out_dir, info)
    writer = open_avi_writer(folder / "video.avi", FPS, SIZE)
    times = FrameTimeWriter(folder / "video_frames.csv")
    faces = [render_face(rng.uniform(0, 1, 4), SIZE) for _ in range(24)]
    t_s = 0.0
    for k in range(n_frames):
        image = cv2.add(faces[k % len(faces)], rng.integers(0, 12, (SIZE[1], SIZE[0], 3), dtype=np.uint8))
        cv2.putText(image, f"{k}", (20, 60), cv2.FONT_HERSHEY_SIMPLEX, 1.8, (255, 255, 255), 3)
        writer.write(image)
        times.write(k, t_s)
        t_s += 1.0 / FPS * (1.003 + rng.normal(0, 0.02))
    writer.release()
    times.close()
    return folder


def _stats_ms(seconds: list[float]) -> tuple[float, float]:
    a = np.asarray(seconds) * 1e3
    return float(np.median(a)), float(np.percentile(a, 95))


def bench_random_seek(folder: Path, n_seeks: int) -> dict[str, tuple[float, float]]:
    """Median and p95 latency (ms) of random exact seeks, VideoIndex vs baselines."""
    import cv2

    from effortface.core.session.folder import read_video_frames

    video_path = folder / "video.avi"
    frame_times = read_video_frames(folder / "video_frames.csv")
    targets = np.random.default_rng(1).integers(0, len(frame_times), n_seeks)
    out: dict[str, tuple[float, float]] = {}
    with VideoIndex(video_path, frame_times, cache_frames=1, prefetch=False) as video:
        lat = []
        for f in targets:
            t0 = time.perf_counter()
            video.get(int(f), prefetch=False)
            lat.append(time.perf_counter() - t0)
        out["VideoIndex.get (cold cache)"] = _stats_ms(lat)
    lat = []
    for f in targets[: max(20, n_seeks // 5)]:
        t0 = time.perf_counter()
        read_frame(video_path, int(f))
        lat.append(time.perf_counter() - t0)
    out["read_frame (open + seek + decode)"] = _stats_ms(lat)
    cap = cv2.VideoCapture(str(video_path), cv2.CAP_OPENCV_MJPEG)
    lat = []
    for _ in range(len(frame_times)):
        t0 = time.perf_counter()
        cap.read()
        lat.append(time.perf_counter() - t0)
    cap.release()
    out["sequential decode (floor)"] = _stats_ms(lat)
    return out


def bench_stepping(folder: Path, n_steps: int, cache_frames: int, rate_hz: float | None) -> dict[str, float]:
    """Hold Right on the real stage: steps/s held, per-step latency, share within one repeat interval."""
    from PySide6 import QtCore, QtWidgets
    from PySide6.QtTest import QTest

    from effortface.annotate.gui.annotate_stage import QtAnnotateStage

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([])
    stage = QtAnnotateStage(folder.parent, cache_frames=cache_frames)
    stage.resize(1400, 900)
    stage.show()
    stage.activateWindow()
    QTest.qWaitForWindowActive(stage)
    editor = stage.open_session(folder, "BENCH")
    view, session = editor.video_view, editor.session
    if cache_frames <= 1:
        editor.video.prefetch_ahead = editor.video.prefetch_behind = 0
    view.setFocus()
    app.processEvents()
    period = 1.0 / rate_hz if rate_hz else 0.0
    lat: list[float] = []
    start = time.perf_counter()
    for i in range(n_steps):
        due = start + i * period
        time.sleep(max(0.0, due - time.perf_counter()))
        app.processEvents()  # the event loop runs between repeats (repaints, timers)
        t0 = time.perf_counter()
        QTest.keyClick(view, QtCore.Qt.Key.Key_Right)
        lat.append(time.perf_counter() - t0)
    elapsed = time.perf_counter() - start
    assert session.frame == n_steps, f"stepped to frame {session.frame}, expected {n_steps}"
    stage.shutdown()
    stage.deleteLater()
    app.processEvents()
    med, p95 = _stats_ms(lat)
    within = float(np.mean(np.asarray(lat) < (period or 1 / 30.0)))
    return {"steps_per_s": n_steps / elapsed, "median_ms": med, "p95_ms": p95, "within": within}


def main(argv: list[str] | None = None) -> int:
    """Generate the video, run both benchmarks, print the figures and ratios."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=450)
    p.add_argument("--seeks", type=int, default=300)
    p.add_argument("--steps", type=int, default=150)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        folder = make_session(Path(tmp), args.frames)
        mb = (folder / "video.avi").stat().st_size / 1e6
        print(f"video: {args.frames} frames 640x480 MJPG, {mb:.1f} MB, generated in {time.perf_counter() - t0:.1f} s\n")
        seek = bench_random_seek(folder, args.seeks)
        floor = seek["sequential decode (floor)"][0]
        print(f"{'random exact seek':<36} {'median ms':>10} {'p95 ms':>8} {'x floor':>8}")
        for name, (med, p95) in seek.items():
            print(f"{name:<36} {med:10.2f} {p95:8.2f} {med / floor:8.2f}")
        target = seek["VideoIndex.get (cold cache)"][0]
        print(f"target median < 30 ms: {'met' if target < 30 else 'MISSED'} ({target:.2f} ms); "
              f"read_frame / VideoIndex = {seek['read_frame (open + seek + decode)'][0] / target:.1f}x\n")
        runs = {"30 Hz repeat, cache + prefetch": bench_stepping(folder, args.steps, 256, 30.0),
                "30 Hz repeat, 1-frame cache": bench_stepping(folder, args.steps, 1, 30.0),
                "unthrottled, cache + prefetch": bench_stepping(folder, args.steps, 256, None),
                "unthrottled, 1-frame cache": bench_stepping(folder, args.steps, 1, None)}
        print(f"{'Right arrow held (real stage)':<34} {'steps/s':>8} {'median ms':>10} {'p95 ms':>8} {'<33 ms':>7}")
        for name, r in runs.items():
            print(f"{name:<34} {r['steps_per_s']:8.1f} {r['median_ms']:10.2f} {r['p95_ms']:8.2f} {r['within']:7.0%}")
        a, b = runs["unthrottled, cache + prefetch"], runs["unthrottled, 1-frame cache"]
        print(f"\nprefetch speed-up of a step (median): {b['median_ms'] / a['median_ms']:.2f}x; "
              f"max stepping rate {a['steps_per_s']:.0f} vs {b['steps_per_s']:.0f} steps/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
