"""Frames per second the Synthesize preview holds on a 120 Hz clip, and where a frame's time goes.

Runs the real :class:`effortface.synth.gui.synth_stage.QtSynthStage` offscreen at the documentation size
(1400 x 900) on the CMU jumping-jacks clip (120 Hz, repeated 30 times = 110 s of curves), with the
built-in rule model and with an SVR bundle trained here on the sample lab (small grid, in a
temporary folder).

1. **Held frame rate**: the stage plays on its own QTimer for a few seconds of wall time (the
   event loop paints as in the application); frames drawn per second. Target >= 60.
2. **Cost of one frame**, measured synchronously: ``model`` = moving the play head and reading the
   curves, weights and pose at it (the model's share: curves are precomputed for the whole clip);
   ``draw`` = stick figure, face rendering, cursors and labels, then a synchronous repaint of the
   whole stage. The sustainable rate is 1 / (model + draw).
3. **Baselines, same process**: the same stage with the pixmap caches of the plots' axes, grids
   and curves switched off (then the moving cursor repaints every curve and axis each frame); and
   stepping the runtime's live per-frame stream
   (``model.stream(character, skeleton).step``) for every displayed frame, instead of looking up
   precomputed curves: its cost per frame and the ratio to the preview's model share.
4. **A character change**: the time to recompute the whole looped clip on the worker thread when
   the training level changes (work cached) and when the mass changes (work recomputed), and the
   time the GUI thread spends on it (the preview keeps playing meanwhile).

Run: ``python benchmarks/bench_synth_preview.py [--seconds 4]``
"""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from PySide6 import QtCore, QtWidgets  # noqa: E402

from effortface.synth.gui.synth_stage import QtSynthStage  # noqa: E402
from effortface.synth.synth_session import SynthSession  # noqa: E402
from effortface.train.train_session import TrainSession  # noqa: E402

from bench_data import DATA  # noqa: E402  (../shared/data, else tests/data)

CLIP = DATA / "motion" / "cmu_13_29_jumping_jacks_120fps.bvh"
LOOPS = 30
TARGET_FPS = 60.0


def make_stage(model: str) -> QtSynthStage:
    """The stage shown offscreen with the clip loaded and looped."""
    stage = QtSynthStage(SynthSession(model, background=True))
    stage.resize(1400, 900)
    stage.show()
    if not stage.load_clip(CLIP):
        raise SystemExit(f"cannot load {CLIP}: {stage.status.text()}")
    stage.session.set_loops(LOOPS)
    stage.session.wait()
    QtWidgets.QApplication.processEvents()
    return stage


def held_fps(stage: QtSynthStage, seconds: float) -> float:
    """Frames drawn per second of wall time while the stage plays on its own timer."""
    app = QtWidgets.QApplication.instance()
    stage.frames_drawn = 0
    stage.session.play()
    t0 = time.perf_counter()
    deadline = QtCore.QDeadlineTimer(int(seconds * 1000))
    while not deadline.hasExpired():
        app.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 5)
    elapsed = time.perf_counter() - t0
    stage.session.play(False)
    return stage.frames_drawn / elapsed


def frame_costs(stage: QtSynthStage, n: int = 300) -> dict[str, float]:
    """Mean seconds per frame in the model (play head + lookups) and in drawing (views + repaint)."""
    s, app = stage.session, QtWidgets.QApplication.instance()
    s.play()
    stage.timer.stop()                      # we drive the frames ourselves
    stage.timings_s = {"model": 0.0, "draw": 0.0}
    advance_s = repaint_s = 0.0
    for _ in range(n):
        t0 = time.perf_counter()
        s.advance(1.0 / 60.0)               # -> _on_position: lookups (model) and view updates (draw)
        t1 = time.perf_counter()
        app.processEvents()                 # the plots' scenes post their updates: deliver them
        stage.repaint()
        repaint_s += time.perf_counter() - t1
        advance_s += t1 - t0
    s.play(False)
    in_views = stage.timings_s["model"] + stage.timings_s["draw"]
    model = (advance_s - in_views) + stage.timings_s["model"]   # play head + callbacks + lookups
    return {"model": model / n, "draw": (stage.timings_s["draw"] + repaint_s) / n}


def set_caches(stage: QtSynthStage, enabled: bool) -> None:
    """Switch the pixmap caches of the plots' axes and curves on or off (off = the drawing baseline)."""
    mode = (QtWidgets.QGraphicsItem.CacheMode.DeviceCoordinateCache if enabled
            else QtWidgets.QGraphicsItem.CacheMode.NoCache)
    plots = [*stage.plots.plots.values(), stage.skeleton.getPlotItem()]
    for plot in plots:
        for name in ("left", "bottom", "right"):
            plot.getAxis(name).setCacheMode(mode)
    for item in stage.plots.curves.values():
        item.curve.setCacheMode(mode)


def live_stream_cost(stage: QtSynthStage, n: int = 300) -> float:
    """Baseline: seconds per frame to step the runtime's live stream on the clip's poses."""
    s = stage.session
    live = s.model.stream(s.character, s.motion)
    dt = 1.0 / s.motion.fps
    t0 = time.perf_counter()
    for i in range(n):
        live.step(s.motion.positions_m[i % s.motion.n_frames], dt)
    return (time.perf_counter() - t0) / n


def change_cost(stage: QtSynthStage, field: str, values: tuple[float, float], n: int = 10
                ) -> tuple[float, float]:
    """Seconds per character change: on the GUI thread, and until the new curves are applied."""
    gui_s = total_s = 0.0
    for i in range(n):
        t0 = time.perf_counter()
        stage.session.set_character(**{field: values[i % 2]})
        t1 = time.perf_counter()
        stage.session.wait(apply=False)
        t2 = time.perf_counter()
        stage.session.poll()                # on the GUI thread: the new curves into the plots
        t3 = time.perf_counter()
        gui_s, total_s = gui_s + (t1 - t0) + (t3 - t2), total_s + (t3 - t0)
    return gui_s / n, total_s / n


def train_bundle(folder: Path) -> Path:
    """A small SVR bundle trained on the sample lab."""
    s = TrainSession(ROOT / "sample_sessions")
    s.set_selected([e.session_id for e in s.entries])
    s.start_training()
    s.wait()
    s.export(folder / "model")
    s.wait()
    return folder / "model"


def report(name: str, stage: QtSynthStage, seconds: float) -> None:
    """Print the figures for one model."""
    set_caches(stage, False)
    fps_base, cost_base = held_fps(stage, seconds), frame_costs(stage)
    set_caches(stage, True)
    fps = held_fps(stage, seconds)
    cost = frame_costs(stage)
    live = live_stream_cost(stage)
    total = cost["model"] + cost["draw"]
    print(f"\n== {name}: {stage.session.n_frames} frames ({stage.session.duration_s:.0f} s at "
          f"{stage.session.motion.fps:g} Hz)")
    print(f"held frame rate (own timer, {seconds:g} s): {fps:6.1f} fps  "
          f"({fps / TARGET_FPS:.2f}x the {TARGET_FPS:g} fps target)")
    print(f"one frame: model {cost['model'] * 1e3:6.3f} ms ({cost['model'] / total:5.1%}), "
          f"draw {cost['draw'] * 1e3:6.2f} ms ({cost['draw'] / total:5.1%}); "
          f"sustainable {1 / total:6.0f} fps")
    print(f"drawing baseline, same stage without the axis and curve pixmap caches: "
          f"{fps_base:5.1f} fps held, draw {cost_base['draw'] * 1e3:6.2f} ms per frame = "
          f"{cost_base['draw'] / cost['draw']:4.1f}x the cached draw")
    print(f"baseline live stream step per frame: {live * 1e3:6.3f} ms = "
          f"{live / cost['model']:6.1f}x the preview's model share")
    for label, field, values in (("training level", "training_level", (2.0, 8.0)),
                                 ("mass (work recomputed)", "mass_kg", (70.0, 80.0))):
        gui_s, total_s = change_cost(stage, field, values)
        print(f"character change, {label}: new curves shown after {total_s * 1e3:6.1f} ms, "
              f"of which the GUI thread was busy {gui_s * 1e3:5.2f} ms")


def main() -> int:
    """Run the benchmark for the rule model and a trained SVR bundle."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="wall time of the held-rate run")
    args = parser.parse_args()
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    with tempfile.TemporaryDirectory() as tmp:
        for name, model in (("built-in rule model", "default"),
                            ("SVR bundle (sample lab, small grid)", str(train_bundle(Path(tmp))))):
            stage = make_stage(model)
            report(name, stage, args.seconds)
            stage.shutdown()
            stage.close()
    del app
    return 0


if __name__ == "__main__":
    sys.exit(main())
