"""``effortface serve MODEL``: stream the face live from an LSL or OSC input (see
:mod:`effortface.train.interop.serve`). Runs until Ctrl-C or ``--duration``; prints its rates."""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from effortface.core.errors import UserError
from effortface.train.character_options import add_character_arguments, character_from_args
from effortface.train.interop.serve import (EFFORT_WORK_TYPE, MOCAP_TYPE, FaceProcessor, LslInput, OscInput,
                                            Outputs, parse_host_port, serve)
from effortface.train.runtime import load_model


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Model, input, outputs, character options."""
    parser.add_argument("model_dir", metavar="MODEL", help="model bundle folder, or 'default'")
    parser.add_argument("--input", choices=("lsl", "osc"), default="lsl", help="where frames come from")
    parser.add_argument("--input-type", choices=(EFFORT_WORK_TYPE, MOCAP_TYPE), default=EFFORT_WORK_TYPE,
                        help="LSL stream type (default EffortWork: w_per_kg, p_per_kg)")
    parser.add_argument("--input-name", default=None, help="LSL stream name (default: the first of its type)")
    parser.add_argument("--skeleton", default=None, metavar="JSON",
                        help="skeleton file with rest_positions_m (MoCap input)")
    parser.add_argument("--mapping", default=None, metavar="JSON",
                        help="joint-to-segment mapping for the --skeleton joints (default: built-in conventions)")
    parser.add_argument("--osc-in-port", type=int, default=9000, metavar="PORT", help="OSC input port (default 9000)")
    parser.add_argument("--output", action="append", choices=("lsl", "osc", "livelink"),
                        help="where weights go (repeatable; default lsl)")
    parser.add_argument("--name", default="effortface face", help="output stream / subject name")
    parser.add_argument("--osc-out", default=None, metavar="HOST:PORT", help="OSC output address")
    parser.add_argument("--livelink-out", default=None, metavar="HOST:PORT", help="Live Link Face UDP address")
    parser.add_argument("--fps", type=float, default=120.0, help="nominal input rate (default 120)")
    parser.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")
    parser.add_argument("--report", type=float, default=5.0, metavar="S", help="seconds between rate lines")
    add_character_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Build the processor, input and outputs; serve until stopped."""
    if args.input_type == MOCAP_TYPE and args.skeleton is None:
        raise UserError("--skeleton: expected a skeleton file for --input-type MoCap, found none")
    model = load_model(args.model_dir)
    processor = FaceProcessor(model, character_from_args(args, model),
                              args.skeleton if args.input_type == MOCAP_TYPE else None, fps=args.fps,
                              mapping=args.mapping)
    outputs = Outputs(model, args.output or ["lsl"], name=args.name,
                      osc_to=parse_host_port("--osc-out", args.osc_out),
                      livelink_to=parse_host_port("--livelink-out", args.livelink_out), rate_hz=args.fps)
    source: LslInput | OscInput
    if args.input == "lsl":
        source = LslInput(args.input_type, args.input_name)
        where = args.input_type
    else:
        source = OscInput(args.osc_in_port)
        where = f"port {source.port}"
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
          f"{stats.losses} losses", file=sys.stderr)
    return 0
