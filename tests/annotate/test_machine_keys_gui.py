"""A pre-annotated session in the Annotate stage offscreen, driven by the keyboard: the machine row never
opens as a window of its own (the main window keeps the keys), "Accept machine" (A) sets sparse keys that
stay the machine's in the file until the rater edits one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from effortface.annotate.keyframes import origin_seconds, read_annotations
from tests.annotate.machine_helpers import write_fake_machine
from tests.annotate.test_machine_guide import one_second_median

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

SESSION = "P01_20260112-093000_cardio"
STAGE_SIZE = (1280, 800)
Key = QtCore.Qt.Key


@pytest.fixture
def lab(lab: Path) -> Path:
    """conftest.py's copy of P01 cardio with its raters' files, and a machine track."""
    write_fake_machine(lab / SESSION)
    return lab


def _open_by_keyboard(qtbot, stage, rater: str):
    """Type the rater code and press Enter (opens the selected session), as a rater does."""
    stage.activateWindow()
    stage.rater.setFocus()
    stage.rater.clear()
    QTest.keyClicks(stage.rater, rater)
    QTest.keyClick(stage.rater, Key.Key_Return)
    assert stage.editor is not None, stage.status.text()
    return stage.editor


class _WindowsShown(QtCore.QObject):
    """Records every widget shown as a window of its own (a Show event on a parentless widget)."""

    def __init__(self) -> None:
        super().__init__()
        self.windows: list[str] = []

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 - Qt override
        if event.type() == QtCore.QEvent.Type.Show and isinstance(watched, QtWidgets.QWidget) \
                and watched.isWindow() and not isinstance(watched, QtWidgets.QMenu):
            self.windows.append(f"{type(watched).__name__} {watched.width()}x{watched.height()}")
        return False


def _type(key: QtCore.Qt.Key) -> None:
    """A key press where the keyboard is: the application's focus widget (not a chosen widget)."""
    target = QtWidgets.QApplication.focusWidget()
    assert target is not None
    QTest.keyClick(target, key)


def test_a_pre_annotated_session_keeps_the_keyboard(qtbot, stage, lab: Path) -> None:
    spy = _WindowsShown()
    QtWidgets.QApplication.instance().installEventFilter(spy)
    try:
        editor = _open_by_keyboard(qtbot, stage, "R1")
    finally:
        QtWidgets.QApplication.instance().removeEventFilter(spy)
    assert spy.windows == []  # no widget was shown before it had a parent (it would take the keyboard)
    assert editor.session.machine is not None and editor.machine_row.isVisible()
    shown = [w for w in QtWidgets.QApplication.topLevelWidgets() if w.isVisible()]
    assert shown == [stage]  # the machine row is inside the editor, not a window of its own
    assert editor.machine_row.window() is stage
    assert QtWidgets.QApplication.focusWidget() is editor.video_view
    start = editor.session.frame
    _type(Key.Key_Right)
    _type(Key.Key_Right)
    assert editor.session.frame == start + 2
    _type(Key.Key_6)
    key = editor.session.key_at()
    assert key is not None and key.weight == 0.6 and key.origin == "typed"


def test_accept_machine_by_keyboard_then_edit_one_key(qtbot, stage, lab: Path) -> None:
    editor = _open_by_keyboard(qtbot, stage, "R7")  # a new rater: no keys yet
    editor.timeline.frame_all()
    assert editor.session.blendshape == "mouth_stretch" and len(editor.session.track) == 0
    _type(Key.Key_A)
    track = editor.session.track
    t = np.asarray(editor.session.session.frame_times_s)
    assert 2 < len(track) <= (t[-1] - t[0]) / 3.0  # at most one key per 3 s (953 frames, 639 s)
    reference = one_second_median(np.clip(editor.session.machine.curve("mouth_stretch"), 0, 1), t)
    face = np.isfinite(reference)
    rms = float(np.sqrt(np.mean((track.evaluate(np.arange(t.size)) - reference)[face] ** 2)))
    assert rms <= 0.08, rms
    assert f"({len(track)} the machine's, grey)" in editor.timeline.title.toPlainText()
    symbols = editor.timeline.keys.data["symbol"]
    assert set(symbols) == {"d"}  # drawn as the machine's
    assert not np.isfinite(editor.timeline.current_curve.getData()[1]).any()  # the whole curve grey
    assert np.isfinite(editor.timeline.machine_keyed_curve.getData()[1]).sum() > 0.8 * t.size
    doc = json.loads((lab / SESSION / "annotations" / "R7.json").read_text())
    saved = doc["tracks"]["mouth_stretch"]
    assert doc["schema_version"] == 2 and len(saved) == len(track)
    assert all(k["origin"] == "machine" and k["accepted_by"] == "R7" for k in saved)
    # edit one key: go to it with the keyboard and type a weight
    target = track.keys[len(track) // 2].frame
    QTest.keyClick(QtWidgets.QApplication.focusWidget(), Key.Key_G, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert QtWidgets.QApplication.focusWidget() is editor.frame_box
    QTest.keyClicks(editor.frame_box, str(target))
    QTest.keyClick(editor.frame_box, Key.Key_Return)
    assert editor.session.frame == target and QtWidgets.QApplication.focusWidget() is editor.video_view
    _type(Key.Key_7)
    back = read_annotations(lab / SESSION / "annotations" / "R7.json").tracks["mouth_stretch"]
    edited = back.get(target)
    assert edited is not None and (edited.origin, edited.weight, edited.accepted_by) == ("edited", 0.7, None)
    assert [k.frame for k in back.keys if k.origin == "edited"] == [target]
    counts = origin_seconds(back, t)
    assert counts["edited"] > 0 and counts["typed"] == 0 and counts["machine"] > counts["edited"]
    assert symbols is not editor.timeline.keys.data["symbol"]
    assert list(editor.timeline.keys.data["symbol"]).count("o") == 1  # the edited key in the rater's colour
    own = np.flatnonzero(np.isfinite(editor.timeline.current_curve.getData()[1]))
    assert own.size > 0 and own.min() < target < own.max()  # its stretch in the rater's colour
