"""ANT+ heart rate through a USB ANT stick (serial framing ``A4 LEN ID DATA[LEN] XOR``).

Frame layout (ANT Message Protocol and Usage, section 7)::

    A4        sync
    LEN       number of DATA bytes (the message id is not counted)
    ID        message id: 0x4E broadcast, 0x4F acknowledged, 0x40 channel response/event, 0x6F startup
    DATA      LEN bytes; for 0x4E/0x4F: channel, 8-byte payload, then an optional extended trailer
    XOR       XOR of every byte from the sync to the last data byte

Extended trailer (flag byte after the payload): ``0x80`` channel id (device number LE16, device type,
transmission type), ``0x40`` RSSI block and ``0x20`` RX timestamp; only the channel id is used, the
rest is tolerated. Only device type :attr:`AntDecoder.device_type` (120, heart-rate monitor) yields
samples; a plain broadcast (no channel id) comes from the device the channel was opened for and is
taken as a heart-rate monitor.

Heart-rate payload (ANT+ HRM device profile), every page::

    b0  page number (bits 0-6) | toggle bit (bit 7)     b4-b5  beat event time, LE16, 1/1024 s
    b1-b3  page specific (page 4: b2-b3 previous beat)  b6     beat count, 8-bit
                                                        b7     computed heart rate, bpm (0 = invalid)

A strap repeats the same payload (about 4 Hz) until the next beat: one :class:`HrSample` is emitted
per NEW beat event, with RR from successive beat event times (wraps of both counters handled) and,
when beats were missed, from page 4's previous beat time.
"""

from __future__ import annotations

import dataclasses

from effortface.capture_tool.protocols import Decoder, HrSample

SYNC = 0xA4
#: largest DATA length we accept: an extended broadcast with every trailer is 20 bytes; longer
#: LEN values come from corruption, and waiting for them would stall the stream
MAX_LEN = 32
HRM_DEVICE_TYPE = 120
MSG_BROADCAST, MSG_ACKNOWLEDGED, MSG_CHANNEL_EVENT, MSG_STARTUP = 0x4E, 0x4F, 0x40, 0x6F
MSG_OPEN_CHANNEL, MSG_CLOSE_CHANNEL = 0x4B, 0x4C
EXT_CHANNEL_ID = 0x80

#: channel event codes (message 0x40 with message id 1)
CHANNEL_EVENTS = {
    0x01: "EVENT_RX_SEARCH_TIMEOUT",
    0x02: "EVENT_RX_FAIL",
    0x03: "EVENT_TX",
    0x04: "EVENT_TRANSFER_RX_FAILED",
    0x05: "EVENT_TRANSFER_TX_COMPLETED",
    0x06: "EVENT_TRANSFER_TX_FAILED",
    0x07: "EVENT_CHANNEL_CLOSED",
    0x08: "EVENT_RX_FAIL_GO_TO_SEARCH",
    0x09: "EVENT_CHANNEL_COLLISION",
}
#: beats further apart than this (host clock) may hide a 64 s beat-time wrap: no RR across them
MAX_BEAT_GAP_S = 60.0


def ant_checksum(frame: bytes | bytearray) -> int:
    """XOR of every byte of ``frame`` (sync through last data byte)."""
    x = 0
    for b in frame:
        x ^= b
    return x


@dataclasses.dataclass(frozen=True)
class HrPage:
    """One decoded ANT+ heart-rate payload (8 bytes)."""

    page: int
    toggle: int
    beat_time_1024: int
    beat_count: int
    hr_bpm: int
    prev_beat_time_1024: int | None = None  # page 4 only

    @property
    def page4_rr_ms(self) -> float | None:
        """Beat time minus previous beat time (page 4), in ms; None on other pages."""
        if self.prev_beat_time_1024 is None:
            return None
        return ((self.beat_time_1024 - self.prev_beat_time_1024) & 0xFFFF) * 1000.0 / 1024.0


def parse_hr_page(payload: bytes | bytearray) -> HrPage:
    """Decode an 8-byte ANT+ heart-rate payload.

    Parameters
    ----------
    payload : bytes
        The 8 data bytes of a broadcast (after the channel number).

    Returns
    -------
    HrPage
    """
    page = payload[0] & 0x7F
    prev = payload[2] | (payload[3] << 8) if page == 4 else None
    return HrPage(
        page=page,
        toggle=payload[0] >> 7,
        beat_time_1024=payload[4] | (payload[5] << 8),
        beat_count=payload[6],
        hr_bpm=payload[7],
        prev_beat_time_1024=prev,
    )


@dataclasses.dataclass
class _BeatState:
    """Last beat event seen from one device."""

    beat_count: int
    beat_time_1024: int
    t_s: float
    valid: bool


class AntDecoder(Decoder):
    """Decoder for the byte stream of a USB ANT stick with a heart-rate channel.

    Parameters
    ----------
    device_type : int
        ANT+ device type that yields samples in extended messages (120 = heart-rate monitor).

    Attributes
    ----------
    state : str
        Link state: ``"unknown"``, ``"searching"``, ``"tracking"``, ``"lost"`` or ``"closed"``.
        Every change is also a :class:`~effortface.capture_tool.protocols.DeviceEvent` of kind ``"link"``.
    """

    name = "ant"

    def __init__(self, device_type: int = HRM_DEVICE_TYPE) -> None:
        super().__init__()
        self.device_type = int(device_type)
        self.state = "unknown"
        self._opened_once = False
        self._beats: dict[str, _BeatState] = {}

    # -- framing -------------------------------------------------------------------------
    def _consume(self, eof: bool = False) -> list[HrSample]:
        out: list[HrSample] = []
        buf = self._buf
        while buf:
            if buf[0] != SYNC:
                self._skip_to_sync()
                continue
            if len(buf) < 2:
                if eof:
                    self._drop_tail()
                    continue
                break
            n = buf[1]
            if n == 0 or n > MAX_LEN:
                self.stats.frames_bad += 1
                self._drop(1, "implausible_len")
                continue
            if len(buf) < n + 4:
                if eof:
                    self._drop_tail()
                    continue
                break
            if ant_checksum(buf[: n + 3]) != buf[n + 3]:
                self.stats.frames_bad += 1
                self._drop(1, "bad_checksum")
                continue
            msg_id, data = buf[2], bytes(buf[3 : n + 3])
            del buf[: n + 4]
            self.stats.frames_ok += 1
            out += self._on_message(msg_id, data)
        return out

    def _drop_tail(self) -> None:
        """At end of stream, drop an incomplete frame up to the next sync (not a bad frame)."""
        i = self._buf.find(SYNC, 1)
        self._drop(len(self._buf) if i < 0 else i, "truncated_tail")

    def _skip_to_sync(self) -> None:
        """Drop bytes up to the next sync byte; zero runs are USB padding, the rest garbage."""
        i = self._buf.find(SYNC)
        n = len(self._buf) if i < 0 else i
        reason = "padding" if not any(self._buf[:n]) else "garbage"
        self._drop(n, reason)

    def finish(self) -> list[HrSample]:
        """End of stream: resync through an incomplete tail (a real frame may follow a false sync)."""
        return self._born(self._consume(eof=True))

    # -- messages ------------------------------------------------------------------------
    def _on_message(self, msg_id: int, data: bytes) -> list[HrSample]:
        if msg_id in (MSG_BROADCAST, MSG_ACKNOWLEDGED) and len(data) >= 9:
            return self._on_data(data)
        if msg_id == MSG_CHANNEL_EVENT and len(data) >= 3:
            self._on_channel_response(data[1], data[2])
        elif msg_id == MSG_STARTUP:
            self.stats.count("startup")
            self._set_state("closed", "stick reset")
        else:
            self.stats.count(f"msg_0x{msg_id:02X}")
        return []

    def _on_data(self, data: bytes) -> list[HrSample]:
        device = "ant"
        ext = data[9:]
        if ext and ext[0] & EXT_CHANNEL_ID and len(ext) >= 5:
            dev_type = ext[3] & 0x7F  # bit 7 is the pairing bit
            if dev_type != self.device_type:
                self.stats.count("other_device_type")
                return []
            device = f"ant:{ext[1] | (ext[2] << 8)}"
        if self.state != "tracking":
            self._set_state("tracking", device)
        return self._on_page(parse_hr_page(data[1:9]), device)

    def _on_channel_response(self, msg_id: int, code: int) -> None:
        if msg_id == 1:
            self._on_channel_event(code)
        elif code != 0:
            self.stats.count("response_error")
            self._emit_event("link", "error", f"message 0x{msg_id:02X}: response code 0x{code:02X}")
        elif msg_id == MSG_OPEN_CHANNEL:
            self._set_state("searching", "re-opened" if self._opened_once else "opened")
            self._opened_once = True
        elif msg_id == MSG_CLOSE_CHANNEL:
            self.stats.count("close_requested")

    def _on_channel_event(self, code: int) -> None:
        name = CHANNEL_EVENTS.get(code, f"EVENT_0x{code:02X}")
        self.stats.count(name.lower())
        if code == 0x08:
            self._set_state("lost", name)
        elif code == 0x01:
            self._emit_event("link", "search_timeout", name)
        elif code == 0x07:
            self._set_state("closed", name)

    def _set_state(self, state: str, detail: str) -> None:
        if state != self.state:
            self.state = state
            self._emit_event("link", state, detail)

    # -- beats ---------------------------------------------------------------------------
    def _on_page(self, page: HrPage, device: str) -> list[HrSample]:
        last = self._beats.get(device)
        valid = page.hr_bpm != 0
        if last is not None and (last.beat_count, last.beat_time_1024) == (
            page.beat_count,
            page.beat_time_1024,
        ):
            return self._repeated(last, page, device, valid)
        rr = self._rr_ms(last, page) if last is not None else ()
        self._beats[device] = _BeatState(page.beat_count, page.beat_time_1024, self._t_s, valid)
        self.stats.count("beats")
        hr = float(page.hr_bpm) if valid else None
        return [HrSample(self._t_s, hr, rr, page.beat_count, device, valid)]

    def _repeated(self, last: _BeatState, page: HrPage, device: str, valid: bool) -> list[HrSample]:
        """A repeat of the last beat event: nothing new, unless the HR just turned invalid."""
        if last.valid and not valid:  # contact lost without a new beat: say so once
            last.valid = False
            return [HrSample(self._t_s, None, (), page.beat_count, device, False)]
        self.stats.count("repeated_messages")
        return []

    def _rr_ms(self, last: _BeatState, page: HrPage) -> tuple[float, ...]:
        """RR intervals ending at this beat event, oldest first."""
        d_count = (page.beat_count - last.beat_count) & 0xFF
        d_time = (page.beat_time_1024 - last.beat_time_1024) & 0xFFFF
        if page.beat_time_1024 < last.beat_time_1024:
            self.stats.count("beat_time_wraps")
        if d_count == 0 or self._t_s - last.t_s > MAX_BEAT_GAP_S:
            self.stats.count("beat_resync")
            return ()
        if d_count == 1:
            return (d_time * 1000.0 / 1024.0,)
        self.stats.count("missed_beats", d_count - 1)
        p4, prev = page.page4_rr_ms, page.prev_beat_time_1024
        if p4 is None or prev is None:  # not page 4 (both are None then)
            return ()
        if d_count == 2:  # last event -> previous beat -> this beat: both intervals are known
            earlier = ((prev - last.beat_time_1024) & 0xFFFF) * 1000.0 / 1024.0
            return (earlier, p4)
        return (p4,)


DECODER = AntDecoder
