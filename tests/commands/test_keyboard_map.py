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



#: opens Help > Keyboard map on a screen of the given size, prints its figures as JSON (a screen of
#: its own needs a process of its own: the offscreen platform's screen is set when Qt starts)
_OPEN_MAP = """
import json, re, sys
from pathlib import Path
from PySide6 import QtCore, QtWidgets
from effortface.app import MainWindow
app = QtWidgets.QApplication([])
settings = QtCore.QSettings(sys.argv[1] + "/s.ini", QtCore.QSettings.Format.IniFormat)
win = MainWindow(Path(sys.argv[2]), settings)
win.resize(*app.primaryScreen().availableGeometry().size().toTuple())
win.show()
box = win.show_keyboard_map()
for _ in range(20):
    app.processEvents()
box.grab().save(sys.argv[1] + "/keyboard_map.png")
print(json.dumps({"height": box.height(), "width": box.width(), "hint": box.sizeHint().height(),
                  "label": box.label.height(), "viewport": box.scroll_area.viewport().height(),
                  "label_w": box.label.width(), "viewport_w": box.scroll_area.viewport().width(),
                  "text": re.sub("<[^>]+>", "|", box.text()).replace("&amp;", "&")}))
box.close()
win.shutdown()
"""


@pytest.mark.parametrize("screen", [(1280, 800), (800, 600)], ids=["1280x800", "800x600"])
def test_the_map_fits_the_screen_and_lists_every_key(tmp_path: Path, screen: tuple[int, int]) -> None:
    """Help > Keyboard map in two columns in a scroll area (it was one list 1302 px tall): whole and
    unscrolled on a 1280x800 screen; on a smaller one never taller than the screen (it scrolls); every key
    of the window, Capture, Annotate and Synthesize still listed."""
    import json
    import os
    import subprocess
    import sys

    from effortface.app import WINDOW_KEYS
    from effortface.capture_tool.gui.phases import PHASE_KEYS
    from effortface.synth.gui.synth_stage import PLAYER_KEYS

    config = tmp_path / "screen.json"
    config.write_text(json.dumps({"screens": [{"name": "s", "x": 0, "y": 0, "width": screen[0],
                                               "height": screen[1], "logicalDpi": 96, "logicalBaseDpi": 96,
                                               "dpr": 1}]}))
    env = {**os.environ, "QT_QPA_PLATFORM": f"offscreen:configfile={config}",
           "EFFORTFACE_SETTINGS": str(tmp_path / "s.ini")}
    done = subprocess.run([sys.executable, "-c", _OPEN_MAP, str(tmp_path), str(ROOT / "sample_sessions")],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.splitlines()[-1])
    assert got["height"] <= screen[1] and got["hint"] <= 800 and got["width"] <= screen[0]
    assert got["label_w"] <= got["viewport_w"]  # never scrolled sideways
    if screen == (1280, 800):
        assert got["label"] <= got["viewport"], got  # the whole map in sight
    for key, _ in (*WINDOW_KEYS, *ANNOTATE_KEYS, *PLAYER_KEYS, *((k, "") for k in PHASE_KEYS.values())):
        assert f"|{key}|" in got["text"], key
    if out := os.environ.get("EFFORTFACE_KEYMAP_PNG_DIR"):
        shot = (tmp_path / "keyboard_map.png").read_bytes()
        (Path(out) / f"keyboard_map_{screen[0]}x{screen[1]}.png").write_bytes(shot)
