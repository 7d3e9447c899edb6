"""The ``effortface`` command line (a contract: see docs/DESIGN.md and the guide, docs/guide/).

Each sub-command lives in its own module exposing ``add_arguments(parser)`` and ``run(args) -> int``;
only the chosen one is imported, so ``effortface decode`` never pays for Qt or scikit-learn. A module's
``HELP_DOCS`` (paths such as ``docs/DESIGN.md``, :mod:`effortface.core.docs`) are cited at the end of
its ``--help`` with where they are installed.
A :class:`~effortface.core.errors.UserError` becomes one line on stderr and exit status 2; so does, as a
last resort, an :class:`OSError` naming a path (a file or folder a command could not read or write).
SIGTERM and SIGINT (Ctrl-C) end a command through its own cleanup (:mod:`effortface.core.stops`): one
line and exit status 143 or 130, no staging folder or worker process left.
A first argument that is neither a command, an option nor an existing folder is refused the same way.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from effortface.core.docs import DESIGN, SCIENCE, cite
from effortface.core.errors import UserError
from effortface.core.stops import Terminated, exit_status, stops_as_exceptions

#: sub-command -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "app": ("effortface.commands.app", "the Qt application, opened on DIR (default: the sample lab)"),
    "ports": ("effortface.capture_tool.commands.ports", "serial ports and cameras found"),
    "capture": ("effortface.capture_tool.commands.capture", "record a strap (and video) into a session folder"),
    "replay": ("effortface.capture_tool.commands.replay", "open a simulated port, print its path, replay LOG"),
    "decode": ("effortface.capture_tool.commands.decode", "raw bytes or .serlog -> heart-rate CSV on stdout"),
    "recover": ("effortface.capture_tool.commands.recover", "finish a session that a crash left incomplete"),
    "agreement": ("effortface.annotate.commands.agreement", "inter-rater agreement report"),
    "preannotate": ("effortface.annotate.commands.preannotate", "the machine rater (MediaPipe Face Landmarker) on every frame"),
    "train": ("effortface.train.commands.train", "fit the heart-rate and face models, export a bundle"),
    "evaluate": ("effortface.train.commands.evaluate", "re-score a model bundle on sessions or a table"),
    "synth": ("effortface.synth.commands.synth", "synthesize face curves from a motion clip"),
    "work": ("effortface.synth.commands.work", "work.csv (w, p per second) from motion/ and the exercise log"),
    "motion": ("effortface.synth.commands.motion", "motion attach SESSION CLIP: align a mocap clip to a session; motion inspect FILE: what a clip holds"),
    "import": ("effortface.interop.commands.import_data", "import xdf FILE | hr FILE...: a LabRecorder recording, or watch/app heart-rate files -> sessions"),
    "export": ("effortface.interop.commands.export_data", "export bids SESSIONS: sessions -> a BIDS dataset"),
    "serve": ("effortface.interop.commands.serve", "live face from an LSL or OSC stream to LSL, OSC or Live Link"),
    "blender-addon": ("effortface.blender.commands.blender_addon", "build the Blender add-on's installable zip"),
    "demo": ("effortface.commands.demo", "the whole pipeline on the sample lab"),
}


#: commands that keep the default stops: the Qt application (its event loop runs no Python between events)
_OWN_STOPS = frozenset({"app"})


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line and exit status 2 (no usage dump)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def top_parser() -> argparse.ArgumentParser:
    """The parser of ``effortface`` itself (``--help``, ``--version``); the guide's command-line reference uses it."""
    width = max(map(len, COMMANDS)) + 2  # the longest command name never runs into its text
    epilog = "\n".join(f"  {name:<{width}}{text}" for name, (_, text) in COMMANDS.items())
    parser = _Parser(
        prog="effortface",
        description="Facial expressions of physical effort: capture, annotate, train, synthesize.",
        epilog="commands:\n" + epilog + "\n\nRun 'effortface COMMAND --help' for a command's options.\n\n"
               + docs_epilog((DESIGN, SCIENCE)),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=_version())
    return parser


def command_parser(command: str) -> argparse.ArgumentParser:
    """The parser of ``effortface COMMAND`` (its module imported; the guide's command-line reference uses it).

    Parameters
    ----------
    command : str
        One of :data:`COMMANDS`.

    Returns
    -------
    argparse.ArgumentParser
        With the command's options, its one-line description and the documents it cites.
    """
    module = importlib.import_module(COMMANDS[command][0])
    parser = _Parser(prog=f"effortface {command}", description=COMMANDS[command][1],
                     epilog=docs_epilog(getattr(module, "HELP_DOCS", ())) or None,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(parser)
    return parser


def docs_epilog(cited: Sequence[str]) -> str:
    """The ``--help`` lines citing shipped documents, each with where it is installed."""
    return "documents:\n" + "\n".join(f"  {cite(c)}" for c in cited) if cited else ""


def _version() -> str:
    from effortface import __version__

    return f"effortface {__version__}"


def _os_error_paths(exc: OSError) -> str:
    """The path(s) an OSError names, or what it is when it names none."""
    paths = [str(p) for p in (exc.filename, exc.filename2) if p is not None]
    return " -> ".join(paths) if paths else "file system"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``effortface`` command line; return the exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] in ("-h", "--help", "--version"):
        top_parser().parse_args(args)
        return 0
    if args and args[0] not in COMMANDS and not args[0].startswith("-") and not Path(args[0]).is_dir():
        found = f"{args[0]!r}" + (" (a file)" if Path(args[0]).exists() else "")
        print(f"effortface: error: expected a command ({', '.join(COMMANDS)}) or a sessions folder, "
              f"found {found}", file=sys.stderr)
        return 2
    command = args[0] if args and args[0] in COMMANDS else "app"
    rest = args[1:] if args and args[0] in COMMANDS else args
    with contextlib.nullcontext() if command in _OWN_STOPS else stops_as_exceptions():
        return _run(command, rest)


def _run(command: str, rest: list[str]) -> int:
    """Import, parse and run one command; its errors and stops as one line and an exit status."""
    try:
        module = importlib.import_module(COMMANDS[command][0])
        ns = command_parser(command).parse_args(rest)
        return int(module.run(ns) or 0)
    except UserError as exc:
        print(f"effortface {command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # last resort for a path the command did not check itself
        if exc.filename is None and exc.strerror is None:
            raise  # not a file-system error (e.g. a bare OSError raised by a library): keep the traceback
        print(f"effortface {command}: error: {_os_error_paths(exc)}: expected a readable/writable path, "
              f"found {exc.strerror or type(exc).__name__}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"effortface {command}: interrupted", file=sys.stderr)
        return exit_status(exc)
    except Terminated as exc:
        print(f"effortface {command}: {exc}; what it had not finished was not written", file=sys.stderr)
        return exit_status(exc)
