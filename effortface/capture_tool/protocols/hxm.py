"""Zephyr HxM BT (Bluetooth SPP) and its frame family.

Every Zephyr frame is ``STX id DLC payload[DLC] CRC terminator`` with STX 0x02, DLC <= 128, CRC-8
(reflected polynomial 0x8C, init 0) over the payload and terminator ETX 0x03, ACK 0x06 or NAK 0x15.
The HxM sends one general packet (id 0x26, DLC 55) per second; its payload (offsets from the first
payload byte, little-endian)::

    0-1 firmware id   2-3 firmware version   4-5 hardware id   6-7 hardware version
    8   battery %     9   heart rate, bpm (0 = no contact)     10  heartbeat number, 8-bit
    11-40  timestamps (ms, 16-bit, rolling) of the last 15 beats, newest first
    41-46 reserved    47-48 distance, 1/16 m   49-50 speed, 1/256 m/s   51 strides   52-54 reserved

Other frames of the family (BioHarness ECG, breathing, summary, ACK/NAK...) are framed, counted per
message id in ``stats.detail`` and skipped: they are not garbage.
"""

from __future__ import annotations

import dataclasses

from effortface.capture_tool.protocols import Decoder, HrSample

STX = 0x02
TERMINATORS = (0x03, 0x06, 0x15)  # ETX, ACK, NAK
MAX_DLC = 128
MSG_HXM = 0x26
HXM_DLC = 55
N_TIMESTAMPS = 15


def _crc8_table() -> bytes:
    table = bytearray(256)
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8C if crc & 1 else crc >> 1
        table[i] = crc
    return bytes(table)


_CRC8 = _crc8_table()


def crc8(data: bytes | bytearray) -> int:
    """Zephyr CRC-8: reflected polynomial 0x8C, initial value 0, no final XOR."""
    crc = 0
    for b in data:
        crc = _CRC8[crc ^ b]
    return crc


@dataclasses.dataclass(frozen=True)
class HxmPacket:
    """The fields of one HxM general packet (message 0x26)."""

    battery_pct: int
    hr_bpm: int
    beat_no: int
    beat_ts_ms: tuple[int, ...]  # 15 rolling timestamps, newest first
    distance_m: float
    speed_m_per_s: float
    strides: int


def parse_hxm_payload(payload: bytes | bytearray) -> HxmPacket:
    """Decode the 55-byte payload of an HxM general packet.

    Parameters
    ----------
    payload : bytes
        The DLC payload bytes (without STX, id, DLC, CRC and ETX).

    Returns
    -------
    HxmPacket
    """
    p = bytes(payload)
    ts = tuple(int.from_bytes(p[11 + 2 * i : 13 + 2 * i], "little") for i in range(N_TIMESTAMPS))
    return HxmPacket(
        battery_pct=p[8],
        hr_bpm=p[9],
        beat_no=p[10],
        beat_ts_ms=ts,
        distance_m=int.from_bytes(p[47:49], "little") / 16.0,
        speed_m_per_s=int.from_bytes(p[49:51], "little") / 256.0,
        strides=p[51],
    )


class HxmDecoder(Decoder):
    """Decoder for a Zephyr HxM BT byte stream; one sample per general packet.

    ``rr_ms`` of a sample holds the intervals of beats new since the previous packet, oldest first
    (at most 14, from the 15 rolling timestamps); the first packet only sets the reference.
    """

    name = "hxm"

    def __init__(self, device: str = "hxm") -> None:
        super().__init__()
        self.device = device
        self._last_beat_no: int | None = None

    def _consume(self, eof: bool = False) -> list[HrSample]:
        out: list[HrSample] = []
        buf = self._buf
        while buf:
            if buf[0] != STX:
                i = buf.find(STX)
                n = len(buf) if i < 0 else i
                self._drop(n, "padding" if not any(buf[:n]) else "garbage")
                continue
            if len(buf) < 3:
                if eof:
                    self._drop_tail()
                    continue
                break
            dlc = buf[2]
            if dlc > MAX_DLC:
                self._bad(1, "implausible_len")
                continue
            if len(buf) < dlc + 5:
                if eof:
                    self._drop_tail()
                    continue
                break
            sample = self._frame(buf[1], dlc)
            if sample is not None:
                out.append(sample)
        return out

    def _drop_tail(self) -> None:
        """At end of stream, drop an incomplete frame up to the next STX (not a bad frame)."""
        i = self._buf.find(STX, 1)
        self._drop(len(self._buf) if i < 0 else i, "truncated_tail")

    def _bad(self, n: int, reason: str) -> None:
        self.stats.frames_bad += 1
        self._drop(n, reason)

    def _frame(self, msg_id: int, dlc: int) -> HrSample | None:
        """Check the complete frame at the buffer head; consume it or drop its STX."""
        buf = self._buf
        if buf[dlc + 4] not in TERMINATORS:
            self._bad(1, "bad_terminator")
            return None
        payload = bytes(buf[3 : 3 + dlc])
        if crc8(payload) != buf[3 + dlc]:
            self._bad(1, "bad_checksum")
            return None
        del buf[: dlc + 5]
        self.stats.frames_ok += 1
        self.stats.count(f"msg_0x{msg_id:02X}")
        if msg_id != MSG_HXM:
            return None
        if dlc != HXM_DLC:
            self.stats.count("hxm_bad_dlc")
            return None
        return self._sample(parse_hxm_payload(payload))

    def finish(self) -> list[HrSample]:
        """End of stream: resync through an incomplete tail (e.g. a lone trailing STX)."""
        return self._born(self._consume(eof=True))

    def _sample(self, pkt: HxmPacket) -> HrSample:
        rr = self._new_rr(pkt)
        valid = pkt.hr_bpm != 0
        hr = float(pkt.hr_bpm) if valid else None
        return HrSample(self._t_s, hr, rr, pkt.beat_no, self.device, valid)

    def _new_rr(self, pkt: HxmPacket) -> tuple[float, ...]:
        """Intervals ending at the beats new since the last packet (8-bit beat-number wrap)."""
        last, self._last_beat_no = self._last_beat_no, pkt.beat_no
        if last is None:
            return ()
        n_new = min((pkt.beat_no - last) & 0xFF, N_TIMESTAMPS - 1)
        ts = pkt.beat_ts_ms
        rr: list[float] = []
        for i in range(n_new - 1, -1, -1):  # oldest new beat first
            rr.append(float((ts[i] - ts[i + 1]) & 0xFFFF))  # 16-bit wrap; limits: Decoder._born
        return tuple(rr)


DECODER = HxmDecoder
