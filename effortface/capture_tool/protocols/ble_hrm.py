"""Bluetooth Low Energy Heart Rate Measurement notifications (service 0x180D, characteristic 0x2A37).

What every modern chest strap (Polar H9/H10, Garmin HRM-Dual/Pro, Wahoo TICKR, Coospo, Magene) and
many watches in "broadcast heart rate" mode send. One notification (GATT Specification Supplement,
Heart Rate Measurement)::

    flags (1 byte)
      bit 0    heart rate as uint16 (else uint8)
      bits 1-2 sensor contact: 0b10 supported and not detected, 0b11 supported and detected
               (0b00, 0b01: contact detection not supported)
      bit 3    energy expended present (uint16, kJ, accumulated)
      bit 4    R-R intervals present (uint16 each, 1/1024 s, oldest first)
      bits 5-7 reserved
    heart rate (uint8 or uint16, bpm), [energy expended], [R-R interval...]

:func:`parse_measurement` decodes one notification (pure, bytes in). The BLE link
(:mod:`effortface.capture_tool.ble_link`) delivers each notification to the serial machinery as one
frame, ``B1 E5 <length> <notification>``, so that the raw log (``serial/<device>.serlog``, each
read stamped with its arrival time), replay and ``decode`` work as for serial straps;
:class:`BleHrmDecoder` reads those frames. A notification that cannot be one (cut short, extra
bytes, reserved flag bits set, a flipped flags byte) is counted (``bad_notification`` and a reason)
and skipped; a strap that reports no skin contact gives a row with ``valid=0``.
"""

from __future__ import annotations

import dataclasses

from effortface.capture_tool.protocols import Decoder, HrSample

#: frame marker the BLE link puts before each notification
SYNC = b"\xb1\xe5"
#: longest notification taken (ATT_MTU 247 - 3); a longer length byte is garbage
MAX_NOTIFICATION = 244
#: R-R unit of 0x2A37, ms
RR_UNIT_MS = 1000.0 / 1024.0


class NotificationError(ValueError):
    """A notification that is not a Heart Rate Measurement; ``reason`` names what is wrong."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclasses.dataclass(frozen=True)
class HeartRateMeasurement:
    """One decoded 0x2A37 notification.

    Attributes
    ----------
    hr_bpm : int
        Heart rate as sent (0 when the strap has none yet).
    contact : bool or None
        Skin contact detected (None: the strap does not report contact).
    energy_kj : int or None
        Accumulated energy expended, when sent.
    rr_ms : tuple of float
        R-R intervals in ms (1/1024 s units converted), oldest first.
    """

    hr_bpm: int
    contact: bool | None
    energy_kj: int | None
    rr_ms: tuple[float, ...]


def parse_measurement(data: bytes) -> HeartRateMeasurement:
    """Decode one Heart Rate Measurement notification.

    Raises
    ------
    NotificationError
        Empty, reserved flag bits set, cut short, or bytes left over (``reason`` says which).
    """
    if not data:
        raise NotificationError("empty", "expected a flags byte, found an empty notification")
    flags = data[0]
    if flags & 0xE0:
        raise NotificationError("reserved_flags", f"expected reserved flag bits 5-7 clear, found flags 0x{flags:02x}")
    hr_size = 2 if flags & 0x01 else 1
    need = 1 + hr_size + (2 if flags & 0x08 else 0)
    if len(data) < need:
        raise NotificationError("short", f"flags 0x{flags:02x}: expected at least {need} bytes, found {len(data)}")
    hr = int.from_bytes(data[1:1 + hr_size], "little")
    energy = int.from_bytes(data[1 + hr_size:need], "little") if flags & 0x08 else None
    rest = data[need:]
    if flags & 0x10:
        if not rest or len(rest) % 2:
            raise NotificationError("bad_rr", f"flags 0x{flags:02x}: expected R-R intervals of 2 bytes each, "
                                              f"found {len(rest)} bytes")
        rr = tuple(round(int.from_bytes(rest[i:i + 2], "little") * RR_UNIT_MS, 3) for i in range(0, len(rest), 2))
    elif rest:
        raise NotificationError("extra_bytes", f"flags 0x{flags:02x}: expected {need} bytes, found {len(data)}")
    else:
        rr = ()
    contact = bool(flags & 0x02) if flags & 0x04 else None
    return HeartRateMeasurement(hr, contact, energy, rr)


def frame(notification: bytes) -> bytes:
    """The bytes the BLE link logs and the decoder reads for one notification."""
    if len(notification) > MAX_NOTIFICATION:
        raise ValueError(f"expected a notification of at most {MAX_NOTIFICATION} bytes, found {len(notification)}")
    return SYNC + bytes([len(notification)]) + notification


def build_measurement(hr_bpm: int, rr_ms: tuple[float, ...] = (), *, contact: bool | None = True,
                      energy_kj: int | None = None, hr16: bool = False) -> bytes:
    """A 0x2A37 notification (tests, replay files): the inverse of :func:`parse_measurement`."""
    flags = (0x01 if hr16 else 0) | (0x04 | (0x02 if contact else 0) if contact is not None else 0)
    flags |= (0x08 if energy_kj is not None else 0) | (0x10 if rr_ms else 0)
    out = bytes([flags]) + int(hr_bpm).to_bytes(2 if hr16 else 1, "little")
    if energy_kj is not None:
        out += int(energy_kj).to_bytes(2, "little")
    return out + b"".join(int(round(r / RR_UNIT_MS)).to_bytes(2, "little") for r in rr_ms)


class BleHrmDecoder(Decoder):
    """Decoder of framed 0x2A37 notifications (one sample per notification).

    Parameters
    ----------
    device : str
        Device identifier written in the samples.
    """

    name = "ble_hrm"

    def __init__(self, device: str = "ble") -> None:
        super().__init__()
        self.device = device
        self.energy_kj: int | None = None

    def _consume(self) -> list[HrSample]:
        out: list[HrSample] = []
        while len(self._buf) >= 3:
            start = self._buf.find(SYNC)
            if start < 0:
                self._drop(len(self._buf) - 1, "garbage")  # keep a last byte that may start a marker
                break
            if start > 0:
                self._drop(start, "garbage")
                continue
            n = self._buf[2]
            if n > MAX_NOTIFICATION:
                self._drop(1, "bad_length")
                continue
            if len(self._buf) < 3 + n:
                break
            payload = bytes(self._buf[3:3 + n])
            del self._buf[:3 + n]
            out += self._notification(payload, n + 3)
        return out

    def _notification(self, payload: bytes, n_bytes: int) -> list[HrSample]:
        try:
            m = parse_measurement(payload)
        except NotificationError as exc:
            self.stats.frames_bad += 1
            self.stats.bytes_dropped += n_bytes
            self.stats.count("bad_notification")
            self.stats.count(exc.reason)
            return []
        self.stats.frames_ok += 1
        if m.energy_kj is not None:
            self.energy_kj = m.energy_kj
        valid = m.contact is not False and m.hr_bpm > 0
        if m.contact is False:
            self.stats.count("no_contact")
        return [HrSample(self._t_s, float(m.hr_bpm) if valid else None, m.rr_ms, None, self.device, valid)]


DECODER = BleHrmDecoder
