"""The keyboard map (Help menu) lists every key the Annotate and Synthesize stages bind (issue 25
item 6): checked against the stages' real shortcuts, so a key added later without its line fails."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.app import ANNOTATE_KEYS, MainWindow

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


def _listed(keys) -> set[str]:
    out = set()
    for key, _ in keys:
        for part in key.split(" / "):
            if part == "0 .. 9":
                out |= {str(d) for d in range(10)}
            out.add(part.strip())
    return out


def test_the_map_lists_every_annotate_and_synthesize_key(qtbot, tmp_path: Path) -> None:
    from effortface.annotate.gui.annotate_stage import QtAnnotateStage
    from effortface.synth.gui.synth_stage import PLAYER_KEYS

    lab = tmp_path / "lab"
    session = "P01_20260112-093000_cardio"
    shutil.copytree(ROOT / "sample_sessions" / session, lab / session, ignore=shutil.ignore_patterns("serial"))
    stage = QtAnnotateStage(lab, cache_frames=16)
    qtbot.addWidget(stage)
    stage.rater.setText("R9")
    editor = stage.open_session(lab / session, "R9")
    assert editor is not None
    bound = {a.shortcut().toString(QtGui.QKeySequence.SequenceFormat.PortableText)
             for w in [editor, *editor.findChildren(QtWidgets.QWidget)] for a in w.actions()
             if not a.shortcut().isEmpty()}
    listed = _listed(ANNOTATE_KEYS) | {"Ctrl+Z", "Ctrl+Y"}
    assert bound and bound - listed == set(), sorted(bound - listed)
    settings = QtCore.QSettings(str(tmp_path / "s.ini"), QtCore.QSettings.Format.IniFormat)
    win = MainWindow(lab, settings)
    qtbot.addWidget(win)
    text = re.sub("<[^>]+>", "|", win.keyboard_map_html())
    assert "Synthesize" in text and all(key in text for key, _ in PLAYER_KEYS)
    assert "Alt+Left / Alt+Right" in text and "Ctrl+A / Esc" in text
    win.shutdown()
    stage.shutdown()
