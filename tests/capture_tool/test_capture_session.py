"""CaptureSession, the Capture stage's model, without Qt (T1): background jobs and emitters.

The GUI tests (test_capture_gui.py, test_capture_recovery_gui.py) drive the same model through the
stage; here the model's own contract is checked: what each emitter says, in which order.
"""

from __future__ import annotations

from pathlib import Path

from effortface.capture_tool.capture_session import CaptureSession, DeviceChoice
from effortface.core.session.folder import Participant, SessionInfo, create_session

TIMEOUT_S = 30


def _listen(session: CaptureSession) -> list[tuple]:
    log: list[tuple] = []
    session.state_changed.connect(lambda state: log.append(("state", state)))
    session.recording_changed.connect(lambda path: log.append(("recording", path)))
    session.status_changed.connect(lambda text, is_error: log.append(("status", text, is_error)))
    session.incomplete_changed.connect(lambda sessions: log.append(("incomplete", [p.name for p in sessions])))
    return log


def _deliver(session: CaptureSession) -> None:
    assert session.jobs.wait(TIMEOUT_S)
    assert session.poll() is None  # not recording: no live update


def test_a_start_that_fails_reports_through_the_emitters_and_goes_back_to_idle(tmp_path: Path) -> None:
    session = CaptureSession(tmp_path / "sessions")
    log = _listen(session)
    session.start_in_background(Participant("P01"), DeviceChoice("", "hxm", None))
    assert session.busy and session.state == "starting"
    _deliver(session)
    assert log == [("state", "starting"), ("state", "idle"),
                   ("status", "Could not start: Strap port: expected a serial port or URL, found none chosen",
                    True)]
    assert not session.busy and not session.recording and session.jobs.idle()
    session.shutdown()


def test_a_failed_recovery_is_not_offered_again(tmp_path: Path) -> None:
    out = tmp_path / "sessions"
    folder = create_session(out, SessionInfo("P05_20260101-120000", Participant("P05"),
                                             {"heart_rate": {"protocol": "hxm"}}))
    (folder / "heart_rate.csv").write_text("time,bpm\n1.0,70\n", encoding="utf-8")  # a wrong header
    session = CaptureSession(out)
    log = _listen(session)
    assert session.check_incomplete() == [folder]
    assert session.recover_in_background(folder)
    assert not session.recover_in_background(folder)  # busy: a second request is ignored
    _deliver(session)
    assert log[:3] == [("incomplete", [folder.name]), ("state", "recovering"), ("state", "idle")]
    kind, text, is_error = log[3]
    assert kind == "status" and text.startswith(f"Recovery of {folder.name} failed: ") and is_error
    assert log[4:] == [("incomplete", [folder.name])]  # still incomplete on disk ...
    assert session.recovery_failed == {folder}          # ... but the view is told not to offer it
    session.shutdown()
