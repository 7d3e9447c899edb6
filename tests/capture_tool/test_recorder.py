"""The recorder, in process: a replayed strap (replay://) plus a real video file -> a session folder."""

from __future__ import annotations

import json
import time

import pytest

from effortface.capture_tool.camera import index_video, read_frame
from effortface.core.errors import DeviceError
from effortface.capture_tool.protocols.encode import hxm_stream
from effortface.capture_tool.recorder import Recorder
from effortface.capture_tool.serlog import read_serlog
from effortface.core.session.folder import Participant, read_session, validate_session

from .capture_helpers import content, decode, frame_number, hxm_chunks, make_numbered_video, write_serlog


def _wait_for(predicate, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_strap_and_video_to_a_complete_session(tmp_path, shared_data) -> None:
    chunks = hxm_chunks(shared_data, 0, 40)
    log = write_serlog(tmp_path / "strap.serlog", chunks)
    video = make_numbered_video(tmp_path / "face.avi", 40)
    rec = Recorder(tmp_path / "out", Participant("P03", "male", 41, 1.8, 80.0, 5.0), f"replay://{log}?speed=20",
                   "hxm", video=video, label="bike")
    path = rec.start()
    assert json.loads((path / "session.json").read_text())["complete"] is False
    rec.mark("phase_start", "warm-up", "50 W")
    expected = decode(chunks)
    _wait_for(lambda: rec.status().samples >= len(expected) and rec.camera.ended)
    st = rec.status()
    assert st.link_state == "connected" and st.hr_bpm == expected[-1].hr_bpm and st.bytes_on_disk > 0
    rec.mark("phase_end", "warm-up")
    rec.stop()
    s = read_session(path)
    assert validate_session(path) == []
    assert path.name.startswith("P03_") and path.name.endswith("_bike")
    assert content(s.heart_rate) == content(expected)
    assert [e.kind for e in s.events] == ["sync", "phase_start", "phase_end", "sync"]
    assert s.events[1].value == "50 W"
    assert len(s.frame_times_s) == index_video(path / "video.avi") == 40
    assert frame_number(read_frame(path / "video.avi", 17)) == 17
    assert s.info.devices["camera"]["codec"] == "MJPG" and s.info.devices["heart_rate"]["protocol"] == "hxm"
    assert s.info.extra["stats"]["hr_samples"] == len(expected)
    assert read_serlog(path / "serial" / "hxm.serlog").data_bytes() == b"".join(d for _, d in chunks)


def test_contact_loss_gives_invalid_rows_never_zero_bpm(tmp_path) -> None:
    beats_ms = [800.0 * k for k in range(1, 12)]
    packets = hxm_stream(beats_ms, [75, 76, 0, 0, 0, 77, 78, 79, 80, 81])  # strap off the chest for 3 s
    log = write_serlog(tmp_path / "strap.serlog", [(t / 1000, p) for t, p in packets])
    rec = Recorder(tmp_path, Participant("P04"), f"replay://{log}?speed=20", "hxm")
    path = rec.start()
    _wait_for(lambda: rec.status().samples >= len(packets))
    rec.stop()
    rows = (path / "heart_rate.csv").read_text().splitlines()[1:]
    hr = [r.split(",")[1] for r in rows]
    valid = [r.split(",")[-1] for r in rows]
    assert hr[2:5] == ["", "", ""] and valid[2:5] == ["0", "0", "0"]
    assert "0" not in hr and valid.count("1") == len(rows) - 3


def test_bad_port_creates_no_folder(tmp_path) -> None:
    rec = Recorder(tmp_path, Participant("P05"), str(tmp_path / "ttyNONE"), "hxm")
    with pytest.raises(DeviceError, match="no such device"):
        rec.start()
    assert list(tmp_path.iterdir()) == []
