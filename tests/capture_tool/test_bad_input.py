"""Bad files and bad options found by the CLI audit: one line on stderr naming the file or option,
exit status 2, no traceback, no byte silently lost."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from effortface.capture_tool.camera import open_capture
from effortface.capture_tool.captures import find_timing_file, read_timed_capture
from effortface.core.errors import SessionFormatError, UserError
from effortface.core.session.hr_csv import HR_CSV_HEADER, read_hr_csv
from effortface.capture_tool.recorder import decode_serlog
from effortface.capture_tool.serlog import EVENT, SerlogWriter, _REC, read_serlog
from effortface.core.session.folder import EVENTS_HEADER, Participant, SessionInfo, read_events, read_session_info
from effortface.cli import main

from .capture_helpers import BODY

BINARY = bytes(range(128, 256)) * 4


def _one_error_line(capsys, argv: list[str]) -> str:
    """Run the CLI; assert exit 2 and exactly one ``error:`` line on stderr; return it."""
    assert main([str(a) for a in argv]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and ": error: " in lines[0], lines
    return lines[0]


def _session(root: Path, **overrides: object) -> Path:
    """A minimal incomplete session (session.json, heart_rate.csv, an hxm serial log) with JSON overrides."""
    folder = root / "P01_20260112-093000"
    (folder / "serial").mkdir(parents=True)
    info = SessionInfo("P01_20260112-093000", Participant("P01"), devices={"heart_rate": {"protocol": "hxm"}})
    data = {**info.to_dict(), **overrides}
    (folder / "session.json").write_text(json.dumps(data), encoding="utf-8")
    (folder / "heart_rate.csv").write_text(HR_CSV_HEADER + "\n", encoding="utf-8")
    with SerlogWriter(folder / "serial" / "hxm.serlog", {"protocol": "hxm", "device": "hxm"}) as w:
        w.write(0.0, b"\x02\x26\x37")
    return folder


# ------------------------------------------------------------------------------ 1. negative camera
def test_capture_negative_camera_is_one_line(tmp_path, capsys) -> None:
    line = _one_error_line(capsys, ["capture", "--port", "loop://", "--protocol", "hxm", "--camera", "-1",
                                    "--participant", "P01", *BODY, "--out", tmp_path / "out", "--duration", "1"])
    assert "--camera: expected a camera index >= 0, found -1" in line
    assert not (tmp_path / "out").exists()


def test_open_capture_refuses_negative_index() -> None:
    with pytest.raises(UserError, match="--camera: expected a camera index >= 0, found -2"):
        open_capture(-2)


# ------------------------------------------------------------------------------------- 2. recover
def test_corrupt_event_record_is_skipped_and_counted(tmp_path) -> None:
    log = tmp_path / "hxm.serlog"
    with SerlogWriter(log, {"protocol": "hxm"}) as w:
        w.write(0.0, b"\x02")
        w.write_event(0.5, "device_gap")
    with open(log, "ab") as fh:
        fh.write(_REC.pack(EVENT, 1.0, 3) + b"\xff\xfe\x00")
    assert [r.event() for r in read_serlog(log).records if r.kind == EVENT][1] == {}
    notes: list[str] = []
    decode_serlog(log, notes)
    assert notes == ["hxm.serlog: skipped 1 corrupt event record(s)"]


def test_recover_corrupt_event_record_does_not_crash(tmp_path, capsys) -> None:
    folder = _session(tmp_path)
    with open(folder / "serial" / "hxm.serlog", "ab") as fh:
        fh.write(_REC.pack(EVENT, 1.0, 2) + b"\xff\xff")
    assert main(["recover", str(folder)]) == 0
    assert "skipped 1 corrupt event record(s)" in capsys.readouterr().out


@pytest.mark.parametrize("name", ["serial/hxm.serlog", "video_frames.csv", "session.json", "heart_rate.csv"])
def test_recover_file_that_is_a_folder(tmp_path, capsys, name: str) -> None:
    folder = _session(tmp_path)
    target = folder / name
    target.unlink(missing_ok=True)
    target.mkdir()
    line = _one_error_line(capsys, ["recover", folder])
    assert f"{target}: expected a" in line and "found a folder" in line


def test_recover_binary_video_frames(tmp_path, capsys) -> None:
    folder = _session(tmp_path)
    (folder / "video_frames.csv").write_bytes(b"frame,t_s\n" + BINARY + b"\n")
    assert "video_frames.csv: expected UTF-8 text" in _one_error_line(capsys, ["recover", folder])


def test_recover_given_a_file(tmp_path, capsys) -> None:
    (tmp_path / "empty.bin").write_bytes(b"")
    line = _one_error_line(capsys, ["recover", tmp_path / "empty.bin"])
    assert line.endswith("empty.bin: expected a session folder, found a file")


def test_recover_names_the_missing_participant_code(tmp_path, capsys) -> None:
    folder = _session(tmp_path, participant={"sex": "female"})
    line = _one_error_line(capsys, ["recover", folder])
    assert "session.json: participant: expected the key 'code', found only ['sex']" in line


def test_recover_blames_the_serlog_header_not_protocol_option(tmp_path, capsys) -> None:
    folder = _session(tmp_path)
    log = folder / "serial" / "hxm.serlog"
    log.unlink()
    SerlogWriter(log, {"protocol": "zzz"}).close()
    line = _one_error_line(capsys, ["recover", folder])
    assert f"{log}: header field 'protocol': expected one of ant, ble_hrm, hrmi, hxm, lines, found 'zzz'" in line
    assert "--protocol" not in line


# ---------------------------------------------------------------------------- 3. session contents
def test_binary_csvs_name_the_file(tmp_path) -> None:
    (tmp_path / "heart_rate.csv").write_bytes(BINARY)
    (tmp_path / "events.csv").write_bytes(EVENTS_HEADER.encode() + b"\n" + BINARY)
    with pytest.raises(SessionFormatError, match=r"heart_rate.csv: expected UTF-8 text"):
        read_hr_csv(tmp_path / "heart_rate.csv")
    with pytest.raises(SessionFormatError, match=r"events.csv: expected UTF-8 text"):
        read_events(tmp_path / "events.csv")


@pytest.mark.parametrize(("field", "value", "found"), [
    ("devices", [1], "field 'devices': expected a JSON object, found array [1]"),
    ("devices", "abc", "field 'devices': expected a JSON object, found string 'abc'"),
    ("software", [3], "field 'software': expected a JSON object, found array [3]"),
    ("complete", "false", "field 'complete': expected true or false, found string 'false'"),
    ("participant", None, "participant: expected a JSON object, found null"),
    ("participant", [1, 2], "participant: expected a JSON object, found array [1, 2]"),
])
def test_session_json_field_types(tmp_path, field: str, value: object, found: str) -> None:
    folder = _session(tmp_path, **{field: value})
    with pytest.raises(SessionFormatError) as info:
        read_session_info(folder)
    assert str(info.value) == f"{folder / 'session.json'}: {found}"


def test_session_json_null_devices_still_reads(tmp_path) -> None:
    assert read_session_info(_session(tmp_path, devices=None, software=None)).devices == {}


# ------------------------------------------------------------------------------- 4. capture --out
@pytest.mark.parametrize("out", ["/proc/effortface-x", "{file}/x", "{file}"])
def test_capture_unwritable_out_names_out(tmp_path, capsys, out: str) -> None:
    (tmp_path / "file").write_text("x")
    out = out.format(file=tmp_path / "file")
    line = _one_error_line(capsys, ["capture", "--port", "loop://", "--protocol", "hxm", "--no-video",
                                    "--participant", "P01", *BODY, "--out", out, "--duration", "1"])
    assert f"--out {out}: expected a folder" in line


# --------------------------------------------------------------------------- 5. raw timing files
def _raw(tmp_path: Path, timing: bytes | None, n: int = 2000) -> Path:
    raw = tmp_path / "r.bin"
    raw.write_bytes(bytes(range(256)) * (n // 256) + bytes(n % 256))
    if timing is not None:
        (tmp_path / "r-timing.csv").write_bytes(timing)
    return raw


def test_binary_timing_csv(tmp_path, capsys) -> None:
    raw = _raw(tmp_path, BINARY)
    line = _one_error_line(capsys, ["decode", "--protocol", "ant", raw])
    assert "r-timing.csv: expected UTF-8 text" in line


def test_timing_csv_that_is_a_folder_is_not_used(tmp_path) -> None:
    raw = _raw(tmp_path, None)
    (tmp_path / "r-timing.csv").mkdir()
    assert find_timing_file(raw) is None
    assert sum(len(d) for _, d in read_timed_capture(raw)) == 2000


def test_timing_csv_with_only_a_header(tmp_path) -> None:
    raw = _raw(tmp_path, b"host_time_s,byte_offset_x\n")
    with pytest.raises(SessionFormatError, match=r"r-timing.csv: expected 'time,offset' rows after the header"):
        read_timed_capture(raw)


@pytest.mark.parametrize("content", [b"", b"\n\n"], ids=["empty", "blank lines"])
def test_empty_timing_csv_is_refused_not_read_as_time_zero(tmp_path, capsys, content) -> None:
    raw = _raw(tmp_path, content)
    line = _one_error_line(capsys, ["decode", "--protocol", "ant", raw])
    assert "r-timing.csv: expected the arrival times of r.bin's bytes, found an empty file" in line


def test_timing_offsets_out_of_order_name_the_line(tmp_path) -> None:
    raw = _raw(tmp_path, b"host_time_s,byte_offset_x\n0.1,500\n0.2,10\n0.3,1000\n")
    with pytest.raises(SessionFormatError, match=r"r-timing.csv: line 3: expected an offset >= 500"):
        read_timed_capture(raw)


def test_timing_in_order_keeps_every_byte(tmp_path) -> None:
    raw = _raw(tmp_path, b"host_time_s,byte_offset_x\n0.1,500\n0.2,500\n0.3,1000\n")
    assert b"".join(d for _, d in read_timed_capture(raw)) == raw.read_bytes()


# ---------------------------------------------------------------------------------- 6. decode
def test_decode_garbage_serlog_says_bad_magic(tmp_path, capsys) -> None:
    (tmp_path / "g.serlog").write_bytes(BINARY)
    for extra in ([], ["--protocol", "ant"]):
        line = _one_error_line(capsys, ["decode", *extra, tmp_path / "g.serlog"])
        assert "g.serlog: expected a .serlog file starting with b'EFSERLOG 1\\n'" in line


def test_decode_garbage_pcap_says_bad_magic(tmp_path, capsys) -> None:
    (tmp_path / "g.pcap").write_bytes(BINARY)
    line = _one_error_line(capsys, ["decode", "--protocol", "ant", tmp_path / "g.pcap"])
    assert "g.pcap: expected a libpcap file starting with magic" in line and "found 80818283" in line


def test_decode_missing_file(tmp_path, capsys) -> None:
    line = _one_error_line(capsys, ["decode", tmp_path / "none.serlog"])
    assert "none.serlog: expected a readable capture file, found nothing (no such file)" in line


def test_decode_bad_protocol_before_note(tmp_path, capsys) -> None:
    log = tmp_path / "a.serlog"
    SerlogWriter(log, {"protocol": "ant"}).close()
    line = _one_error_line(capsys, ["decode", "--protocol", "bogus", log])
    assert "--protocol: expected one of ant, ble_hrm, hrmi, hxm, lines, found 'bogus'" in line


@pytest.mark.parametrize("special", ["/dev/zero", "fifo"])
def test_decode_refuses_non_regular_files(tmp_path, capsys, special: str) -> None:
    if special == "fifo":
        special = str(tmp_path / "fifo.bin")
        os.mkfifo(special)
    line = _one_error_line(capsys, ["decode", "--protocol", "hxm", special])
    assert f"{special}: expected a readable capture file, found a special file" in line


# -------------------------------------------------------------------------- 7. port and --wait
def test_capture_missing_ant_port_before_key(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.delenv("EFFORTFACE_ANT_NETWORK_KEY", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    line = _one_error_line(capsys, ["capture", "--port", tmp_path / "ttyNOPE", "--protocol", "ant", "--no-video",
                                    "--participant", "P01", *BODY, "--out", tmp_path / "out", "--duration", "1"])
    assert f"--port {tmp_path / 'ttyNOPE'}: expected a serial port, found no such device" in line


@pytest.mark.parametrize("wait", ["-1", "nan", "inf", "0"])
def test_replay_wait_must_be_positive_and_finite(tmp_path, capsys, wait: str) -> None:
    log = tmp_path / "a.serlog"
    SerlogWriter(log, {"protocol": "hxm"}).close()
    line = _one_error_line(capsys, ["replay", log, "--wait", wait])
    assert "--wait: expected seconds above 0" in line
