"""One strap status (issue 25 item 3): the state machine behind the Strap line, banner and HR readout,
fed with real monitor figures and real link error texts."""

from __future__ import annotations

import pytest

from effortface.capture_tool.monitor import MonitorStats
from effortface.capture_tool.strap_status import NO_DECODE_BYTES, StrapStatus, plain_link_error

PORT = "/dev/ttyUSB0"


def _stats(**kw) -> MonitorStats:
    base = dict(port=PORT, link_state="connected", hr_bpm=None, rr_ms=None, rate_hz=None, since_last_s=None,
                contact_fraction=None, contact_now=None, frames_bad=0, bytes_in=0, samples_total=0)
    return MonitorStats(**{**base, **kw})


@pytest.mark.parametrize(("raw", "plain"), [
    ("device reports readiness to read but returned no data (device disconnected or multiple access on port?)",
     "the receiver stopped answering: it was unplugged or lost power"),
    ("--port /dev/ttyUSB0: expected a free port, found it in use by another program",
     "/dev/ttyUSB0: in use by another program: close it (or the other effortface window) and choose the port "
     "again"),
    ("--port /dev/ttyUSB9: expected a serial port, found no such device",
     "/dev/ttyUSB9: no such device: the receiver is unplugged, or another port is meant"),
    ("[Errno 13] could not open port /dev/ttyACM0: [Errno 13] Permission denied: '/dev/ttyACM0'",
     "permission denied: add this user to the 'dialout' group, then log in again"),
    ("[Errno 5] Input/output error", "the receiver stopped answering: it was unplugged or lost power"),
    ("something new\nsecond line", "something new"),
])
def test_pyserial_messages_in_plain_words(raw: str, plain: str) -> None:
    assert plain_link_error(raw) == plain


def test_wrong_protocol_is_named_and_detect_clears_it() -> None:
    strap = StrapStatus()
    strap.choose(PORT, "ant")
    strap.opened()
    assert strap.view().ok and strap.view().banner == ""
    strap.watched(_stats(bytes_in=NO_DECODE_BYTES * 4, frames_bad=0))
    view = strap.view()
    assert view.state == "no_decode" and view.ok is False and view.hr_bpm is None
    assert "bytes arrive but none decode as ANT: try Detect" in view.line
    assert view.banner == f"Strap {PORT}: bytes arrive but none decode as ANT: try Detect"
    strap.detected("hxm")
    assert strap.view().banner == "" and strap.view().ok and "detected protocol: hxm" in strap.view().line
    strap.watched(_stats(hr_bpm=71.0, contact_now=True, bytes_in=900, samples_total=3))
    assert strap.view().hr_bpm == 71.0 and strap.view().line.startswith("ready:") and strap.view().banner == ""


def test_a_busy_port_is_never_ready_and_its_banner_goes_with_another_port() -> None:
    strap = StrapStatus()
    strap.choose(PORT, "hxm")
    strap.failed("--port /dev/ttyUSB0: expected a free port, found it in use by another program")
    view = strap.view()
    assert view.state == "busy" and view.ok is False and "in use by another program" in view.banner
    assert not view.line.startswith("ready")
    strap.choose("/dev/ttyUSB1", "hxm")
    assert strap.view().banner == "" and strap.view().state == "checking"


def test_strap_loss_then_stop_says_missing_not_ready() -> None:
    strap = StrapStatus()
    strap.choose(PORT, "hxm")
    strap.opened()
    strap.watched(_stats(hr_bpm=80.0, contact_now=True, bytes_in=500, samples_total=5))
    strap.watched(_stats(link_state="reconnecting", bytes_in=500, samples_total=5))
    assert strap.view().state == "lost" and strap.view().hr_bpm is None and "strap lost" in strap.view().banner
    strap.failed("--port /dev/ttyUSB0: expected a serial port, found no such device")
    view = strap.view()
    assert view.state == "missing" and view.line.startswith("missing") and "no such device" in view.banner
    strap.opened()  # plugged back in
    assert strap.view().banner == "" and strap.view().line.startswith("ready")


def test_no_contact_is_not_a_heart_rate() -> None:
    strap = StrapStatus()
    strap.choose(PORT, "hxm")
    strap.watched(_stats(contact_now=False, bytes_in=300, samples_total=4))
    assert strap.view().hr_bpm is None and "no skin contact" in strap.view().line
