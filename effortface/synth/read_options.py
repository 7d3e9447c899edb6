"""How a command reads motion: ``--unit-m``, ``--up``, ``--mapping`` and ``--trust-skeleton``, one definition.

Every command that reads a motion clip (``synth``, ``work``, ``motion attach``, ``motion inspect``,
``serve --skeleton``) takes the same four options through :func:`add_motion_read_arguments` and
turns them into one :class:`MotionReadOptions` with :func:`read_options_from_args`, so the checks
and the messages are the same everywhere.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from effortface.core import bounds
from effortface.core.errors import UserError

#: the up axes a file may have (``--up``): the axis, with its sign, that points up in the file
UP_AXES = ("x", "y", "z", "-x", "-y", "-z")


@dataclasses.dataclass(frozen=True)
class MotionReadOptions:
    """The caller's say on how a clip is read (None everywhere: the file's own, detected).

    Parameters
    ----------
    unit_m : float or None
        Metres per file length unit (None: from the file or the skeleton's size).
    up : str or None
        The file's up axis, one of :data:`UP_AXES` (None: from the file or the motion).
    mapping : str, mapping or None
        A joint-to-segment mapping JSON file, or one already read (None: the built-in conventions).
    trust_skeleton : bool
        Proceed with a body outside the human ranges of the plausibility gate.
    """

    unit_m: float | None = None
    up: str | None = None
    mapping: str | Path | Mapping[str, Any] | None = None
    trust_skeleton: bool = False


def check_up(up: str | None, option: str = "--up") -> str | None:
    """``up`` lower-cased if it is one of :data:`UP_AXES` (or None); UserError naming ``option`` otherwise."""
    if up is None:
        return None
    key = str(up).strip().lower()
    if key.startswith("+"):
        key = key[1:]
    if key not in UP_AXES:
        raise UserError(f"{option}: expected one of {', '.join(UP_AXES)}, found {up!r}")
    return key


def check_unit_m(unit_m: float | None, option: str = "--unit-m") -> float | None:
    """``unit_m`` if it is a length in metres within the bounds table (or None); UserError otherwise."""
    if unit_m is None:
        return None
    if not (isinstance(unit_m, (int, float)) and math.isfinite(unit_m) and unit_m > 0):
        shown = f"{unit_m:g}" if isinstance(unit_m, (int, float)) else repr(unit_m)
        raise UserError(f"{option}: expected a length in metres above 0, found {shown}")
    bounds.check("unit_m", float(unit_m), option)
    return float(unit_m)


def add_motion_read_arguments(parser: argparse.ArgumentParser, *, what: str = "the clip") -> None:
    """Add ``--unit-m``, ``--up``, ``--mapping`` and ``--trust-skeleton`` to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    what : str
        What the options apply to, for the help texts (``"the clip"``, ``"clips attached without one"``).
    """
    parser.add_argument("--unit-m", type=float, default=None, metavar="M",
                        help=f"length unit of {what} in metres (default: from the file, or detected from the "
                             "skeleton's rest height; CMU cgspeed BVH 0.05644)")
    parser.add_argument("--up", default=None, metavar="AXIS", type=str.lower, choices=UP_AXES,
                        help=f"the up axis of {what}: {', '.join(UP_AXES)} (default: from the file, or "
                             "detected from the rest pose and gravity)")
    parser.add_argument("--mapping", default=None, metavar="JSON",
                        help=f"joint-to-segment mapping for {what} (default: built-in conventions and marker "
                             "sets; a partial mapping fills what they miss)")
    parser.add_argument("--trust-skeleton", action="store_true",
                        help="proceed with a body outside the human ranges (a child, a creature: on purpose)")


def read_options_from_args(args: argparse.Namespace) -> MotionReadOptions:
    """The checked :class:`MotionReadOptions` of parsed arguments (UserError naming the option)."""
    return MotionReadOptions(
        unit_m=check_unit_m(getattr(args, "unit_m", None)),
        up=check_up(getattr(args, "up", None)),
        mapping=getattr(args, "mapping", None),
        trust_skeleton=bool(getattr(args, "trust_skeleton", False)),
    )
