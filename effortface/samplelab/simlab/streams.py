"""Beats -> the real byte streams of the supported straps, with their host arrival times.

Each ``*_chunks`` function returns ``[(t_s, bytes), ...]``: what one ``read()`` of the serial port
would have returned and when. Encoding uses the project's own encoders
(:mod:`effortface.capture_tool.protocols.encode`); the link's imperfections are simulated here:

- ANT+ (USB stick): a broadcast every 8070/32768 s, toggle bit every 4 messages, background page 2
  every 65th message; a missed message is an ``EVENT_RX_FAIL`` channel event, a long drop-out
  ``EVENT_RX_FAIL_GO_TO_SEARCH`` then silence until the channel tracks again;
- Zephyr HxM (Bluetooth SPP): one 60-byte packet a second, split and merged across reads as on the
  real capture (60 B, 1 + 59 B, two packets in one read); drop-outs delay packets (SPP retransmits);
- HRMI: a reply ``<status> <count> <hr>`` to the host's ``G1`` poll once a second (the count
  grows per computed value; HR 0 while nothing is received);
- text lines (PulseSensor over a USB-serial adapter): ``B<bpm>`` and ``Q<ibi>`` per beat.

A contact loss makes the strap report HR 0 (no beats detected); a few bytes are corrupted on
purpose so the decoders' resync is exercised.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from effortface.capture_tool.protocols.encode import (
    encode_ant_broadcast,
    encode_ant_channel_event,
    encode_hrmi_reply,
    encode_hxm_packet,
    encode_line,
)

ANT_PERIOD_S = 8070 / 32768
EVENT_RX_FAIL, EVENT_RX_FAIL_GO_TO_SEARCH = 0x02, 0x08
#: serial settings as pyserial's get_settings() reports them, per protocol
BAUD = {"ant": 115200, "hxm": 115200, "hrmi": 9600, "lines": 115200}


@dataclasses.dataclass(frozen=True)
class LinkFaults:
    """When the strap or the radio misbehaves (session seconds)."""

    contact_loss: tuple[float, float]
    dropouts: tuple[tuple[float, float], ...]
    n_corrupt_bytes: int = 4


def _in_any(t: float, windows: tuple[tuple[float, float], ...]) -> bool:
    return any(a <= t < b for a, b in windows)


def _strap_hr(beats_s: np.ndarray, k: int) -> int:
    """The strap's own HR at beat ``k``: 60 / mean of the last (up to) 4 R-R intervals, rounded;
    intervals over 2 s (a contact loss) end the window, and no interval means HR 0 (invalid)."""
    n = 0
    while n < 4 and k - n >= 1 and beats_s[k - n] - beats_s[k - n - 1] <= 2.0:
        n += 1
    if n == 0:
        return 0
    return int(round(60.0 * n / (beats_s[k] - beats_s[k - n])))


def detected_beats(beats_s: np.ndarray, faults: LinkFaults) -> np.ndarray:
    """Beats the strap detects (none during the contact loss)."""
    a, b = faults.contact_loss
    return beats_s[(beats_s < a) | (beats_s >= b)]


def ant_chunks(beats_s: np.ndarray, faults: LinkFaults, duration_s: float,
               rng: np.random.Generator, device_number: int | None) -> list[tuple[float, bytes]]:
    """ANT+ broadcasts (plain, or extended with the device number) and channel events."""
    beats = detected_beats(beats_s, faults)
    out: list[tuple[float, bytes]] = []
    t0 = float(rng.uniform(0.05, 0.25))
    n_msgs = int((duration_s - t0) / ANT_PERIOD_S)
    missed_run = 0
    for n in range(n_msgs):
        t = t0 + n * ANT_PERIOD_S * (1 + 20e-6)  # the strap's crystal runs 20 ppm fast
        arrival = t + float(rng.uniform(0.001, 0.004))
        if _in_any(t, faults.dropouts):
            missed_run += 1
            code = EVENT_RX_FAIL_GO_TO_SEARCH if missed_run == 8 else EVENT_RX_FAIL
            if missed_run <= 8:
                out.append((arrival, encode_ant_channel_event(code)))
            continue
        missed_run = 0
        out.append((arrival, _ant_message(beats, beats_s, faults, t, n, device_number)))
    return out


def _ant_message(beats: np.ndarray, all_beats: np.ndarray, faults: LinkFaults, t: float, n: int,
                 device_number: int | None) -> bytes:
    """The broadcast the strap sends at ``t`` (its latest detected beat, HR 0 without contact)."""
    k = int(np.searchsorted(beats, t, side="right")) - 1
    beat_t = beats[k] if k >= 0 else 0.0
    prev_t = beats[k - 1] if k >= 1 else beat_t
    no_contact = faults.contact_loss[0] + 2.0 <= t < faults.contact_loss[1]
    hr = 0 if no_contact or k < 1 else _strap_hr(beats, k)
    page = 2 if n % 65 == 64 else 4
    return encode_ant_broadcast(
        page, (n // 4) % 2, int(round(beat_t * 1024)), max(k + 1, 0), hr,
        page_bytes=b"\x0d\x44\x06" if page == 2 else b"\xff\xff\xff",
        prev_beat_time_1024=int(round(prev_t * 1024)), extended_device=device_number,
    )


def hxm_chunks(beats_s: np.ndarray, faults: LinkFaults, duration_s: float,
               rng: np.random.Generator, speed_at: Callable[[float], float]) -> list[tuple[float, bytes]]:
    """Zephyr HxM packets at 1 Hz, split and merged across reads like Bluetooth SPP."""
    beats = detected_beats(beats_s, faults)
    pending: list[tuple[float, bytes]] = []
    t, distance_m, strides = 1.0 + float(rng.uniform(0, 0.3)), 0.0, 0
    while t < duration_s:
        speed = float(speed_at(t))
        distance_m += speed
        strides += int(round(speed * 0.9))
        pending.append((t, _hxm_packet(beats, faults, t, speed, distance_m, strides)))
        t += 1.0
    return _spp_reads(pending, faults, rng)


def _hxm_packet(beats: np.ndarray, faults: LinkFaults, t: float, speed: float, distance_m: float,
                strides: int) -> bytes:
    k = int(np.searchsorted(beats, t, side="right")) - 1
    no_contact = faults.contact_loss[0] + 2.0 <= t < faults.contact_loss[1]
    hr = 0 if no_contact or k < 1 else _strap_hr(beats, k)
    stamps = [int(round(beats[i] * 1000)) if i >= 0 else 0 for i in range(k, k - 15, -1)]
    return encode_hxm_packet(hr, k + 1, stamps, distance_m=distance_m % 4096,
                             speed_m_per_s=speed, strides=strides)


def _spp_reads(packets: list[tuple[float, bytes]], faults: LinkFaults,
               rng: np.random.Generator) -> list[tuple[float, bytes]]:
    """Bluetooth SPP delivery: latency, split reads, packets held back during a drop-out."""
    out: list[tuple[float, bytes]] = []
    held = b""
    for t, pkt in packets:
        if _in_any(t, faults.dropouts):
            held += pkt  # the radio retransmits: the bytes arrive late, all at once
            continue
        data, held = held + pkt, b""
        arrival = t + float(rng.uniform(0.02, 0.12))
        if len(data) == len(pkt) and rng.random() < 0.12:
            out += [(arrival, data[:1]), (arrival + 0.003, data[1:])]
        else:
            out.append((arrival, data))
    return out


def hrmi_chunks(beats_s: np.ndarray, faults: LinkFaults, duration_s: float,
                rng: np.random.Generator) -> list[tuple[float, bytes]]:
    """HRMI replies to a ``G1`` poll every second (a missed reply during drop-outs)."""
    beats = detected_beats(beats_s, faults)
    out: list[tuple[float, bytes]] = []
    count, last_k, t = 0, -1, 0.0
    while t < duration_s:
        k = int(np.searchsorted(beats, t, side="right")) - 1
        no_contact = faults.contact_loss[0] + 2.0 <= t < faults.contact_loss[1]
        if k != last_k or no_contact:
            count, last_k = (count + 1) % 256, k  # the HRMI computed a new value
        hr = 0 if no_contact or k < 1 else _strap_hr(beats, k)
        if not _in_any(t, faults.dropouts):
            out.append((t + float(rng.uniform(0.008, 0.02)), encode_hrmi_reply(1, count, [hr])))
        t += 1.0 + float(rng.normal(0, 0.002))
    return out


def line_chunks(beats_s: np.ndarray, faults: LinkFaults, duration_s: float,
                rng: np.random.Generator) -> list[tuple[float, bytes]]:
    """PulseSensor ``B``/``Q`` lines per detected beat; ``B0`` once a second without contact."""
    beats = detected_beats(beats_s, faults)
    out: list[tuple[float, bytes]] = []
    for k in range(1, beats.size):
        if beats[k] >= duration_s:
            break
        ibi_ms = (beats[k] - beats[k - 1]) * 1000.0
        rr_ms = None if ibi_ms > 2000 else ibi_ms  # first beat after the contact loss: no interval
        line = encode_line(_strap_hr(beats, k), rr_ms, style="pulsesensor")
        out.append((beats[k] + float(rng.uniform(0.002, 0.01)), line))
    a, b = faults.contact_loss
    out += [(t, encode_line(0, style="pulsesensor")) for t in np.arange(a + 2.0, b, 1.0)]
    return sorted(out, key=lambda c: c[0])


def corrupt(chunks: list[tuple[float, bytes]], n: int, rng: np.random.Generator,
            ) -> tuple[list[tuple[float, bytes]], list[dict]]:
    """Flip one byte in ``n`` random chunks; return the new chunks and what was changed."""
    out = list(chunks)
    changed = []
    for i in sorted(rng.choice(len(out), size=min(n, len(out)), replace=False).tolist()):
        t, data = out[i]
        pos = int(rng.integers(len(data)))
        flip = int(rng.integers(1, 256))
        out[i] = (t, data[:pos] + bytes([data[pos] ^ flip]) + data[pos + 1:])
        changed.append({"t_s": round(t, 4), "offset": pos, "xor": flip})
    return out, changed


def chunks_for(protocol: str, beats_s: np.ndarray, faults: LinkFaults, duration_s: float,
               rng: np.random.Generator, *, device_number: int | None = None,
               speed_at: Callable[[float], float] = lambda t: 0.0) -> list[tuple[float, bytes]]:
    """Dispatch to the protocol's stream builder (``speed_at`` feeds the HxM speed field)."""
    if protocol == "ant":
        return ant_chunks(beats_s, faults, duration_s, rng, device_number)
    if protocol == "hxm":
        return hxm_chunks(beats_s, faults, duration_s, rng, speed_at)
    if protocol == "hrmi":
        return hrmi_chunks(beats_s, faults, duration_s, rng)
    if protocol == "lines":
        return line_chunks(beats_s, faults, duration_s, rng)
    raise ValueError(f"protocol: expected ant, hxm, hrmi or lines, found {protocol!r}")
