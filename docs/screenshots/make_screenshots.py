"""Take every screenshot the README cites, offscreen, from a temporary copy of the sample lab.

    QT_QPA_PLATFORM=offscreen python docs/screenshots/make_screenshots.py [--only GROUP ...] [--out DIR]

Writes ``<name>_<w>x<h>.png`` at 1280x800 and 1920x1080 into this folder (or ``--out``), replacing
the previous ones (that is what the script is for; each path is printed). Groups (``--only``, default
all): ``app`` (the main window as it opens), ``capture`` (``before``, ``framing`` (the camera check's banner
on a GRID talking face shrunk to 14 % of the frame height, ``tests/data/video``), ``during``, ``strap_lost``,
``after`` (Stop: the last recording's summary and plot, the strap plugged back in on its own small
live plot): P01's
ANT+ serial log replayed on a pseudo-terminal, the session video played as the camera, recorded into
an empty lab), ``participant`` (``capture_participant_refused``: P01 typed as a man of 45 with
training level 8 on the sample lab, whose P01 is a woman of 23 with 2.5, Record refused;
``capture_participant_record``: the code P01 alone, the lab's record taken), ``annotate`` (``keyframes``, ``blind_round``, ``reliability``), ``train`` (``fig2``,
``fig3``, ``runlog`` after training in the stage; ``compare`` of two bundles made by
``effortface train``; ``card``: the Card tab after exporting the stage's model), ``synth`` (``rule``, ``trained``), ``machine`` (``annotate_machine_guide``:
R1's keys over the machine rater's dashed curves (the real rater, run on the copy), 330-470 s; ``annotate_machine_accept``:
a new rater after "Accept machine" over the whole session), ``fileinfo`` (``synth_fileinfo``: the
Synthesize stage's File info panel on bvh-toolbox's walk, ``tests/data/bvh``, with a mapping of its two feet),
``import_hr`` (``capture_import_hr``: a new participant P07 typed in the Capture stage, a Garmin Fenix 5
FIT and a Polar S810 R-R file from ``tests/data/hr`` imported with *Import heart rate...*).

The sample lab (``sample_sessions/``) is copied to a temporary folder first and never written to;
the states are fixed (session P01 cardio, frame at 400 s for rater R1, new rater R7 in the blind
round, P02's squat clip at 2 s) so that a retake differs only where the product changed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

os.environ["QT_QPA_PLATFORM"] = "offscreen"  # never "minimal": it lays out and draws differently
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from PySide6 import QtCore, QtWidgets  # noqa: E402
from PySide6.QtTest import QTest  # noqa: E402

from effortface.app import MainWindow, wait_settled  # noqa: E402
from effortface.core.fileio import atomic_write  # noqa: E402

OUT = Path(__file__).resolve().parent
SAMPLES = ROOT / "sample_sessions"
SIZES = ((1280, 800), (1920, 1080))
GROUPS = ("app", "capture", "participant", "annotate", "train", "synth", "machine", "fileinfo", "import_hr")
#: the fixed states of the pictures
SESSION = "P01_20260112-093000_cardio"
KEYFRAME_T_S = 400.0            # P01's 3.4 m/s run
RATER, BLIND_RATER = "R1", "R7"  # R1 finished the sample round, R7 is new to it
CLIP = Path("P02_20260112-113700_strength") / "motion" / "squats_set2.bvh"
CLIP_T_S = 2.0
GUIDE_SPAN_S = (330.0, 470.0)    # the machine guide's close-up (P01's second run)
STRAP_SPEED = 8.0               # the strap replay runs 8 times faster than recorded


# ------------------------------------------------------------------------------------ helpers
def _wait(seconds: float, until: Callable[[], bool] = lambda: False) -> bool:
    """Process events for up to ``seconds`` or until ``until()``; returns ``until()``."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not until():
        QtWidgets.QApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 50)
        time.sleep(0.02)
    return until()


def _settle(window: MainWindow, timeout_s: float = 60.0) -> None:
    """Background work done, then a few rounds of layout and painting."""
    if not wait_settled(window, timeout_s):
        raise RuntimeError(f"the window did not settle within {timeout_s:g} s")
    _wait(0.4)


def _save_png(window: QtWidgets.QWidget, path: Path) -> None:
    """The window's pixels as a PNG, written atomically (a crash leaves the previous file)."""
    data = QtCore.QByteArray()
    buffer = QtCore.QBuffer(data)
    buffer.open(QtCore.QIODevice.OpenModeFlag.WriteOnly)
    if not window.grab().save(buffer, "PNG", 0):  # 0: the smallest file (zlib level 9), lossless
        raise RuntimeError(f"could not encode {path.name}")
    buffer.close()
    atomic_write(path, lambda fh: fh.write(bytes(data.data())))
    print(path, f"{path.stat().st_size / 1024:.0f} kB")


def grab(window: MainWindow, name: str, out: Path, before: Callable[[], None] = lambda: None) -> None:
    """Save ``<name>_<w>x<h>.png`` at every size, then go back to the first size.

    ``before()`` runs after each resize (e.g. to put a scrolled view back in place).
    """
    for w, h in SIZES:
        window.resize(w, h)
        _settle(window)
        before()
        _wait(0.3)
        _save_png(window, out / f"{name}_{w}x{h}.png")
    window.resize(*SIZES[0])  # plot labels are laid out at the size they are drawn in: keep the first
    _wait(0.3)


@contextmanager
def main_window(lab: Path, settings_dir: Path, stage: str = "capture") -> Iterator[MainWindow]:
    """A main window on ``lab`` with its own settings file (never the user's), at the first size."""
    settings = QtCore.QSettings(str(settings_dir / f"settings-{lab.name}.ini"), QtCore.QSettings.Format.IniFormat)
    window = MainWindow(lab, settings)
    window.resize(*SIZES[0])
    window.show()
    window.show_stage(stage)
    try:
        yield window
    finally:
        window.shutdown()
        window.hide()
        window.deleteLater()
        _wait(0.2)


def copy_lab(tmp: Path) -> Path:
    """The sample lab copied to ``tmp/sample_sessions`` (the stages write there, never into the repo)."""
    lab = tmp / "sample_sessions"
    shutil.copytree(SAMPLES, lab, ignore=shutil.ignore_patterns("_ground_truth", "__pycache__", "*.py"))
    return lab


def train_bundles(lab: Path, models: Path) -> dict[str, Path]:
    """``effortface train`` on the lab: the paper's leave-one-participant-out model and a K-fold one."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))}
    bundles = {}
    for cv in ("lopo", "kfold"):
        bundles[cv] = models / cv
        command = [sys.executable, "-m", "effortface", "train", str(lab), "--out", str(bundles[cv]), "--cv", cv]
        print("$", " ".join(command[1:]), flush=True)
        subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
    return bundles


# ---------------------------------------------------------------------------------- the stages
def shoot_app(lab: Path, tmp: Path, out: Path) -> None:
    """The main window as it opens on the lab: the Capture stage, nothing chosen yet."""
    with main_window(lab, tmp) as window:
        grab(window, "app", out)


def shoot_capture(tmp: Path, out: Path) -> None:
    """Capture before, during and after a strap loss: P01's strap replayed, recorded into an empty lab."""
    from effortface.capture_tool.participants import register
    from effortface.capture_tool.replay import PtyReplay, load_timed_chunks, start_replay_thread
    from effortface.core.session.folder import read_session_info

    session = SAMPLES / SESSION
    lab = tmp / "capture_lab"
    lab.mkdir()
    register(lab / "participants.tsv", read_session_info(session).participant)
    replay = PtyReplay(load_timed_chunks(session / "serial" / "ant.serlog"), speed=STRAP_SPEED,
                       unplug_after_s=200.0)  # after the "during" picture, even on a busy machine
    replays = [(replay, start_replay_thread(replay))]
    try:
        with main_window(lab, tmp) as window:
            stage = window.stages["capture"]
            stage.form.registry.setCurrentText("P01")
            _choose_devices(stage, replay.path, session / "video.avi")
            _wait(15, lambda: stage.settled() and stage.live.hr_label.value.text() != "--")
            _wait(2)
            grab(window, "capture_before", out)
            # the camera check on a face too small for the machine rater (a real GRID talker at 14 %): its banner
            stage.preflight.set_choice(video_file=small_face_video(tmp / "small_face.avi"))
            if not _wait(20, lambda: stage.banner_text().startswith("Camera: move the camera closer")):
                raise RuntimeError(f"no framing banner: {stage.banner_text()!r}")
            grab(window, "capture_framing", out)
            stage.preflight.set_choice(video_file=session / "video.avi")
            _wait(20, lambda: not stage.banner_text().startswith("Camera: "))
            _record(stage)
            grab(window, "capture_during", out)
            _wait(30, lambda: stage.session.recorder.link.state == "reconnecting")
            _wait(1.5)
            grab(window, "capture_strap_lost", out)
            stage.phases.marker_text.clear()
            stage.sync_test()  # the flash (the session video is no camera facing the screen: not seen)
            _wait(20, lambda: stage.session.recorder.link.state == "connected")
            stage.stop_recording()  # as the operator does: in the background, the summary stays after it
            if not _wait(60, lambda: not stage.session.recording and stage.settled()):
                raise RuntimeError("the recording did not stop")
            # the receiver plugged back in (a new port): its live strap gets a small plot of its own, the
            # summary and the recording's plot stay
            replug = PtyReplay(load_timed_chunks(session / "serial" / "ant.serlog"), speed=STRAP_SPEED)
            replays.append((replug, start_replay_thread(replug)))
            stage.preflight.set_choice(port=replug.path)  # checked again (the same path may come back)
            if not _wait(30, lambda: stage.live.n_monitor_samples() >= 40):
                raise RuntimeError(f"the strap plugged back in is not drawn: {stage.preflight.strap_status.text()}")
            grab(window, "capture_after", out)
    finally:
        for each, each_thread in replays:
            each.stop()
            each_thread.join(5)
            each.close()


def shoot_participant(lab: Path, tmp: Path, out: Path) -> None:
    """One truth per participant: P01 typed with other demographics is refused; the code alone takes the
    lab's record (the sample lab's registry, or its sessions when it has none)."""
    with main_window(lab, tmp) as window:
        stage = window.stages["capture"]
        stage.preflight.set_choice(port="loop://", protocol="ant")
        stage.preflight.camera.setCurrentText("No video")
        _settle(window)
        form = stage.form
        form.sex.setCurrentText("male")
        form.age.setValue(45)
        form.height_m.setValue(1.66)
        form.mass.setValue(58.0)
        form.training_level.setValue(8)
        form.code.setText("P01")
        stage.start_recording()  # refused: the form and the banner say why
        grab(window, "capture_participant_refused", out)
        form.clear_fields()
        form.code.clear()
        form.code.setText("P01")
        stage.clear_banner()
        grab(window, "capture_participant_record", out)


def small_face_video(path: Path, share: float = 0.14) -> Path:
    """The GRID talking face of tests/data/video shrunk so that it fills ``share`` of the frame's height."""
    import numpy as np

    from effortface.capture_tool.framing_sampler import check_camera_framing
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    cap = cv2.VideoCapture(str(ROOT / "tests" / "data" / "video" / "grid_sbwe5n.mpg"))
    frames = [frame for ok, frame in iter(cap.read, (False, None)) if ok][:25]
    cap.release()
    scale = share / (check_camera_framing(frames[0]).face_share or 1.0)
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (w, h))
    for frame in frames:
        small = cv2.resize(frame, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
        canvas = np.full_like(frame, 40)
        top, left = (h - small.shape[0]) // 2, (w - small.shape[1]) // 2
        canvas[top:top + small.shape[0], left:left + small.shape[1]] = small
        writer.write(canvas)
    writer.release()
    return path


def _choose_devices(stage: QtWidgets.QWidget, port: str, video: Path) -> None:
    """The protocol and the camera first, then the port alone, as an operator picks them: one check
    of the strap, then its live monitor (checks overlapping on one port find it busy)."""
    preflight = stage.preflight
    _wait(15, stage.settled)
    preflight.set_choice(protocol="ant", video_file=video)
    _wait(15, stage.settled)
    preflight.port.setCurrentText(port)
    if not _wait(15, lambda: stage.settled() and stage.session.watching(port)):
        raise RuntimeError(f"the strap on {port} is not watched: {preflight.strap_status.text()}")


def _record(stage: QtWidgets.QWidget) -> None:
    """Record, then log rest, a walk, a marker, a run and a speed change; a marker note left typed."""
    stage.notes.setPlainText("P01 first treadmill session; strap moistened at 09:28")
    stage.toggle_recording()
    _wait(10, lambda: stage.session.recording and stage.settled())
    panel = stage.phases
    panel.request_phase("rest")
    _wait(4)
    panel.pick("treadmill_walk", speed_m_s=1.5, grade_pct=1.0)
    panel.request_exercise()
    _wait(3)
    panel.marker_text.setText("water")
    panel.request_marker()
    _wait(2)
    panel.pick("treadmill_run", speed_m_s=3.4, grade_pct=1.0)
    panel.request_exercise()
    _wait(2)
    panel.pick("treadmill_run", speed_m_s=3.6, grade_pct=1.0)
    panel.request_parameters()
    _wait(2)
    panel.marker_text.setText("side stitch, slowing")


def shoot_annotate(lab: Path, tmp: Path, out: Path) -> None:
    """Key-frames of P01's cardio session for R1; the blind round of a new rater; R1's report."""
    with main_window(lab, tmp, "annotate") as window:
        stage = window.stages["annotate"]
        editor = stage.open_session(lab / SESSION, RATER)
        if editor is None:
            raise RuntimeError(stage.status.text())
        editor.session.go_to_time(KEYFRAME_T_S)
        grab(window, "annotate_keyframes", out)
        stage.tabs.setCurrentIndex(1)
        for rater, name in ((BLIND_RATER, "annotate_blind_round"), (RATER, "annotate_reliability")):
            stage.rater.setText(rater)  # typed and confirmed, as a rater does
            QTest.keyClick(stage.rater, QtCore.Qt.Key.Key_Return)
            panel = stage.reliability
            if panel is None or stage.reliability_host.currentWidget() is not panel or panel.rater != rater:
                raise RuntimeError(stage.status.text())
            panel.poses.selectRow(0)
            grab(window, name, out, before=panel.poses.scrollToTop)


def machine_track(session: Path) -> None:
    """Pre-annotate the session with the machine rater; without the engine (a build without the face
    landmarker), the test suite's stand-in track (the raters' mean + noise, two no-face stretches)."""
    from effortface.annotate.machine.preannotate import preannotate_session
    from effortface.core.errors import UserError

    try:
        written = preannotate_session(session)
        print(f"machine: the real rater wrote {written}", flush=True)
    except UserError as exc:
        from tests.annotate.machine_helpers import write_fake_machine

        print(f"machine: {exc}; drawing the test track instead", flush=True)
        write_fake_machine(session, noise=0.01)


def shoot_machine(lab: Path, tmp: Path, out: Path) -> None:
    """P01 cardio with a machine track: R1's keys over the dashed machine guides; R7 after "Accept machine"."""
    machine_track(lab / SESSION)
    with main_window(lab, tmp, "annotate") as window:
        stage = window.stages["annotate"]
        for rater, name in ((RATER, "annotate_machine_guide"), (BLIND_RATER, "annotate_machine_accept")):
            stage.close_session()
            stage.rater.setText(rater)
            editor = stage.open_session(lab / SESSION, rater)
            if editor is None:
                raise RuntimeError(stage.status.text())
            editor.session.set_blendshape("mouth_open")
            editor.session.go_to_time(KEYFRAME_T_S)
            if rater == BLIND_RATER:
                editor.timeline.frame_all()
                editor.accept_machine()

            def framed(editor=editor, whole=rater == BLIND_RATER) -> None:
                if whole:
                    editor.timeline.frame_all()
                else:  # a close-up before the cursor, where the dashes show between R1's keys
                    editor.timeline.curve_plot.setXRange(*GUIDE_SPAN_S, padding=0)
            grab(window, name, out, before=framed)


def shoot_train(lab: Path, bundles: dict[str, Path], tmp: Path, out: Path) -> None:
    """Train in the stage on every session (defaults), show its results, compare the two CLI bundles."""
    with main_window(lab, tmp, "train") as window:
        stage = window.stages["train"]
        stage.picker.select_shown_button.click()
        stage.train()
        if not _wait(600, lambda: stage.settled() and stage.session.outcome is not None):
            raise RuntimeError(f"training did not finish: {stage.status.text()}")
        stage.hr_results.choice.setCurrentText(SESSION)
        stage.face_results.choice.setCurrentText(SESSION)
        for index, name in ((0, "train_fig2"), (1, "train_fig3"), (3, "train_runlog")):
            stage.tabs.setCurrentIndex(index)
            grab(window, name, out)
        stage.tabs.setCurrentIndex(2)
        compare = stage.comparison
        for edit, cv in zip(compare.paths, ("lopo", "kfold")):
            edit.setText(str(bundles[cv]))
        compare.choice.setCurrentText(SESSION)
        compare.compare()
        if not _wait(120, lambda: stage.settled() and stage.session.comparison is not None):
            raise RuntimeError(f"the comparison did not finish: {stage.status.text()}")
        grab(window, "train_compare", out)
        if not stage.export(tmp / "card_model"):  # the Card tab shows the exported MODEL_CARD.md
            raise RuntimeError(f"export failed: {stage.status.text()}")
        if not _wait(300, lambda: stage.settled() and bool(stage.card.toPlainText())):
            raise RuntimeError(f"the export did not finish: {stage.status.text()}")
        stage.tabs.setCurrentWidget(stage.card)
        grab(window, "train_card", out)


def shoot_synth(lab: Path, bundles: dict[str, Path], tmp: Path, out: Path) -> None:
    """P02's squat clip at 2 s: the built-in rule model (front view), the trained one (side view, 3 x)."""
    with main_window(lab, tmp, "synthesize") as window:
        stage = window.stages["synthesize"]
        for name, model, view, loops in (("synth_rule", "default", 0, 1),
                                         ("synth_trained", bundles["lopo"], 1, 3)):
            for ok in (stage.load_model(model), stage.load_clip(lab / CLIP)):
                if not ok:
                    raise RuntimeError(stage.status.text())
            stage.view_combo.setCurrentIndex(view)
            stage.loops.setValue(loops)
            _settle(window)
            stage.session.seek(CLIP_T_S)
            grab(window, name, out)


def shoot_fileinfo(lab: Path, tmp: Path, out: Path) -> None:
    """The File info panel: bvh-toolbox's walk (the conventions map all but its feet) and a mapping of the feet."""
    clip = tmp / "walk01.bvh"
    shutil.copyfile(ROOT / "tests" / "data" / "bvh" / "bvhtoolbox_walk01.bvh", clip)
    feet = tmp / "walk01-feet.json"
    feet.write_text('{"version": 2, "left_foot": ["LeftFoot", "LeftFoot_end"], '
                    '"right_foot": ["RightFoot", "RightFoot_end"]}\n', encoding="utf-8")
    with main_window(lab, tmp, "synthesize") as window:
        stage = window.stages["synthesize"]
        for ok in (stage.load_model("default"), stage.load_clip(clip)):
            if not ok:
                raise RuntimeError(stage.status.text())
        _settle(window)  # the clip's recompute (refused: its feet are unmapped) is done before the mapping
        if not stage.set_mapping(feet):
            raise RuntimeError(stage.status.text())
        _settle(window)
        stage.show_file_info()
        grab(window, "synth_fileinfo", out)


def shoot_import_hr(lab: Path, tmp: Path, out: Path) -> None:
    """Two watch files imported for a new participant from the Capture stage's action bar."""
    data = ROOT / "tests" / "data" / "hr"
    with main_window(lab, tmp) as window:
        stage = window.stages["capture"]
        _settle(window)
        form = stage.form
        form.code.setText("P07")
        form.sex.setCurrentText("male")
        form.age.setValue(34)
        form.height_m.setValue(1.81)
        form.mass.setValue(77.5)
        form.training_level.setValue(5.0)
        if not stage.import_heart_rate([str(data / "garmin-fenix5-run.fit"), str(data / "polar-s810-rr.hrm")]):
            raise RuntimeError(stage.banner.text())
        if not _wait(60.0, lambda: stage.banner.text().startswith(("Imported", "Import refused"))):
            raise RuntimeError("the import did not finish in 60 s")
        _settle(window)
        grab(window, "capture_import_hr", out)


# ----------------------------------------------------------------------------------- main
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """``--only GROUP ...`` and ``--out DIR``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=GROUPS, default=list(GROUPS), metavar="GROUP",
                        help=f"groups to take (default all: {', '.join(GROUPS)})")
    parser.add_argument("--out", type=Path, default=OUT, help="folder of the PNGs (default: this folder)")
    args = parser.parse_args(argv)
    if not args.out.is_dir():
        parser.error(f"--out {args.out}: expected an existing folder, found none")
    return args


def main(argv: list[str] | None = None) -> int:
    """Take the screenshots of the groups asked for."""
    args = parse_args(argv)
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    tmp = Path(tempfile.mkdtemp(prefix="effortface-shots-"))
    try:
        lab = copy_lab(tmp)
        bundles = train_bundles(lab, tmp / "models") if {"train", "synth"} & set(args.only) else {}
        if "app" in args.only:
            shoot_app(lab, tmp, args.out)
        if "capture" in args.only:
            shoot_capture(tmp, args.out)
        if "participant" in args.only:
            shoot_participant(lab, tmp, args.out)
        if "annotate" in args.only:
            shoot_annotate(lab, tmp, args.out)
        if "train" in args.only:
            shoot_train(lab, bundles, tmp, args.out)
        if "synth" in args.only:
            shoot_synth(lab, bundles, tmp, args.out)
        if "machine" in args.only:
            shoot_machine(lab, tmp, args.out)
        if "fileinfo" in args.only:
            shoot_fileinfo(lab, tmp, args.out)
        if "import_hr" in args.only:
            shoot_import_hr(lab, tmp, args.out)
    finally:
        app.processEvents()
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
