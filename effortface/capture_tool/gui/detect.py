"""Guess a strap's protocol from its first bytes (Qt-free, so it is tested without a display).

Every known decoder is fed the same bytes; the one that turns most of them into valid samples wins.
Polled protocols (HRMI) send nothing until asked, so they cannot be detected this way: the caller
keeps the user's choice when :func:`detect_protocol` returns None.
"""

from __future__ import annotations

import time

from effortface.core.errors import UserError
from effortface.capture_tool.protocols import PROTOCOLS, get_decoder

#: a decoder must explain at least this share of the bytes and give this many samples to be chosen
MIN_ACCOUNTED = 0.8
MIN_SAMPLES = 2


def score_protocol(protocol: str, data: bytes) -> float:
    """Share of ``data`` that ``protocol``'s decoder accepted, 0 if it found under two samples.

    Parameters
    ----------
    protocol : str
        A name of :data:`effortface.capture_tool.protocols.PROTOCOLS`.
    data : bytes
        The first bytes read from the port.

    Returns
    -------
    float
        In [0, 1]; 0 when the decoder module is missing or yields too few samples.
    """
    try:
        decoder = get_decoder(protocol)
    except (ImportError, UserError):
        return 0.0
    samples = decoder.feed(data, 0.0)
    if len(samples) < MIN_SAMPLES or not data:
        return 0.0
    return 1.0 - decoder.stats.bytes_dropped / len(data)


def detect_protocol(data: bytes) -> str | None:
    """Return the protocol whose decoder best explains ``data``, or None if none fits.

    Parameters
    ----------
    data : bytes
        About a second or more of bytes from the device.

    Returns
    -------
    str or None
        The protocol name, or None when no decoder accounts for :data:`MIN_ACCOUNTED` of the bytes.
    """
    scores = {name: score_protocol(name, data) for name in sorted(PROTOCOLS)}
    best = max(scores, key=scores.__getitem__)
    return best if scores[best] >= MIN_ACCOUNTED else None


def read_first_bytes(port: str, seconds: float = 2.5, max_bytes: int = 4096) -> bytes:
    """Read what a port sends during ``seconds`` (blocking: call it off the GUI thread).

    Parameters
    ----------
    port : str
        A device path or pyserial URL.
    seconds : float
        How long to listen.
    max_bytes : int
        Stop early once this many bytes arrived.

    Returns
    -------
    bytes

    Raises
    ------
    serial.SerialException
        If the port cannot be opened.
    """
    import serial

    out = bytearray()
    with serial.serial_for_url(port, baudrate=115200, timeout=0.1) as link:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and len(out) < max_bytes:
            out += link.read(512)
    return bytes(out)
