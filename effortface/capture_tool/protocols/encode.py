"""Encoders: turn heart-rate values into the byte streams the straps send.

The inverse of the decoders in this package, for round-trip tests and for the sample-lab generator
(simulated beats -> realistic byte streams). Every function returns complete, valid frames; corrupt
them on purpose afterwards if a test needs it.
"""

from __future__ import annotations

from collections.abc import Sequence

from effortface.capture_tool.protocols.ant import (
    EXT_CHANNEL_ID,
    HRM_DEVICE_TYPE,
    MSG_BROADCAST,
    MSG_CHANNEL_EVENT,
    SYNC,
    ant_checksum,
)
from effortface.capture_tool.protocols.hxm import HXM_DLC, MSG_HXM, N_TIMESTAMPS, STX, crc8


def encode_ant_frame(msg_id: int, data: bytes) -> bytes:
    """Frame one ANT message: ``A4 LEN ID DATA XOR``.

    Parameters
    ----------
    msg_id : int
        Message id (e.g. 0x4E broadcast, 0x4A reset).
    data : bytes
        Message content (1..255 bytes).

    Returns
    -------
    bytes
    """
    if not 0 < len(data) < 256 or not 0 <= msg_id < 256:
        raise ValueError(f"ANT message: expected 1..255 data bytes and an id < 256, "
                         f"found {len(data)} bytes, id {msg_id}")
    head = bytes([SYNC, len(data), msg_id]) + bytes(data)
    return head + bytes([ant_checksum(head)])


def encode_ant_broadcast(
    page: int,
    toggle: int,
    beat_time_1024: int,
    beat_count: int,
    hr_bpm: int,
    *,
    page_bytes: bytes = b"\xff\xff\xff",
    prev_beat_time_1024: int | None = None,
    extended_device: int | None = None,
    device_type: int = HRM_DEVICE_TYPE,
    trans_type: int = 1,
    channel: int = 0,
) -> bytes:
    """Frame an ANT+ heart-rate broadcast (message 0x4E), plain or extended.

    Parameters
    ----------
    page : int
        Data page 0..127 (4 carries ``prev_beat_time_1024``).
    toggle : int
        Toggle bit (0/1): flips every 4 messages on a real strap.
    beat_time_1024 : int
        Last beat event time in 1/1024 s (wrapped to 16 bits here).
    beat_count : int
        Beat counter (wrapped to 8 bits here).
    hr_bpm : int
        Computed heart rate, 0 = invalid.
    page_bytes : bytes
        Bytes 1-3 of the payload (page 4 uses only the first: its manufacturer-specific byte).
    prev_beat_time_1024 : int, optional
        Page 4's previous beat event time (1/1024 s).
    extended_device : int, optional
        Device number: append an extended trailer (flag 0x80, device number, type, trans type).
    device_type, trans_type, channel : int
        Channel id fields and channel number.

    Returns
    -------
    bytes
    """
    if page == 4:
        prev = (beat_time_1024 if prev_beat_time_1024 is None else prev_beat_time_1024) & 0xFFFF
        page_bytes = bytes(page_bytes[:1]) + prev.to_bytes(2, "little")  # b1: manufacturer byte
    t = beat_time_1024 & 0xFFFF
    payload = bytes([(page & 0x7F) | ((toggle & 1) << 7)]) + bytes(page_bytes[:3])
    payload += t.to_bytes(2, "little") + bytes([beat_count & 0xFF, int(hr_bpm) & 0xFF])
    data = bytes([channel]) + payload
    if extended_device is not None:
        data += bytes([EXT_CHANNEL_ID]) + (extended_device & 0xFFFF).to_bytes(2, "little")
        data += bytes([device_type, trans_type])
    return encode_ant_frame(MSG_BROADCAST, data)


def encode_ant_channel_event(code: int, channel: int = 0, msg_id: int = 1) -> bytes:
    """Frame a channel event (``msg_id`` 1) or a response to ``msg_id`` with ``code``."""
    return encode_ant_frame(MSG_CHANNEL_EVENT, bytes([channel, msg_id, code]))


def encode_hxm_packet(
    hr_bpm: int,
    beat_no: int,
    beat_ts_ms: Sequence[int],
    *,
    battery_pct: int = 100,
    distance_m: float = 0.0,
    speed_m_per_s: float = 0.0,
    strides: int = 0,
) -> bytes:
    """Frame a Zephyr HxM general packet ``02 26 37 payload[55] CRC8 03``.

    Parameters
    ----------
    hr_bpm : int
        Heart rate (0 = no contact).
    beat_no : int
        Heartbeat number of the newest beat (wrapped to 8 bits here).
    beat_ts_ms : sequence of 15 int
        Rolling ms timestamps of the last 15 beats, newest first (wrapped to 16 bits here).
    battery_pct, distance_m, speed_m_per_s, strides
        The other fields (distance in 1/16 m, speed in 1/256 m/s on the wire).

    Returns
    -------
    bytes
        60 bytes.
    """
    if len(beat_ts_ms) != N_TIMESTAMPS:
        raise ValueError(f"beat_ts_ms: expected {N_TIMESTAMPS} timestamps, found {len(beat_ts_ms)}")
    p = bytearray(HXM_DLC)
    p[0:8] = bytes([0x1A, 0x00, 0x31, 0x66, 0x50, 0x00, 0x31, 0x64])  # ids of the real HxM capture
    p[8], p[9], p[10] = battery_pct, int(hr_bpm) & 0xFF, beat_no & 0xFF
    for i, ts in enumerate(beat_ts_ms):
        p[11 + 2 * i : 13 + 2 * i] = (int(ts) & 0xFFFF).to_bytes(2, "little")
    p[47:49] = (round(distance_m * 16) & 0xFFFF).to_bytes(2, "little")
    p[49:51] = (round(speed_m_per_s * 256) & 0xFFFF).to_bytes(2, "little")
    p[51] = strides & 0xFF
    return encode_zephyr_frame(MSG_HXM, bytes(p))


def encode_zephyr_frame(msg_id: int, payload: bytes, terminator: int = 0x03) -> bytes:
    """Frame any message of the Zephyr family: ``STX id DLC payload CRC8 terminator``."""
    if len(payload) > 128:
        raise ValueError(f"Zephyr payload: expected at most 128 bytes, found {len(payload)}")
    return bytes([STX, msg_id, len(payload)]) + payload + bytes([crc8(payload), terminator])


def hxm_stream(beat_times_ms: Sequence[float], hr_bpm: Sequence[int], packet_period_ms: float = 1000.0,
               ) -> list[tuple[float, bytes]]:
    """HxM packets for a beat sequence, one per ``packet_period_ms``: ``[(t_ms, packet), ...]``.

    Parameters
    ----------
    beat_times_ms : sequence of float
        Times of successive beats (ms, increasing); the first one is heartbeat number 1.
    hr_bpm : sequence of int
        Heart rate to report in each packet (one per packet; the last value is reused).
    packet_period_ms : float
        Interval between packets (the HxM sends one per second).

    Returns
    -------
    list of (float, bytes)
    """
    out: list[tuple[float, bytes]] = []
    t, k, n_beats = packet_period_ms, 0, 0
    while n_beats < len(beat_times_ms):
        while n_beats < len(beat_times_ms) and beat_times_ms[n_beats] <= t:
            n_beats += 1
        recent = [int(beat_times_ms[i]) if i >= 0 else 0 for i in range(n_beats - 1, n_beats - 16, -1)]
        hr = hr_bpm[min(k, len(hr_bpm) - 1)] if hr_bpm else 0
        out.append((t, encode_hxm_packet(hr, n_beats, recent)))
        t, k = t + packet_period_ms, k + 1
    return out


def encode_hrmi_reply(status: int, count: int, hr_values: Sequence[int]) -> bytes:
    """An HRMI reply line ``<status> <count> <hr1> ... <hrn>\\r`` (newest value first)."""
    if not hr_values:
        raise ValueError("hr_values: expected at least one value, found none")
    fields = [status & 0xFF, count & 0xFF, *(int(v) for v in hr_values)]
    return " ".join(str(f) for f in fields).encode("ascii") + b"\r"


def encode_line(hr_bpm: float | None = None, rr_ms: float | None = None, *, style: str = "csv") -> bytes:
    """One text line for the ``lines`` protocol.

    Parameters
    ----------
    hr_bpm : float, optional
        Heart rate (0 or None writes ``0``, which decodes as invalid).
    rr_ms : float, optional
        Inter-beat interval.
    style : {"csv", "hr", "pulsesensor"}
        ``"csv"``: ``72,833``; ``"hr"``: ``HR:72``; ``"pulsesensor"``: ``B72\\nQ833``.

    Returns
    -------
    bytes
        The line(s), each ending in ``\\r\\n``.
    """
    hr = "0" if not hr_bpm else f"{hr_bpm:g}"
    if style == "csv":
        text = hr if rr_ms is None else f"{hr},{rr_ms:g}"
    elif style == "hr":
        text = f"HR:{hr}"
    elif style == "pulsesensor":
        text = f"B{hr}" if rr_ms is None else f"B{hr}\r\nQ{int(round(rr_ms))}"
    else:
        raise ValueError(f"style: expected 'csv', 'hr' or 'pulsesensor', found {style!r}")
    return text.encode("ascii") + b"\r\n"
