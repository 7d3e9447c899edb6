"""``effortface decode [--protocol P] FILE``: recorded strap bytes -> heart-rate CSV on stdout.

FILE is a ``.serlog``, a ``.pcap`` or a raw capture (see :mod:`effortface.capture_tool.captures`). A
``.serlog`` names its protocol in its header, so ``--protocol`` may be left out for one (given, it
wins, with a note on stderr if it differs); a pcap or raw capture needs it. The file's chunks
are fed to the decoder with their recorded arrival times, so ``t_s`` is seconds since the first
chunk. The CSV is ``heart_rate.csv``'s format; a one-line summary of the decoder's counters goes
to stderr.

A damaged ``.serlog`` (a flipped byte in a record's kind, length or time) is decoded all but the
damaged records: the reader resynchronises after each, and ``warning: FILE: skipped N damaged bytes
in K places (first at byte B)`` goes to stderr. Exit status: 0 when every byte was read, 1 when
damaged bytes were skipped (the CSV is still written), 2 for a file that cannot be decoded at all.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TextIO

from effortface.capture_tool.captures import check_capture_file, read_timed_capture
from effortface.core.errors import UserError
from effortface.core.session.hr_csv import HR_CSV_HEADER, format_hr_row
from effortface.capture_tool.protocols import (PROTOCOLS, Decoder, check_protocol, decode_chunks, get_decoder,
                                              header_protocol)
from effortface.capture_tool.serlog import is_serlog, read_serlog, read_serlog_header


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``effortface decode``."""
    parser.add_argument("--protocol", default=None, metavar="P",
                        help=f"strap protocol: {', '.join(sorted(PROTOCOLS))} "
                             "(default for a .serlog: the one in its header)")
    parser.add_argument("--device-type", type=int, default=None, metavar="N",
                        help="ANT only: device type that yields heart rate (default 120)")
    parser.add_argument("file", metavar="FILE", help=".serlog, .pcap or raw capture")


def summary_line(decoder: Decoder) -> str:
    """The decoder's counters as one line of ``name=value`` pairs."""
    counters = decoder.stats.as_dict()
    return f"{decoder.name}: " + " ".join(f"{k}={v}" for k, v in counters.items())


def file_protocol(path: str | os.PathLike, given: str | None) -> str:
    """The protocol to decode ``path`` with: ``given``, else the one a ``.serlog`` header names.

    ``given`` is checked first, then the file (it must be a regular file; one named ``.serlog``
    must start with the serlog magic), then a note goes to stderr if the header disagrees.

    Raises
    ------
    UserError
        If ``given`` is not a protocol, the file is missing or not a regular file, a ``.serlog``
        is malformed, or none is given and the file is not a ``.serlog`` naming a protocol.
    """
    if given is not None:
        check_protocol(given)
    path = check_capture_file(path)
    header = read_serlog_header(path) if _looks_like_serlog(path) else {}
    named = header.get("protocol")
    if given is not None:
        if named is not None and named != given:
            print(f"note: {path} was recorded as {named!r}; decoding as --protocol {given}", file=sys.stderr)
        return given
    if named is None:
        raise UserError(f"--protocol: expected one of {', '.join(sorted(PROTOCOLS))} for {path}, found none "
                        "(only a .serlog names its own protocol)")
    return header_protocol(header, path)


def _looks_like_serlog(path: Path) -> bool:
    """True for a file named ``.serlog`` or starting with the serlog magic (its header is then read)."""
    return path.suffix.lower() == ".serlog" or is_serlog(path)


def _make_decoder(args: argparse.Namespace) -> Decoder:
    args.protocol = file_protocol(args.file, args.protocol)
    if args.device_type is None:
        return get_decoder(args.protocol)
    if args.protocol != "ant":
        raise UserError(f"--device-type: expected only with --protocol ant, found --protocol {args.protocol}")
    if not 0 < args.device_type < 128:
        raise UserError(f"--device-type: expected an ANT device type 1..127, found {args.device_type}")
    return get_decoder("ant", device_type=args.device_type)


def run(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Decode FILE and print the CSV; return 0, or 1 when damaged bytes of a ``.serlog`` were skipped."""
    decoder = _make_decoder(args)
    warning = None
    if is_serlog(args.file):
        log = read_serlog(args.file)
        chunks, warning = list(log.data_chunks()), log.damage_warning()
    else:
        chunks = read_timed_capture(args.file)
    samples = decode_chunks(decoder, chunks)
    out = sys.stdout if out is None else out
    try:
        out.write(HR_CSV_HEADER + "\n")
        out.writelines(format_hr_row(s) + "\n" for s in samples)
        out.flush()
    except BrokenPipeError:  # e.g. piped into head: the reader has all it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    print(summary_line(decoder), file=sys.stderr)
    if warning:
        print(warning, file=sys.stderr)
        return 1
    return 0
