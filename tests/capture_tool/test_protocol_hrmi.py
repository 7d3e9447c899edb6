"""HRMI (polled ASCII) decoder: replies, the count field against repeats, invalid readings,
garbage, chunking and the encoder round trip."""

from __future__ import annotations

import pytest

from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.protocols.encode import encode_hrmi_reply
from effortface.capture_tool.protocols.hrmi import HrmiDecoder, poll_command
from tests.capture_tool._decode_helpers import CHUNKINGS, decode

# replies to G1 once a second from a strap beating at its own pace (count = values computed)
REPLIES = [(1, 106, [79]), (1, 106, [79]), (1, 107, [80]), (1, 108, [81]), (1, 108, [81]),
           (1, 255, [90]), (1, 0, [91]), (1, 1, [92])]
STREAM = b"".join(encode_hrmi_reply(*r) for r in REPLIES)


def test_poll_bytes_are_the_get_command():
    assert HrmiDecoder.startup_bytes == HrmiDecoder.poll_bytes == b"G1\r" == poll_command(1)
    assert HrmiDecoder.poll_interval_s == 1.0
    with pytest.raises(ValueError, match="n_values: expected 1..32, found 33"):
        poll_command(33)


def test_only_new_counts_give_samples_across_the_wrap():
    samples, dec = decode("hrmi", STREAM)
    assert [(s.hr_bpm, s.beat_count) for s in samples] == [
        (79.0, 106), (80.0, 107), (81.0, 108), (90.0, 255), (91.0, 0), (92.0, 1)]
    assert dec.stats.frames_ok == len(REPLIES) and dec.stats.detail["no_new_value"] == 2
    assert {s.device for s in samples} == {"hrmi"}


def test_newest_value_of_a_long_reply_is_emitted():
    samples, _ = decode("hrmi", b"1 107 77 79 80 81 81 80\r\n")
    assert [s.hr_bpm for s in samples] == [77.0]


@pytest.mark.parametrize("reply", [encode_hrmi_reply(1, 5, [0]), encode_hrmi_reply(3, 5, [72])])
def test_no_contact_is_invalid_never_zero_bpm(reply):
    samples, dec = decode("hrmi", reply)
    assert [(s.hr_bpm, s.valid) for s in samples] == [(None, False)]
    assert dec.stats.invalid_samples == 1


def test_status_mask_can_be_disabled():
    dec = get_decoder("hrmi", invalid_status_mask=0)
    assert [s.hr_bpm for s in dec.feed(encode_hrmi_reply(3, 5, [72]))] == [72.0]


@pytest.mark.parametrize("chunking", CHUNKINGS)
def test_identical_output_for_every_chunking(chunking):
    assert decode("hrmi", STREAM, chunking)[0] == decode("hrmi", STREAM)[0]


@pytest.mark.parametrize("name, data, counter", [
    ("garbage line", b"\x00\xffG1\r" + STREAM, "unparsed_line"),
    ("echoed command", b"G1\r" + STREAM, "unparsed_line"),
    ("line too long", b"7" * 300 + b"\r" + STREAM, "line_too_long"),
    ("truncated last reply", STREAM + b"1 2 7", "truncated_tail"),
])
def test_bad_input_is_counted_and_the_next_reply_found(name, data, counter):
    for chunking in ("1", "3", "whole"):
        samples, dec = decode("hrmi", data, chunking)
        assert [s.beat_count for s in samples] == [106, 107, 108, 255, 0, 1]
        assert dec.stats.detail[counter] == 1 and dec.stats.bytes_dropped > 0


def test_encoder_needs_a_value():
    with pytest.raises(ValueError, match="at least one value"):
        encode_hrmi_reply(0, 1, [])
