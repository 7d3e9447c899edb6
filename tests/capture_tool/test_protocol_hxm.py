"""Zephyr HxM decoder on the real HxM and BioHarness captures, the corruption table, wraps and
the encoder round trip."""

from __future__ import annotations

import json

import pytest

from effortface.capture_tool.protocols.encode import encode_hxm_packet, encode_zephyr_frame, hxm_stream
from effortface.capture_tool.protocols.hxm import crc8, parse_hxm_payload
from tests.capture_tool._decode_helpers import CHUNKINGS, decode

HXM = "serial/zephyr-bt/120-second-bt-stream-hxm.dat"
BIOHARNESS = "serial/zephyr-bt/120-second-bt-stream.dat"


@pytest.fixture(scope="module")
def expected(shared_data):
    return json.loads((shared_data / "serial/expected_values.json").read_text())


@pytest.fixture(scope="module")
def hxm(shared_data):
    return decode("hxm", (shared_data / HXM).read_bytes())


def test_one_sample_per_packet(hxm, expected):
    samples, dec = hxm
    e = expected["hxm"]
    assert len(samples) == dec.stats.frames_ok == e["frames_ok"] == 142
    assert dec.stats.frames_bad == e["frames_bad"] == 0
    assert dec.stats.detail["msg_0x26"] == 142


def test_heart_rate_values(hxm, expected):
    samples, _ = hxm
    e = expected["hxm"]
    hr = [s.hr_bpm for s in samples]
    assert (min(hr), max(hr), round(sum(hr) / len(hr), 2)) == (e["hr_min"], e["hr_max"], e["hr_mean"])
    assert hr[:10] == e["hr_first10"]
    assert (samples[0].beat_count, samples[-1].beat_count) == (101, 52)  # 255 -> 0 wrap on the way
    assert samples[-1].hr_bpm == e["last"]["hr"]
    assert {s.device for s in samples} == {"hxm"} and all(s.valid for s in samples)


def test_rr_intervals(hxm, expected):
    samples, _ = hxm
    e = expected["hxm"]
    rr = [r for s in samples for r in s.rr_ms]
    assert len(rr) == e["n_rr"] == 207
    assert rr[:10] == e["rr_ms_first10"]
    assert (min(rr), max(rr), round(sum(rr) / len(rr), 1)) == (
        e["rr_ms_min"], e["rr_ms_max"], e["rr_ms_mean"])
    assert samples[0].rr_ms == ()  # the first packet only sets the reference beat


def test_lone_trailing_stx_is_ignored(shared_data):
    blob = (shared_data / HXM).read_bytes()
    assert blob[-1:] == b"\x02"
    samples, dec = decode("hxm", blob[:-1])
    with_stx, dec2 = decode("hxm", blob)
    assert with_stx == samples
    assert dec2.stats.detail["truncated_tail"] == 1 and dec2.stats.bytes_dropped == 1
    assert "truncated_tail" not in dec.stats.detail


def test_first_packet_fields(shared_data, expected):
    blob = (shared_data / HXM).read_bytes()
    assert crc8(blob[3:58]) == blob[58] and blob[59] == 0x03
    pkt = parse_hxm_payload(blob[3:58])
    first = expected["hxm"]["first"]
    assert (pkt.battery_pct, pkt.hr_bpm, pkt.beat_no) == (first["battery"], first["hr"], first["beat_no"])
    assert list(pkt.beat_ts_ms[:3]) == expected["hxm"]["first_ts_newest3"]
    last = parse_hxm_payload(blob[-58:-3])  # the last packet, before the lone STX
    assert (last.distance_m, last.speed_m_per_s, last.strides) == (129.6875, 0.0, 81)


def test_bioharness_frames_are_skipped_cleanly(shared_data, expected):
    samples, dec = decode("hxm", (shared_data / BIOHARNESS).read_bytes())
    e = expected["bioharness"]
    assert samples == []
    assert dec.stats.frames_ok == e["frames_ok"] == 1479
    assert dec.stats.frames_bad == e["crc_or_framing_rejects"] == 0
    counted = {k[4:].lower(): v for k, v in dec.stats.detail.items() if k.startswith("msg_0x")}
    assert counted == e["msg_ids"]
    assert dec.stats.detail.get("garbage", 0) == 0


@pytest.mark.parametrize("chunking", CHUNKINGS)
@pytest.mark.parametrize("path", [HXM, BIOHARNESS])
def test_identical_output_for_every_chunking(shared_data, path, chunking):
    samples, dec = decode("hxm", (shared_data / path).read_bytes(), chunking)
    whole, whole_dec = decode("hxm", (shared_data / path).read_bytes())
    assert samples == whole and dec.stats == whole_dec.stats


# -- corruption table -------------------------------------------------------------------------
def _packets(n: int = 5) -> list[bytes]:
    return [encode_hxm_packet(70 + k, 10 + k, [1000 * (10 + k - i) for i in range(15)]) for k in range(n)]


GOOD = _packets()
HR_ALL = [70.0, 71.0, 72.0, 73.0, 74.0]
FLIP = GOOD[2][:20] + bytes([GOOD[2][20] ^ 0x40]) + GOOD[2][21:]
CORRUPTIONS = {
    "garbage prefix": (b"\x02\x26\xffjunk\x02" + b"".join(GOOD), HR_ALL, "garbage"),
    "flipped payload bit": (b"".join(GOOD[:2] + [FLIP] + GOOD[3:]), HR_ALL[:2] + HR_ALL[3:],
                            "bad_checksum"),
    "zero padding": (b"".join(p + b"\x00" * 9 for p in GOOD), HR_ALL, "padding"),
    "truncated last frame": (b"".join(GOOD) + GOOD[0][:30], HR_ALL, "truncated_tail"),
    "truncated mid-stream": (b"".join(GOOD[:2] + [GOOD[2][:25]] + GOOD[3:]),
                             HR_ALL[:2] + HR_ALL[3:], "bad_terminator"),
    "implausible DLC": (b"".join(GOOD[:2]) + b"\x02\x26\xf0" + b"".join(GOOD[2:]), HR_ALL,
                        "implausible_len"),
    "bad terminator": (b"".join(GOOD[:2] + [GOOD[2][:-1] + b"\x7f"] + GOOD[3:]),
                       HR_ALL[:2] + HR_ALL[3:], "bad_terminator"),
}


@pytest.mark.parametrize("chunking", ["1", "whole"])
@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_corruption_is_dropped_counted_and_resynced(name, chunking):
    data, hr, counter = CORRUPTIONS[name]
    samples, dec = decode("hxm", data, chunking)
    assert [s.hr_bpm for s in samples] == hr
    assert dec.stats.detail[counter] >= 1 and dec.stats.bytes_dropped > 0


def test_rr_after_a_dropped_packet_still_counts_every_beat():
    samples, _ = decode("hxm", b"".join(GOOD[:2] + GOOD[3:]))
    assert [s.rr_ms for s in samples] == [(), (1000.0,), (1000.0, 1000.0), (1000.0,)]


def test_contact_loss_is_invalid_never_zero_bpm():
    samples, dec = decode("hxm", encode_hxm_packet(0, 5, [0] * 15))
    assert [(s.hr_bpm, s.valid) for s in samples] == [(None, False)]
    assert dec.stats.invalid_samples == 1


def test_ack_nak_and_other_ids_are_counted_not_garbage():
    data = (encode_zephyr_frame(0x16, b"", 0x06) + encode_zephyr_frame(0x23, b"", 0x15)
            + encode_zephyr_frame(0x22, bytes(128)) + GOOD[0])
    samples, dec = decode("hxm", data, "1")
    assert len(samples) == 1 and dec.stats.frames_ok == 4 and dec.stats.bytes_dropped == 0
    assert {k: v for k, v in dec.stats.detail.items() if k.startswith("msg")} == {
        "msg_0x16": 1, "msg_0x23": 1, "msg_0x22": 1, "msg_0x26": 1}


def test_beat_number_and_timestamp_wraps_round_trip():
    """300 beats of 300..800 ms starting at 60 s: both the 8-bit beat number and the 16-bit ms
    timestamps wrap; the decoded RR are exactly the simulated intervals."""
    intervals = [300 + (k * 37) % 500 for k in range(300)]
    times, t = [], 60000
    for dt in intervals:
        t += dt
        times.append(t)
    packets = hxm_stream(times, [80])
    samples, dec = decode("hxm", b"".join(p for _, p in packets), "random")
    rr = [r for s in samples for r in s.rr_ms]
    assert rr == [float(x) for x in intervals[len(intervals) - len(rr):]]
    assert len(rr) >= 300 - 3  # only beats before the first packet's reference are unseen
    assert dec.stats.frames_bad == 0


@pytest.mark.parametrize("bad, message", [
    (dict(beat_ts_ms=[0] * 14), "15 timestamps"),
])
def test_encoder_rejects_bad_input(bad, message):
    args = dict(hr_bpm=70, beat_no=1, beat_ts_ms=[0] * 15) | bad
    with pytest.raises(ValueError, match=message):
        encode_hxm_packet(**args)
