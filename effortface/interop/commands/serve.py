"""``effortface serve MODEL``: stream the face live from an LSL or OSC input (see
:mod:`effortface.interop.serve`). Runs until Ctrl-C or ``--duration``; prints its rates.

Every option is checked before serving (ports, fps, report period, duration, output hosts): a bad
one is one line naming it and exit status 2."""

from __future__ import annotations

import argparse
import signal
import socket
import sys
import threading
from typing import Any

from effortface.core import bounds
from effortface.core.errors import UserError
from effortface.synth.character_options import add_character_arguments, character_from_args
from effortface.interop.serve import (EFFORT_WORK_TYPE, MOCAP_TYPE, FaceProcessor, LslInput, OscInput,
                                            Outputs, input_names, make_input, output_names, parse_host_port, serve)
from effortface.synth.read_options import add_motion_read_arguments, read_options_from_args
from effortface.synth.runtime import load_model


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Model, input, outputs, character options."""
    parser.add_argument("model_dir", metavar="MODEL", help="model bundle folder, or 'default'")
    parser.add_argument("--input", choices=input_names(), default="lsl", help="where frames come from")
    parser.add_argument("--input-type", choices=(EFFORT_WORK_TYPE, MOCAP_TYPE), default=EFFORT_WORK_TYPE,
                        help="LSL stream type (default EffortWork: w_per_kg, p_per_kg)")
    parser.add_argument("--input-name", default=None, help="LSL stream name (default: the first of its type)")
    parser.add_argument("--skeleton", default=None, metavar="JSON",
                        help="skeleton file with rest_positions_m (MoCap input)")
    add_motion_read_arguments(parser, what="the --skeleton joints and the MoCap frames")
    parser.add_argument("--osc-in-port", type=int, default=9000, metavar="PORT", help="OSC input port (default 9000)")
    parser.add_argument("--output", action="append", choices=output_names(),
                        help="where weights go (repeatable; default lsl)")
    parser.add_argument("--name", default="effortface face", help="output stream / subject name")
    parser.add_argument("--osc-out", default=None, metavar="HOST:PORT", help="OSC output address")
    parser.add_argument("--livelink-out", default=None, metavar="HOST:PORT", help="Live Link Face UDP address")
    parser.add_argument("--fps", type=float, default=120.0, help="nominal input rate (default 120)")
    parser.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")
    parser.add_argument("--report", type=float, default=5.0, metavar="S", help="seconds between rate lines")
    add_character_arguments(parser)


def check_options(args: argparse.Namespace) -> dict[str, tuple[str, int] | None]:
    """Check every option before anything is served; return the output addresses.

    Raises
    ------
    UserError
        One line naming the option: a port outside 0-65535, an fps or report period that is not a
        positive finite number within :data:`effortface.core.bounds.BOUNDS`, a duration beyond it,
        an output address that is not ``HOST:PORT`` or whose host does not resolve.
    """
    if args.input_type == MOCAP_TYPE and args.skeleton is None:
        raise UserError("--skeleton: expected a skeleton file for --input-type MoCap, found none")
    bounds.check("port", args.osc_in_port, "--osc-in-port")
    bounds.check("fps", args.fps, "--fps")
    bounds.check("report_s", args.report, "--report")
    if args.duration is not None:
        bounds.check("t_s", args.duration, "--duration")
    return {"osc_to": resolve_address("--osc-out", args.osc_out),
            "livelink_to": resolve_address("--livelink-out", args.livelink_out)}


def resolve_address(option: str, text: str | None) -> tuple[str, int] | None:
    """``HOST:PORT`` whose host resolves (checked now, not at the first frame); None stays None."""
    address = parse_host_port(option, text)
    if address is None:
        return None
    try:
        socket.getaddrinfo(address[0], address[1], type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise UserError(f"{option}: expected a host name or address that resolves, found {address[0]!r} "
                        f"({why})") from None
    return address


def run(args: argparse.Namespace) -> int:
    """Build the processor, input and outputs; serve until stopped."""
    addresses = check_options(args)
    model = load_model(args.model_dir)
    processor = FaceProcessor(model, character_from_args(args, model),
                              args.skeleton if args.input_type == MOCAP_TYPE else None, fps=args.fps,
                              mapping=args.mapping, read=read_options_from_args(args))
    outputs = Outputs(model, args.output or ["lsl"], name=args.name, osc_to=addresses["osc_to"],
                      livelink_to=addresses["livelink_to"], rate_hz=args.fps)
    source: Any
    if args.input == "lsl":
        widths = (3 * processor.n_joints,) if processor.n_joints else (2, 3)
        source = LslInput(args.input_type, args.input_name, widths)
        where = args.input_type
    else:
        source = OscInput(args.osc_in_port) if args.input == "osc" else make_input(args.input, args)
        where = f"port {source.port}" if args.input == "osc" else "(registered)"
        outputs.open_lsl(processor.columns, 0.0)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print(f"serve: {model.name} -> {', '.join(outputs.kinds)}; input {args.input} {where}", file=sys.stderr,
          flush=True)
    try:
        stats = serve(processor, source, outputs, stop=stop, duration_s=args.duration, report_s=args.report)
    except KeyboardInterrupt:
        return 0
    print(f"serve: {stats.received} frames in, {stats.sent} out, {stats.connects} connects, "
          f"{stats.losses} losses, {stats.bad} bad", file=sys.stderr)
    return 0
