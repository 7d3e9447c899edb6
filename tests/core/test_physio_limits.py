"""Issue 17, cases 6 and 9: impossible values never pass as valid samples (one table of limits,
applied where samples are born, counted), and codes / labels / raters are whole-string matches."""

from __future__ import annotations

import pytest

from effortface.annotate.annotate_session import check_rater
from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.protocols.encode import encode_ant_broadcast, encode_hxm_packet, encode_line
from effortface.core.session.folder import check_participant_code, make_session_id, parse_session_id
from effortface.core.errors import UserError
from effortface.core.physio_limits import HR_BPM, RR_MS, hr_plausible, rr_plausible


def test_the_table_of_limits() -> None:
    assert HR_BPM == (20.0, 250.0) and RR_MS[1] == 3000.0
    assert not any(hr_plausible(v) for v in (None, 0, 1, 19, 251, 255, -70, float("nan")))
    assert all(hr_plausible(v) for v in (20, 72, 250))
    assert not any(rr_plausible(v) for v in (0, 150, 3001, 64_000, 99_999, float("nan")))


@pytest.mark.parametrize("hr", [1, 19, 251, 255])
def test_ant_checksum_valid_frames_with_impossible_hr_are_invalid(hr: int) -> None:
    dec = get_decoder("ant")
    stream = encode_ant_broadcast(0, 0, 1024, 1, 70) + encode_ant_broadcast(0, 1, 2048, 2, hr)
    samples = dec.feed(stream, 1.0) + dec.finish()
    assert [s.valid for s in samples] == [True, False]
    assert samples[1].hr_bpm is None and samples[1].rr_ms == (1000.0,)
    assert dec.stats.detail["implausible_hr"] == 1 and dec.stats.invalid_samples == 1


@pytest.mark.parametrize("d_time_1024", [0, 65535])  # RR 0 ms; RR 64 s (the 16-bit wrap)
def test_ant_impossible_rr_is_dropped_and_counted(d_time_1024: int) -> None:
    dec = get_decoder("ant")
    t1 = (1000 + d_time_1024) & 0xFFFF
    stream = encode_ant_broadcast(0, 0, 1000, 1, 70) + encode_ant_broadcast(0, 1, t1, 2, 70)
    samples = dec.feed(stream, 1.0)
    assert len(samples) == 2 and samples[1].rr_ms == () and samples[1].valid
    assert dec.stats.detail["implausible_rr"] == 1


@pytest.mark.parametrize("hr", [5, 252])
def test_hxm_impossible_hr_is_invalid(hr: int) -> None:
    dec = get_decoder("hxm")
    samples = dec.feed(encode_hxm_packet(hr, 1, [1000] * 15), 1.0)
    assert len(samples) == 1 and not samples[0].valid and samples[0].hr_bpm is None
    assert dec.stats.detail["implausible_hr"] == 1


@pytest.mark.parametrize("line", [b"72,00", b"72,99999", b"B72\nQ00"])  # RR 0 ms and 99,999 ms
def test_lines_impossible_rr_is_dropped(line: bytes) -> None:
    dec = get_decoder("lines")
    samples = dec.feed(line + b"\n", 1.0)
    assert len(samples) == 1 and samples[0].valid and samples[0].hr_bpm == 72 and samples[0].rr_ms == ()
    assert dec.stats.detail["implausible_rr"] == 1
    assert dec.feed(encode_line(72, 800.0), 2.0)[0].rr_ms == (800.0,)


@pytest.mark.parametrize("bad", ["P01\n", "P01\r\n", "\nP01"])
def test_codes_ending_in_a_newline_are_refused(bad: str) -> None:
    with pytest.raises(UserError, match="participant code"):
        check_participant_code(bad)


def test_labels_ids_and_raters_are_whole_string_matches() -> None:
    import datetime as dt

    with pytest.raises(UserError, match="session label"):
        make_session_id("P01", dt.datetime(2026, 1, 1), "cardio\n")
    with pytest.raises(UserError, match="session id"):
        parse_session_id("P01_20260101-100000_cardio\n")
    with pytest.raises(UserError):
        check_rater("R1\n")
    assert parse_session_id("P01_20260101-100000_cardio")[2] == "cardio"
    assert check_rater("R1") == "R1"
