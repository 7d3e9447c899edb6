"""Text-line decoder: PulseSensor B/Q pairing, HR: and CSV lines, invalid values, garbage,
chunking and the encoder round trip."""

from __future__ import annotations

import pytest

from effortface.capture_tool.protocols import HrSample, get_decoder
from effortface.capture_tool.protocols.encode import encode_line
from tests.capture_tool._decode_helpers import CHUNKINGS, decode

PULSESENSOR = b"S512\r\nS530\r\nB72\r\nQ833\r\nS500\r\nB75\r\nQ800\r\nS490\r\n"


def test_q_attaches_its_interval_to_the_pending_beat():
    samples, dec = decode("lines", PULSESENSOR)
    assert [(s.hr_bpm, s.rr_ms) for s in samples] == [(72.0, (833.0,)), (75.0, (800.0,))]
    assert dec.stats.frames_ok == 4 and dec.stats.bytes_dropped == 0


def test_beat_is_released_by_the_next_line_or_the_end():
    samples, _ = decode("lines", b"B72\nB73\n")
    assert [(s.hr_bpm, s.rr_ms) for s in samples] == [(72.0, ()), (73.0, ())]


def test_raw_signal_line_releases_a_beat_without_interval():
    dec = get_decoder("lines")
    assert dec.feed(b"B72\n", 1.0) == []
    assert dec.feed(b"S500\n", 1.02) == [HrSample(1.0, 72.0, (), None, "lines", True)]


def test_orphan_interval_uses_the_last_hr():
    samples, dec = decode("lines", b"Q900\nHR:70\nQ850\n")
    assert [(s.hr_bpm, s.rr_ms) for s in samples] == [(70.0, ()), (70.0, (850.0,))]
    assert dec.stats.detail["orphan_ibi"] == 1


@pytest.mark.parametrize("style, hr, rr, expected", [
    ("csv", 72, 833, [(72.0, (833.0,))]),
    ("csv", 72, None, [(72.0, ())]),
    ("hr", 64.5, None, [(64.5, ())]),
    ("pulsesensor", 90, 667, [(90.0, (667.0,))]),
])
def test_encoder_round_trip(style, hr, rr, expected):
    samples, _ = decode("lines", encode_line(hr, rr, style=style))
    assert [(s.hr_bpm, s.rr_ms) for s in samples] == expected


@pytest.mark.parametrize("line", [b"0\n", b"B0\n", b"HR:300\n", encode_line(None)])
def test_zero_or_implausible_hr_is_invalid_never_zero_bpm(line):
    samples, dec = decode("lines", line)
    assert [(s.hr_bpm, s.valid) for s in samples] == [(None, False)]
    assert dec.stats.invalid_samples == 1


@pytest.mark.parametrize("chunking", CHUNKINGS)
def test_identical_output_for_every_chunking(chunking):
    data = PULSESENSOR + b"HR: 80\r\n81,740\n" + encode_line(82, 731.5)
    assert decode("lines", data, chunking)[0] == decode("lines", data)[0]


@pytest.mark.parametrize("data, counter", [
    (b"hello world\nHR:70\n", "unparsed_line"),
    (b"x" * 200 + b"\nHR:70\n", "line_too_long"),
    (b"HR:70\nHR:7", "truncated_tail"),
])
def test_bad_lines_are_counted_and_skipped(data, counter):
    for chunking in CHUNKINGS:
        samples, dec = decode("lines", data, chunking)
        assert [s.hr_bpm for s in samples] == [70.0]
        assert dec.stats.detail[counter] == 1 and dec.stats.bytes_dropped > 0


def test_encoder_rejects_unknown_style():
    with pytest.raises(ValueError, match="style: expected"):
        encode_line(70, style="json")
