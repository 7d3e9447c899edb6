"""``python -m effortface.annotate.gui [DIR] [--session NAME] [--rater R] [--size WxH] [--screenshot PNG [--tab key|reliability]]``.

The Annotate stage on its own window (the main application hosts the same widget). With
``--screenshot`` it renders offscreen-friendly, saves a PNG (never over an existing file) and exits.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from PySide6 import QtWidgets

from effortface.annotate.gui.annotate_stage import QtAnnotateStage
from effortface.core.gui.qt_messages import install_message_filter

SIZE = (1400, 900)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m effortface.annotate.gui", description="the Annotate stage alone")
    p.add_argument("dir", nargs="?", default="sample_sessions", help="folder of sessions")
    p.add_argument("--session", help="open this session folder name at start")
    p.add_argument("--rater", default="", help="rater code")
    p.add_argument("--frame", type=int, default=0, help="go to this frame after opening")
    p.add_argument("--screenshot", metavar="PNG", help="save a screenshot and exit")
    p.add_argument("--tab", choices=("key", "reliability"), default="key", help="tab for the screenshot")
    p.add_argument("--size", type=_size, default=SIZE, metavar="WxH", help="window size (default 1400x900)")
    return p


def _size(text: str) -> tuple[int, int]:
    """``1280x800`` -> (1280, 800); argparse turns a ValueError into a one-line usage error."""
    w, h = (int(v) for v in text.lower().split("x"))
    if not (320 <= w <= 8000 and 240 <= h <= 8000):
        raise ValueError(text)
    return w, h


def main(argv: list[str] | None = None) -> int:
    """Run the stage window; return the exit status."""
    args = _parser().parse_args(argv)
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    install_message_filter()  # Qt's propagateSizeHints() noise
    stage = QtAnnotateStage(Path(args.dir))
    stage.rater.setText(args.rater)
    stage.resize(*args.size)
    stage.setWindowTitle("effortface - Annotate")
    if args.session:
        editor = stage.open_session(Path(args.dir) / args.session, args.rater)
        if editor is not None:
            editor.session.set_frame(args.frame)
    if args.tab == "reliability":
        stage.tabs.setCurrentIndex(1)
        if stage.reliability is not None:
            stage.reliability.poses.setFocus()
    stage.show()
    if args.screenshot:
        if Path(args.screenshot).exists():
            print(f"--screenshot {args.screenshot}: expected a new file, found one exists", file=sys.stderr)
            return 2
        for _ in range(5):
            app.processEvents()
        stage.grab().save(args.screenshot)
        stage.shutdown()
        return 0
    code = app.exec()
    stage.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
