"""Issue 17 case 3 and 12: one writer per rater file (a lock with a visible owner), and a refused
save shown with its file and cause. Real models, a real second process, real Qt stages offscreen."""

from __future__ import annotations

import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from PySide6 import QtCore
from PySide6.QtTest import QTest

from effortface.annotate.gui.annotate_stage import QtAnnotateStage
from effortface.annotate.keyframes import read_annotations
from effortface.annotate.annotate_session import AnnotateSession, RaterBusyError, annotation_path

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P03_20260113-094400_cardio"
N_KEYS = 30
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


@pytest.fixture
def session(tmp_path: Path) -> Path:
    dst = tmp_path / "lab" / SESSION
    shutil.copytree(SAMPLES / SESSION, dst, ignore=shutil.ignore_patterns("serial", "work.csv", "annotations"))
    return dst


def _key_all(model: AnnotateSession, first: int = 0) -> None:
    for i in range(N_KEYS):
        model.set_key(0.5, frame=first + 3 * i)


def _keys_on_disk(session: Path, rater: str = "R9") -> int:
    return sum(len(t) for t in read_annotations(annotation_path(session, rater)).tracks.values())


def test_second_annotate_on_same_rater_is_refused_naming_the_owner(session: Path) -> None:
    first = AnnotateSession(session, "R9")
    _key_all(first)
    owner = rf"pid {os.getpid()} on {socket.gethostname()} since \S+Z \(annotate\)"
    with pytest.raises(RaterBusyError, match=rf"R9\.json: expected rater R9 free on this session, found it "
                                             rf"open in another Annotate \({owner}\)"):
        AnnotateSession(session, "R9")
    _key_all(first, first=1)  # the first goes on saving, nobody overwrites it
    assert _keys_on_disk(session) == 2 * N_KEYS
    other = AnnotateSession(session, "R8")  # another rater is not blocked
    other.close()
    first.close()
    second = AnnotateSession(session, "R9")  # once closed, the next one sees every key
    assert sum(len(t) for t in second.annotations.tracks.values()) == 2 * N_KEYS
    second.close()
    assert not list((session / "annotations").glob(".*.lock"))  # a released lock leaves nothing


_HOLDER = textwrap.dedent("""
    import sys
    from effortface.annotate.annotate_session import AnnotateSession
    m = AnnotateSession(sys.argv[1], "R9")
    for i in range(int(sys.argv[2])):
        m.set_key(0.25, frame=2 * i)
    print("ready", flush=True)
    sys.stdin.readline()
    m.close()
""")


def _holder(session: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, str(session), str(N_KEYS)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc


def test_another_process_holds_the_rater_until_it_ends(session: Path) -> None:
    proc = _holder(session)
    try:
        with pytest.raises(RaterBusyError, match=rf"open in another Annotate \(pid {proc.pid} on "):
            AnnotateSession(session, "R9")
    finally:
        proc.communicate("\n", timeout=60)
    m = AnnotateSession(session, "R9")
    assert sum(len(t) for t in m.annotations.tracks.values()) == N_KEYS
    m.close()


def test_a_killed_holder_leaves_a_stale_lock_that_blocks_nothing(session: Path) -> None:
    proc = _holder(session)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert list((session / "annotations").glob(".R9.lock"))  # the file stays: kill -9 removes nothing
    m = AnnotateSession(session, "R9")
    assert sum(len(t) for t in m.annotations.tracks.values()) == N_KEYS  # every key it set is kept
    m.set_key(0.9, frame=500)
    assert _keys_on_disk(session) == N_KEYS + 1
    m.close()


@pytest.fixture
def two_stages(qtbot, session: Path) -> tuple[QtAnnotateStage, QtAnnotateStage]:
    stages = []
    for _ in range(2):
        stage = QtAnnotateStage(session.parent, cache_frames=16)
        qtbot.addWidget(stage)
        stage.resize(1200, 800)
        stage.show()
        qtbot.waitExposed(stage)
        stages.append(stage)
    yield tuple(stages)
    for stage in stages:
        stage.shutdown()


def _focus(qtbot, stage: QtAnnotateStage, editor) -> None:
    """Make ``stage`` the active window and its video view the focus, so key shortcuts reach it."""
    stage.activateWindow()
    qtbot.waitUntil(stage.isActiveWindow)
    editor.video_view.setFocus()


def test_two_annotate_stages_on_one_rater_lose_no_key(qtbot, session: Path, two_stages) -> None:
    one, two = two_stages
    editor = one.open_session(session, "R9")
    assert editor is not None
    _focus(qtbot, one, editor)
    for i in range(N_KEYS):
        editor.session.set_frame(4 * i)
        QTest.keyClick(editor.video_view, QtCore.Qt.Key.Key_5)
    assert _keys_on_disk(session) == N_KEYS
    assert two.open_session(session, "R9") is None
    assert "open in another Annotate" in two.status.text() and f"pid {os.getpid()}" in two.status.text()
    one.close_session()
    editor2 = two.open_session(session, "R9")
    assert editor2 is not None and sum(len(t) for t in editor2.session.annotations.tracks.values()) == N_KEYS


def test_a_refused_save_names_the_file_and_cause_and_keeps_the_keys(qtbot, session: Path, two_stages) -> None:
    stage = two_stages[0]
    editor = stage.open_session(session, "R9")
    editor.report = stage.show_message
    editor.session.set_key(0.3, frame=0)
    before = annotation_path(session, "R9").read_bytes()
    editor.session.set_frame(10)
    _focus(qtbot, stage, editor)
    old_limit = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # like a full disk: writes fail with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (64, old_limit[1]))
    try:
        QTest.keyClick(editor.video_view, QtCore.Qt.Key.Key_7)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old_limit)
        signal.signal(signal.SIGXFSZ, old_handler)
    text = stage.status.text()
    assert "R9.json: expected to save the keys, found the write refused (File too large)" in text, text
    assert "Unexpected" not in text
    assert annotation_path(session, "R9").read_bytes() == before  # the file keeps the keys before
    assert editor.session.key_at(10) is None  # the shown keys are the keys on disk
