"""``effortface replay LOG [--speed X] [--unplug-after S]``: a simulated serial port.

The first stdout line is the pseudo-terminal path (flushed at once, so a script can read it);
replay starts when a program opens that path and ends when the recording has been played and the
reader closes the port (or ``--unplug-after`` pulls it, or Ctrl-C / SIGTERM; a reader that closes the
port in mid-play and does not open it again within 2 s ends it too). Stopped by SIGTERM it exits quietly with status 0 (a stop asked for is not an
error).
"""

from __future__ import annotations

import argparse
import math
import signal
import sys

from effortface.core.errors import UserError
from effortface.capture_tool.replay import open_pty_replay


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """LOG, --speed, --unplug-after, --wait."""
    parser.add_argument("log", metavar="LOG", help=".serlog, or a raw capture with its -timing.csv")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed factor (default 1: recorded timing)")
    parser.add_argument("--unplug-after", type=float, default=None, metavar="S",
                        help="close the port after S seconds of the recording, as if the stick was pulled")
    parser.add_argument("--wait", type=float, default=60.0, metavar="S",
                        help="seconds to wait for a program to open the port (default 60)")


def run(args: argparse.Namespace) -> int:
    """Open the pseudo-terminal, print its path, replay, close."""
    if not (math.isfinite(args.wait) and args.wait > 0):
        raise UserError(f"--wait: expected seconds above 0, found {args.wait}")
    if args.unplug_after is not None and not (math.isfinite(args.unplug_after) and args.unplug_after >= 0):
        raise UserError(f"--unplug-after: expected seconds >= 0, found {args.unplug_after}")
    replay = open_pty_replay(args.log, speed=args.speed, unplug_after_s=args.unplug_after)
    signal.signal(signal.SIGTERM, lambda *_: replay.stop())
    print(replay.path, flush=True)
    try:
        if not replay.wait_for_reader(args.wait):
            if replay.stopped:  # SIGTERM while waiting: not a timeout
                return 0
            print(f"effortface replay: no program opened {replay.path} within {args.wait:g} s", file=sys.stderr)
            return 1
        n = replay.play()
        if replay.reader_left:
            print(f"effortface replay: the reader closed {replay.path} after {n} bytes; replay ended",
                  file=sys.stderr, flush=True)
        elif not replay.stopped:
            print(f"replayed {n} bytes", file=sys.stderr, flush=True)
        replay.hold()
    except KeyboardInterrupt:
        pass
    finally:
        replay.close()
    return 0
