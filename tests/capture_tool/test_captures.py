"""read_timed_capture on the real captures (zephyr timing, derived ANT timing, libant pcaps),
on .serlog and plain raw files, and its refusals."""

from __future__ import annotations

import collections
import csv
import struct

import pytest

from effortface.capture_tool.captures import find_timing_file, read_timed_capture
from effortface.core.errors import SessionFormatError, UserError
from effortface.capture_tool.serlog import SerlogWriter

ZEPHYR = "serial/zephyr-bt/120-second-bt-stream-hxm.dat"


def test_zephyr_chunks_follow_the_timing_csv(shared_data):
    chunks = read_timed_capture(shared_data / ZEPHYR)
    blob = (shared_data / ZEPHYR).read_bytes()
    assert b"".join(c for _, c in chunks) == blob  # nothing lost, nothing reordered
    assert len(chunks) == 156 + 1  # 156 timed reads + the lone trailing byte past the last offset
    sizes = collections.Counter(len(c) for _, c in chunks[:-1])
    # the README's "60 B x125" counts the gaps between rows; the first read is 60 B too:
    # 126 * 60 + 15 * 1 + 14 * 59 + 119 = 8520, the last logged offset
    assert sizes == {60: 126, 1: 15, 59: 14, 119: 1}
    assert chunks[0][0] == 0.0
    assert chunks[-1][0] == pytest.approx(1348671345.284 - 1348671204.717)
    assert all(b[0] <= a[0] for a, b in zip(chunks[1:], chunks))  # times never go back


@pytest.mark.parametrize("name, frame_len", [
    ("njcant_hrm1_ant_broadcast.bin", 13),
    ("njcant_hrm1_ant_broadcast_ext.bin", 18),
])
def test_derived_ant_streams_use_their_offset_column(shared_data, name, frame_len):
    path = shared_data / "serial/derived" / name
    chunks = read_timed_capture(path)
    assert find_timing_file(path).name == "njcant_hrm1_ant_timing.csv"
    assert len(chunks) == 2822 and {len(c) for _, c in chunks} == {frame_len}
    with open(find_timing_file(path), newline="") as fh:
        times = [float(r["host_time_s"]) for r in csv.DictReader(fh)]
    assert [t for t, _ in chunks] == pytest.approx([t - times[0] for t in times], abs=1e-6)


@pytest.mark.parametrize("name, n_records", [("demo-capture-1.pcap", 1888), ("demo-capture-2.pcap", 1522)])
def test_pcap_records_are_stick_reads(shared_data, name, n_records):
    chunks = read_timed_capture(shared_data / "serial/libant" / name)
    assert len(chunks) == n_records  # libant logs one frame per USB read
    assert all(c[0] == 0xA4 for _, c in chunks)
    assert chunks[0][0] == 0.0 and 299.0 < chunks[-1][0] < 301.0


def test_serlog_round_trip(tmp_path):
    path = tmp_path / "strap.serlog"
    with SerlogWriter(path, {"device": "hxm"}) as log:
        log.write(10.5, b"\x02\x26")
        log.write_event(10.7, "gap", "unplugged")
        log.write(11.0, b"\x37")
    assert read_timed_capture(path) == [(10.5, b"\x02\x26"), (11.0, b"\x37")]  # session time kept


def test_raw_file_without_timing_is_one_chunk(tmp_path):
    path = tmp_path / "strap.bin"
    path.write_bytes(b"HR:70\n")
    assert read_timed_capture(path) == [(0.0, b"HR:70\n")]


def test_cut_pcap_keeps_whole_records(shared_data, tmp_path):
    blob = (shared_data / "serial/libant/demo-capture-1.pcap").read_bytes()
    path = tmp_path / "cut.pcap"
    path.write_bytes(blob[:-5])
    assert len(read_timed_capture(path)) == 1887


@pytest.mark.parametrize("message, name, content", [
    (r"notes\.csv: expected a \.serlog, \.pcap or raw .* found suffix '\.csv'", "notes.csv", b"1,2"),
    (r"x\.pcapng: expected a libpcap file, found pcapng", "x.pcapng", b"\x0a\x0d\x0d\x0a" + bytes(20)),
    (r"short\.pcap: expected a 24-byte pcap header, found 10 bytes", "short.pcap",
     b"\xd4\xc3\xb2\xa1" + bytes(6)),
])
def test_unknown_or_broken_formats_are_refused_by_name(tmp_path, message, name, content):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(UserError, match=message):
        read_timed_capture(tmp_path / name)


def test_missing_file_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match=r"nope\.dat: expected a readable capture file"):
        read_timed_capture(tmp_path / "nope.dat")


def test_malformed_timing_row_names_file_and_line(tmp_path):
    (tmp_path / "s.dat").write_bytes(bytes(10))
    (tmp_path / "s-timing.csv").write_text("1.0,5\n2.0,five\n")
    with pytest.raises(SessionFormatError, match=r"s-timing\.csv: line 2: expected 'time,offset'"):
        read_timed_capture(tmp_path / "s.dat")


def test_pcap_big_endian_nanosecond(tmp_path):
    header = b"\xa1\xb2\x3c\x4d" + struct.pack(">HHiIII", 2, 4, 0, 0, 65535, 1)
    recs = b"".join(struct.pack(">IIII", 100, ns, 2, 2) + b"\xa4\x01" for ns in (0, 500_000_000))
    (tmp_path / "be.pcap").write_bytes(header + recs)
    assert read_timed_capture(tmp_path / "be.pcap") == [(0.0, b"\xa4\x01"), (0.5, b"\xa4\x01")]
