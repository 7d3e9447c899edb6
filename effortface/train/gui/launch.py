"""Standalone launcher of the Train and Synthesize stages (for screenshots and for a quick look).

::

    python -m effortface.train.gui.launch synth --clip CLIP.bvh [--model DIR] [--loops N] [--seconds S] [--screenshot PNG]
    python -m effortface.train.gui.launch train [--sessions DIR] [--train] [--tab N] [--screenshot PNG]

``--size WxH`` sets the window's size (default 1400x900).

``--screenshot`` renders offscreen and exits; ``--train`` trains on every annotated session first
(with the small grid); ``--seconds`` plays the clip that long before the picture.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from effortface.core.errors import UserError
from effortface.core.gui.qt_messages import install_message_filter

if TYPE_CHECKING:
    from PySide6 import QtCore

SIZE = (1400, 900)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m effortface.train.gui.launch", description=__doc__.splitlines()[0])
    p.add_argument("stage", choices=("train", "synth"))
    p.add_argument("--sessions", default="sample_sessions", metavar="DIR")
    p.add_argument("--clip", metavar="CLIP")
    p.add_argument("--model", default="default", metavar="DIR")
    p.add_argument("--loops", type=int, default=1)
    p.add_argument("--training-level", type=float, default=None, metavar="TL")
    p.add_argument("--view", choices=("front", "side"), default="front")
    p.add_argument("--load-back", type=float, default=0.0, metavar="KG")
    p.add_argument("--expressiveness", default=None, metavar="A,B,C,D")
    p.add_argument("--seconds", type=float, default=0.0, metavar="S")
    p.add_argument("--train", action="store_true")
    p.add_argument("--compare", nargs=2, metavar="MODEL_DIR")
    p.add_argument("--tab", type=int, default=0)
    p.add_argument("--screenshot", metavar="PNG")
    p.add_argument("--size", type=_size, default=SIZE, metavar="WxH")
    return p


def _size(text: str) -> tuple[int, int]:
    """``"1280x800"`` as (1280, 800)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1280x800, found {text!r}") from None
    return w, h


def _wait(app: QtCore.QCoreApplication, seconds: float) -> None:
    from PySide6 import QtCore

    deadline = QtCore.QDeadlineTimer(int(seconds * 1000))
    while not deadline.hasExpired():
        app.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 20)


def _synth(args: argparse.Namespace) -> object:
    from effortface.synth.gui.synth_stage import QtSynthStage
    from effortface.synth.synth_session import SynthSession

    session = SynthSession(args.model, background=True)
    folder = Path(args.clip).parent if args.clip else Path(args.sessions)
    stage = QtSynthStage(session, motion_dir=folder)
    if args.clip:
        stage.load_clip(args.clip)
        session.set_loops(args.loops)
    if args.training_level is not None:
        session.set_character(training_level=args.training_level)
    session.set_character(load_back_kg=args.load_back)
    if args.expressiveness:
        session.set_character(expressiveness=tuple(float(v) for v in args.expressiveness.split(",")))
    stage.view_combo.setCurrentIndex(("front", "side").index(args.view))
    session.wait()
    return stage


def _train(args: argparse.Namespace, app: object) -> object:
    from effortface.train.gui.train_stage import QtTrainStage
    from effortface.train.train_session import TrainSession

    session = TrainSession(args.sessions)
    stage = QtTrainStage(session)
    if args.train:
        session.set_selected([e.session_id for e in session.entries if e.annotated])
        session.start_training()
        session.wait()
    if args.compare:
        session.compare(*args.compare)
        session.wait()
    stage.tabs.setCurrentIndex(args.tab)
    return stage


def main(argv: list[str] | None = None) -> int:
    """Open a stage in its own window (or render it to a PNG and exit)."""
    args = _parser().parse_args(argv)
    if args.screenshot:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6 import QtWidgets

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    install_message_filter()  # Qt's propagateSizeHints() noise
    try:
        # a QtSynthStage or QtTrainStage, typed object so that the stage modules load lazily
        stage = _synth(args) if args.stage == "synth" else _train(args, app)
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stage.resize(*args.size)  # type: ignore[attr-defined]  # a stage, typed object
    stage.show()  # type: ignore[attr-defined]  # a stage, typed object
    if args.stage == "synth" and args.seconds > 0:
        stage.session.play()  # type: ignore[attr-defined]  # a stage, typed object
    _wait(app, max(args.seconds, 0.5))
    if not args.screenshot:
        return int(app.exec())
    stage.shutdown()  # type: ignore[attr-defined]  # a stage, typed object
    _wait(app, 0.3)
    out = Path(args.screenshot)
    if not stage.grab().save(str(out), "PNG"):  # type: ignore[attr-defined]  # a stage, typed object
        print(f"error: --screenshot {out}: could not write", file=sys.stderr)
        return 2
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
