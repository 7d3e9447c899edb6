"""ANT+ heart-rate decoder on the real captures (njcant payloads, libant stick reads), the
corruption table, the link state machine, the encoders and the stick's open sequence."""

from __future__ import annotations

import csv
import json

import pytest

from effortface.capture_tool.captures import read_timed_capture
from effortface.core.errors import DeviceError, DeviceErrorReason, UserError
from effortface.capture_tool.protocols import ant_stick
from effortface.capture_tool.protocols.ant import parse_hr_page
from effortface.capture_tool.protocols.encode import (
    encode_ant_broadcast,
    encode_ant_channel_event,
    encode_ant_frame,
)
from tests.capture_tool._decode_helpers import CHUNKINGS, decode

PLAIN = "serial/derived/njcant_hrm1_ant_broadcast.bin"
EXT = "serial/derived/njcant_hrm1_ant_broadcast_ext.bin"


@pytest.fixture(scope="module")
def expected(shared_data):
    return json.loads((shared_data / "serial/expected_values.json").read_text())["njcant_hrm1"]


@pytest.fixture(scope="module")
def expected_rows(shared_data):
    with open(shared_data / "serial/derived/njcant_hrm1_expected.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def plain(shared_data):
    return decode("ant", (shared_data / PLAIN).read_bytes())


def test_one_sample_per_beat_event_not_per_message(plain, expected):
    samples, dec = plain
    assert dec.stats.frames_ok == expected["lines"] == 2822
    assert len(samples) == expected["unique_beat_events"] == 686
    assert dec.stats.detail["repeated_messages"] == 2822 - 686
    assert dec.stats.frames_bad == dec.stats.bytes_dropped == 0


def test_heart_rate_range_and_ends(plain, expected):
    samples, _ = plain
    hr = [s.hr_bpm for s in samples]
    assert all(s.valid for s in samples)
    assert (min(hr), max(hr)) == (expected["hr_min"], expected["hr_max"]) == (51, 80)
    assert (hr[0], hr[-1]) == (expected["hr_first"], expected["hr_last"])
    assert {s.device for s in samples} == {"ant"}  # plain broadcasts carry no device number


def test_wraps_and_missed_beats_are_counted(plain, expected):
    _, dec = plain
    assert dec.stats.detail["beat_time_wraps"] == expected["beat_time_wraps"] == 11
    assert dec.stats.detail["missed_beats"] == expected["beat_count_increments"]["2"] == 4


def test_event_time_rr_matches_expected_csv(plain, expected, expected_rows):
    samples, _ = plain
    ours = [s.rr_ms[0] for s in samples if len(s.rr_ms) == 1]
    theirs = [float(r["rr_ms_from_event_times"]) for r in expected_rows if r["rr_ms_from_event_times"]]
    assert len(ours) == len(theirs) == expected["rr_from_events_n"] == 681
    assert ours == pytest.approx(theirs, abs=1e-3)
    assert [round(x, 1) for x in ours[:5]] == expected["rr_from_events_first5_ms"]
    lo, hi, mean = expected["rr_events_min_max_mean_ms"]
    assert (round(min(ours), 1), round(max(ours), 1), round(sum(ours) / len(ours), 1)) == (lo, hi, mean)


def test_missed_beats_give_both_intervals_from_page4(plain, expected, expected_rows):
    samples, _ = plain
    two = [s for s in samples if len(s.rr_ms) == 2]
    assert [round(s.rr_ms[1], 1) for s in two] == expected["rr_page4_when_2_beats_elapsed_ms"]
    # the earlier interval plus page 4's makes the event-time difference across the missed beat
    events = [expected_rows[0]] + [r for r in expected_rows if r["new_beat"] == "1"]
    times = [int(r["beat_time_1024"]) for r in events]
    spans = [(times[i] - times[i - 1]) & 0xFFFF for i, s in enumerate(samples) if len(s.rr_ms) == 2]
    assert [sum(s.rr_ms) for s in two] == pytest.approx([x * 1000 / 1024 for x in spans])


def test_page4_rr_equals_event_rr(shared_data, plain, expected_rows):
    samples, _ = plain
    blob = (shared_data / PLAIN).read_bytes()
    frames = [blob[i : i + 13] for i in range(0, len(blob), 13)]
    new_beat = [k for k, r in enumerate(expected_rows) if r["new_beat"] == "1"]
    checked = 0
    for sample, k in zip(samples[1:], new_beat, strict=True):
        page = parse_hr_page(frames[k][4:12])
        assert (page.beat_count, page.hr_bpm) == (sample.beat_count, sample.hr_bpm)
        if page.page4_rr_ms is not None:
            assert page.page4_rr_ms == sample.rr_ms[-1]
            checked += 1
    assert checked == 672 + 4


def test_extended_stream_names_the_device(shared_data, plain):
    samples, dec = decode("ant", (shared_data / EXT).read_bytes())
    assert {s.device for s in samples} == {"ant:3425"}
    strip = [(s.hr_bpm, s.rr_ms, s.beat_count) for s in samples]
    assert strip == [(s.hr_bpm, s.rr_ms, s.beat_count) for s in plain[0]]
    assert [e.label for e in dec.pop_events()] == ["tracking"]


def test_other_device_type_yields_nothing(shared_data):
    samples, dec = decode("ant", (shared_data / EXT).read_bytes(), device_type=121)
    assert samples == []
    assert dec.stats.detail["other_device_type"] == 2822


@pytest.mark.parametrize("name, frames, responses", [
    ("demo-capture-1.pcap", 1888, 7),
    ("demo-capture-2.pcap", 1522, 9),
])
def test_libant_pcaps_parse_without_hr(shared_data, name, frames, responses):
    chunks = read_timed_capture(shared_data / "serial/libant" / name)
    samples, dec = decode("ant", b"".join(c for _, c in chunks), "whole")
    assert samples == []
    assert dec.stats.frames_ok == frames and dec.stats.frames_bad == 0
    # every 0x4E LEN 0x14 frame (flag 0xE0 trailer) parsed: a power meter and a speed sensor
    assert dec.stats.detail["other_device_type"] == frames - responses


def test_libant_invalid_message_response_is_an_event(shared_data):
    chunks = read_timed_capture(shared_data / "serial/libant/demo-capture-2.pcap")
    _, dec = decode("ant", b"".join(c for _, c in chunks))
    events = dec.pop_events()
    assert [e.value for e in events] == ["message 0x4A: response code 0x28"] * 2
    assert dec.stats.detail["response_error"] == 2


@pytest.mark.parametrize("chunking", CHUNKINGS)
@pytest.mark.parametrize("path", [PLAIN, EXT])
def test_identical_output_for_every_chunking(shared_data, plain, path, chunking):
    samples, dec = decode("ant", (shared_data / path).read_bytes(), chunking)
    whole, whole_dec = decode("ant", (shared_data / path).read_bytes())
    assert samples == whole
    assert dec.stats == whole_dec.stats


# -- corruption table -------------------------------------------------------------------------
def _beats(n: int = 6, start: int = 250, t0: int = 65000) -> list[bytes]:
    """n beat events 800 ms apart (each sent twice), crossing both counter wraps."""
    frames = []
    for k in range(n):
        t = (t0 + k * 819) & 0xFFFF
        frame = encode_ant_broadcast(4, k % 2, t, start + k, 70 + k, prev_beat_time_1024=t - 819)
        frames += [frame, frame]
    return frames


GOOD = _beats()
ALL_BEATS = [(250 + k) & 0xFF for k in range(6)]
FLIPPED = GOOD[4][:-1] + bytes([GOOD[4][-1] ^ 0xFF])
CORRUPTIONS = {
    "garbage prefix": (b"\x13\x37 junk \xa4" + b"".join(GOOD), ALL_BEATS, "garbage"),
    "flipped checksum": (b"".join(GOOD[:4] + [FLIPPED] + GOOD[6:]), ALL_BEATS[:2] + ALL_BEATS[3:],
                         "bad_checksum"),
    "zero padding": (b"".join(f + b"\x00" * 7 for f in GOOD), ALL_BEATS, "padding"),
    "truncated last frame": (b"".join(GOOD) + GOOD[0][:6], ALL_BEATS, "truncated_tail"),
    "truncated mid-stream": (b"".join(GOOD[:4] + [GOOD[4][:8]] + GOOD[6:]),
                             ALL_BEATS[:2] + ALL_BEATS[3:], "bad_checksum"),
    "implausible LEN": (b"".join(GOOD[:4]) + b"\xa4\xff\x4e" + b"".join(GOOD[4:]), ALL_BEATS,
                        "implausible_len"),
}


@pytest.mark.parametrize("chunking", ["1", "whole"])
@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_corruption_is_dropped_counted_and_resynced(name, chunking):
    data, beats, counter = CORRUPTIONS[name]
    samples, dec = decode("ant", data, chunking)
    assert [s.beat_count for s in samples] == beats
    assert dec.stats.detail[counter] >= 1
    assert dec.stats.bytes_dropped > 0


def test_rr_across_both_wraps():
    samples, _ = decode("ant", b"".join(GOOD))
    assert [s.rr_ms for s in samples[1:]] == [(819 * 1000 / 1024,)] * 5


def test_contact_loss_is_invalid_never_zero_bpm():
    frames = [encode_ant_broadcast(0, 0, 1024 * k, k, 72) for k in range(1, 4)]
    frames += [encode_ant_broadcast(0, 0, 3 * 1024, 3, 0)] * 3  # strap off: HR 0, no new beat
    frames += [encode_ant_broadcast(0, 0, 1024 * k, k, 0) for k in range(5, 7)]
    samples, dec = decode("ant", b"".join(frames))
    assert [s.valid for s in samples] == [True, True, True, False, False, False]
    assert all(s.hr_bpm is None for s in samples if not s.valid)
    assert dec.stats.invalid_samples == 3


def test_two_frames_in_one_read_vector():
    """openyou/libfitbit #7: a valid frame then the start of the next one."""
    dec_samples, dec = decode("ant", bytes.fromhex("A4094E003E610E0000000000B2A403"), "whole")
    assert dec.stats.frames_ok == 1 and dec.stats.detail["truncated_tail"] == 1
    assert [(s.hr_bpm, s.valid) for s in dec_samples] == [(None, False)]


# -- link state ------------------------------------------------------------------------------
def test_channel_events_drive_the_link_state():
    beat = encode_ant_broadcast(4, 0, 1000, 1, 70)
    stream = [
        bytes.fromhex("A4016F20EA"),  # startup after reset (python-ant PR #21)
        bytes.fromhex("A4 06 54 08 03 00 BA 36 00 71"),  # capabilities
        bytes.fromhex("A40340004600A1"),  # set network key: RESPONSE_NO_ERROR
        encode_ant_channel_event(0, msg_id=0x4B),  # open channel OK
        beat,
        bytes.fromhex("A40340000102E4"),  # EVENT_RX_FAIL (libfitbit #19)
        encode_ant_channel_event(0x08),  # EVENT_RX_FAIL_GO_TO_SEARCH
        beat,
        encode_ant_channel_event(0x01),  # EVENT_RX_SEARCH_TIMEOUT
        encode_ant_channel_event(0x07),  # EVENT_CHANNEL_CLOSED
        encode_ant_channel_event(0, msg_id=0x4B),  # re-open
    ]
    _, dec = decode("ant", b"".join(stream))
    events = [(e.kind, e.label, e.value) for e in dec.pop_events()]
    assert events == [
        ("link", "closed", "stick reset"),
        ("link", "searching", "opened"),
        ("link", "tracking", "ant"),
        ("link", "lost", "EVENT_RX_FAIL_GO_TO_SEARCH"),
        ("link", "tracking", "ant"),
        ("link", "search_timeout", "EVENT_RX_SEARCH_TIMEOUT"),
        ("link", "closed", "EVENT_CHANNEL_CLOSED"),
        ("link", "searching", "re-opened"),
    ]
    assert dec.state == "searching"
    assert dec.stats.detail["event_rx_fail"] == 1 and dec.stats.detail["msg_0x54"] == 1
    assert dec.pop_events() == []


# -- encoders --------------------------------------------------------------------------------
def test_encoder_reproduces_the_real_first_frames(shared_data):
    frame = encode_ant_broadcast(4, 1, 0xAD2B, 1, 63, prev_beat_time_1024=0xA92C, page_bytes=b"\x00")
    assert frame == bytes.fromhex("A4094E0084002CA92BAD013F5A") == (shared_data / PLAIN).read_bytes()[:13]
    ext = encode_ant_broadcast(4, 1, 0xAD2B, 1, 63, prev_beat_time_1024=0xA92C, page_bytes=b"\x00",
                               extended_device=3425, trans_type=1)
    assert ext == (shared_data / EXT).read_bytes()[:18]


def test_encoder_round_trip_through_the_decoder():
    frames = [encode_ant_broadcast(k % 5, k % 2, 900 * k, k, 60 + k, extended_device=77)
              for k in range(1, 30)]
    samples, dec = decode("ant", b"".join(frames))
    assert [(s.hr_bpm, s.beat_count, s.device) for s in samples] == [
        (60.0 + k, k, "ant:77") for k in range(1, 30)
    ]
    assert dec.stats.frames_bad == 0


def test_encode_frame_rejects_empty_data():
    with pytest.raises(ValueError, match="1..255 data bytes"):
        encode_ant_frame(0x4E, b"")


# -- real stick: open sequence and network key ------------------------------------------------
FAKE_KEY_TEXT = "00 11 22 33 44 55 66 77"  # made up: the real key is never committed


def test_open_sequence_frames():
    msgs = ant_stick.open_sequence(bytes.fromhex(FAKE_KEY_TEXT))
    assert [m[2] for m in msgs] == [0x4A, 0x46, 0x42, 0x51, 0x43, 0x45, 0x4B]
    assert msgs[0] == bytes.fromhex("A4014A00EF")  # reset (python-ant PR #21)
    assert msgs[2] == bytes.fromhex("A4 03 42 00 00 00 E5")  # assign (python-ant tests)
    assert msgs[3][3:8] == bytes([0, 0, 0, 120, 0])  # wildcard device, type 120, trans 0
    assert int.from_bytes(msgs[4][4:6], "little") == 8070 and msgs[5][4] == 57
    _, dec = decode("ant", b"".join(msgs))
    assert dec.stats.frames_ok == 7 and dec.stats.frames_bad == 0


def test_key_from_environment_wins_over_config(tmp_path):
    cfg = tmp_path / "effortface" / "config.ini"
    cfg.parent.mkdir()
    cfg.write_text("[ant]\nnetwork_key = 0x01,0x02,0x03,0x04,0x05,0x06,0x07,0x08\n")
    env = {"XDG_CONFIG_HOME": str(tmp_path)}
    assert ant_stick.load_network_key(env) == bytes(range(1, 9))
    env[ant_stick.ENV_VAR] = FAKE_KEY_TEXT
    assert ant_stick.load_network_key(env) == bytes.fromhex(FAKE_KEY_TEXT)


def test_missing_key_says_how_to_get_one(tmp_path):
    with pytest.raises(DeviceError) as info:
        ant_stick.load_network_key({"XDG_CONFIG_HOME": str(tmp_path)})
    assert info.value.reason is DeviceErrorReason.NO_KEY
    message = str(info.value)
    assert "thisisant.com" in message and ant_stick.ENV_VAR in message and "config.ini" in message
    assert "\n" not in message


@pytest.mark.parametrize("message, text", [
    (r"EFFORTFACE_ANT_NETWORK_KEY: expected .* 16 hex digits .* found 2 hex bytes", "0011"),
    (r"found 9 hex bytes", "00 11 22 33 44 55 66 77 88"),
    (r"found 7 hex bytes and 'zz'", "00 11 22 33 44 55 66 zz"),
])
def test_bad_key_names_the_variable(message, text):
    with pytest.raises(UserError, match=message):
        ant_stick.load_network_key({ant_stick.ENV_VAR: text})
