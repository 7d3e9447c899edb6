"""Decoder throughput in MB/s for each protocol, against baselines measured in the same process.

Each decoder is fed a realistic stream (the real captures in ../shared/data/serial, else tests/data/serial, where they exist,
encoder output otherwise), repeated to about ``TARGET_BYTES``, in 64-byte reads (a typical serial
read) and in one read. Two baselines run over the same bytes:

- ``find``: a ``bytes.find`` scan for the sync byte (the C floor for any framing);
- ``loop``: a bare Python ``for`` loop over the bytes (the Python floor for byte-wise work).

A ratio above 1 against ``loop`` means the decoder beats a byte-by-byte Python loop. For scale: a
strap sends 15 B/s (ANT at 4 Hz), 60 B/s (HxM) or a few B/s (HRMI, lines).

Run: ``python benchmarks/bench_decoders.py [--mb 2]``
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from effortface.capture_tool.protocols import get_decoder  # noqa: E402
from effortface.capture_tool.protocols.encode import encode_hrmi_reply, encode_line  # noqa: E402

from bench_data import DATA  # noqa: E402  (../shared/data, else tests/data)

SERIAL = DATA / "serial"


def _streams() -> dict[str, tuple[bytes, int]]:
    """protocol -> (one period of a realistic stream, its sync byte)."""
    hrmi = b"".join(encode_hrmi_reply(1, k, [60 + k % 40]) for k in range(256))
    lines = b"".join(b"S512\r\n" * 20 + encode_line(60 + k % 40, 800, style="pulsesensor")
                     for k in range(200))
    return {
        "ant": ((SERIAL / "derived/njcant_hrm1_ant_broadcast_ext.bin").read_bytes(), 0xA4),
        "hxm": ((SERIAL / "zephyr-bt/120-second-bt-stream-hxm.dat").read_bytes()[:-1], 0x02),
        "hxm-bioharness": ((SERIAL / "zephyr-bt/120-second-bt-stream.dat").read_bytes(), 0x02),
        "hrmi": (hrmi, ord("\r")),
        "lines": (lines, ord("\n")),
    }


def _best_of(fn: Callable[[], object], repeat: int = 3) -> float:
    """Fastest wall time of ``repeat`` runs (s)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _decode(protocol: str, data: bytes, read_size: int) -> None:
    dec = get_decoder("hxm" if protocol.startswith("hxm") else protocol)
    for i in range(0, len(data), read_size):
        dec.feed(data[i : i + read_size], 0.0)
    dec.finish()


def _find_scan(data: bytes, sync: int) -> int:
    n, i, s = 0, data.find(sync), bytes([sync])
    while i >= 0:
        n += 1
        i = data.find(s, i + 1)
    return n


def _python_loop(data: bytes) -> int:
    x = 0
    for b in data:
        x ^= b
    return x


def main() -> None:
    """Print one line per protocol: MB/s in 64-byte and whole reads, baselines and ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=float, default=2.0, help="bytes per protocol, in MB")
    target = int(parser.parse_args().mb * 1e6)
    print(f"{'protocol':<15} {'MB/s 64B':>9} {'MB/s whole':>10} {'find MB/s':>10} {'loop MB/s':>10} "
          f"{'vs loop':>8} {'vs find':>8}")
    for protocol, (period, sync) in _streams().items():
        data = period * max(1, target // len(period))
        mb = len(data) / 1e6
        t64 = _best_of(lambda: _decode(protocol, data, 64))
        twhole = _best_of(lambda: _decode(protocol, data, len(data)))
        tfind = _best_of(lambda: _find_scan(data, sync))
        tloop = _best_of(lambda: _python_loop(data))
        print(f"{protocol:<15} {mb / t64:9.2f} {mb / twhole:10.2f} {mb / tfind:10.1f} {mb / tloop:10.1f} "
              f"{tloop / t64:8.2f} {tfind / t64:8.4f}")


if __name__ == "__main__":
    main()
