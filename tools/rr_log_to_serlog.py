"""Turn a log of decoded Heart Rate Measurement notifications back into a BLE strap log (``.serlog``).

Programs that read a strap over Bluetooth often keep only what they decoded from each 0x2A37
notification: when it arrived and the R-R intervals it carried, one row per interval. For example
kbre93/dont-hold-your-breath's ``data/sample_data_ibi.csv`` (a Polar H10 read with ``bleak``):
``t_s,rr_ms`` without a header, the arrival in seconds and the interval in milliseconds rounded up
from the strap's 1/1024 s count (``np.ceil(count / 1024 * 1000)``). This rebuilds the notifications
so that ``effortface capture --ble replay://LOG`` and ``effortface decode --protocol ble_hrm LOG``
play them as a recording of the strap:

- intervals that arrived within :data:`SAME_NOTIFICATION_S` of the one before came in one
  notification (such a logger stamps each interval of a notification as it unpacks them,
  microseconds apart; notifications come about a second apart);
- each interval becomes the 1/1024 s count the strap sent: the smallest count whose milliseconds,
  rounded as the logger rounded them (``ceil``, ``floor`` or ``round``), are the logged value. That is
  the count sent except where two counts give the same millisecond (one value in 42): then the
  smaller is taken, at most 0.98 ms off;
- what such a log does not keep is not guessed silently: the flags byte is 0x10 (R-R intervals
  present, skin contact not reported) and the rate byte is the rate of the notification's mean
  interval (a strap sends its own averaged rate, which the log dropped).

Each notification is written as the BLE link writes it (one frame ``B1 E5 <length> <notification>``
per read, stamped with the arrival time). Usage::

    python tools/rr_log_to_serlog.py IN.csv OUT.serlog [--rounding ceil|floor|round] [--device NAME]

Bad input (not two numbers a row, an interval outside 200-65535 ms' reach, arrival times going
backwards) is one line naming the file and the row, exit status 2, nothing written.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from effortface.capture_tool.protocols.ble_hrm import frame  # noqa: E402
from effortface.capture_tool.serlog import SerlogWriter  # noqa: E402

#: intervals that arrived closer together than this came in one notification, s
SAME_NOTIFICATION_S = 0.05
#: how the logger turned a 1/1024 s count into its milliseconds
ROUNDING = {"ceil": math.ceil, "floor": math.floor, "round": round}
#: the flags byte written: R-R intervals present, skin contact not reported, 8-bit rate
FLAGS_RR_ONLY = 0x10
#: longest interval a 16-bit count of 1/1024 s can hold, ms
MAX_RR_MS = 65535 * 1000 / 1024


class RrLogError(ValueError):
    """An input that is not such a log; the one-line message names the file and the row."""


def read_rr_log(path: Path) -> list[tuple[float, float]]:
    """(arrival s, interval ms) rows of a two-column CSV; a first row that is not numbers is a header.

    Raises
    ------
    RrLogError
        A row that is not two numbers, an interval out of a 16-bit count's reach, or time going back.
    """
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise RrLogError(f"{path}: expected a text table of arrival time and R-R interval, found "
                         f"{type(exc).__name__}") from None
    rows: list[tuple[float, float]] = []
    for n, cells in enumerate(csv.reader(lines), start=1):
        if not cells or not "".join(cells).strip():
            continue
        try:
            t_s, rr_ms = (float(c) for c in cells[:2])
            if len(cells) != 2:
                raise ValueError
        except ValueError:
            if n == 1:
                continue   # a header
            raise RrLogError(f"{path}: row {n}: expected two numbers (arrival s, R-R ms), found {cells[:3]}") from None
        if not (math.isfinite(t_s) and 0 < rr_ms <= MAX_RR_MS):
            raise RrLogError(f"{path}: row {n}: expected a finite time and an R-R of 0-{MAX_RR_MS:.0f} ms, "
                             f"found {t_s:g} s, {rr_ms:g} ms")
        if rows and t_s < rows[-1][0]:
            raise RrLogError(f"{path}: row {n}: expected arrival times that never go backwards, found {t_s:g} s "
                             f"after {rows[-1][0]:g} s")
        rows.append((t_s, rr_ms))
    if not rows:
        raise RrLogError(f"{path}: expected rows of arrival time and R-R interval, found none")
    return rows


def group_notifications(rows: list[tuple[float, float]],
                        same_s: float = SAME_NOTIFICATION_S) -> list[tuple[float, list[float]]]:
    """(arrival s of its first interval, intervals ms) of each notification, in arrival order."""
    out: list[tuple[float, list[float]]] = []
    last_t = -math.inf
    for t_s, rr_ms in rows:
        if out and t_s - last_t < same_s:
            out[-1][1].append(rr_ms)
        else:
            out.append((t_s, [rr_ms]))
        last_t = t_s
    return out


def rr_count(rr_ms: float, rounding: str = "ceil") -> int:
    """The smallest 1/1024 s count whose milliseconds, rounded by ``rounding``, are ``rr_ms``.

    Raises
    ------
    ValueError
        No count gives ``rr_ms`` (a value the logger cannot have written).
    """
    to_ms = ROUNDING[rounding]
    first = max(0, math.floor((rr_ms - 1) * 1.024) - 1)
    for count in range(first, first + 6):
        if to_ms(count * 1000 / 1024) == rr_ms:
            return count
    raise ValueError(f"no 1/1024 s count rounds ({rounding}) to {rr_ms:g} ms")


def notification(rr_ms: list[float], rounding: str = "ceil") -> bytes:
    """One 0x2A37 notification: flags 0x10, the rate of its mean interval, the 1/1024 s counts."""
    counts = [rr_count(r, rounding) for r in rr_ms]
    hr = min(255, max(1, round(60000 / (sum(counts) * 1000 / 1024 / len(counts)))))
    return bytes([FLAGS_RR_ONLY, hr]) + b"".join(c.to_bytes(2, "little") for c in counts)


def convert(src: Path, dst: Path, *, rounding: str = "ceil", device: str = "ble_hrm") -> int:
    """Write ``dst`` (a ``.serlog`` of framed notifications) from the log ``src``; the notification count.

    Raises
    ------
    RrLogError
        ``src`` is not such a log, or ``dst`` exists (nothing is written then).
    """
    try:
        notes = [(t_s, notification(rr, rounding)) for t_s, rr in group_notifications(read_rr_log(src))]
    except ValueError as exc:
        if isinstance(exc, RrLogError):
            raise
        raise RrLogError(f"{src}: {exc}") from None
    if dst.exists():
        raise RrLogError(f"{dst}: expected a new file, found one (refusing to overwrite)")
    with SerlogWriter(dst, {"protocol": "ble_hrm", "device": device, "port": f"converted from {src.name}",
                            "settings": {"rounding": rounding, "same_notification_s": SAME_NOTIFICATION_S}}) as log:
        for t_s, note in notes:
            log.write(t_s, frame(note))
    return len(notes)


def main(argv: list[str] | None = None) -> int:
    """Command line: convert one log; 0, or 2 with one line on stderr."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("src", type=Path, help="CSV of arrival time (s) and R-R interval (ms), one row per interval")
    parser.add_argument("dst", type=Path, help="the .serlog to write")
    parser.add_argument("--rounding", choices=sorted(ROUNDING), default="ceil",
                        help="how the logger turned 1/1024 s counts into ms (default: ceil)")
    parser.add_argument("--device", default="ble_hrm", help="device name in the log's header")
    args = parser.parse_args(argv)
    try:
        n = convert(args.src, args.dst, rounding=args.rounding, device=args.device)
    except RrLogError as exc:
        print(f"rr_log_to_serlog: error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.dst}: {n} notifications")
    return 0


if __name__ == "__main__":
    sys.exit(main())
