"""``effortface agreement (SESSION | DIR | --ratings CSV)``: the inter-rater reliability report.

Where the ratings come from (see :mod:`effortface.annotate.agreement`): ``--ratings CSV`` as given; a folder
with ``reliability/ratings.csv`` (the lab's blind round); otherwise every rater's key-frame curves at
the pose frames (``reliability/poses.csv`` when present, else poses proposed from HR and phase
extremes). Prints per pose, per blendshape and overall: mean absolute disagreement in % of the
weight range, ICC(A,1), ICC(C,1), Krippendorff's alpha (interval), Bland-Altman per rater pair,
flagged poses. ``--plot PNG`` also draws the Bland-Altman plot.

When the sessions hold a machine track (``SESSION/machine/face_landmarker.csv``, written by
``effortface preannotate``), a section labelled "machine rater" follows the humans' report, unchanged:
first its one-line summary (the machine against the human mean, all blendshapes pooled: n, ICC(A,1)
with its CI, alpha, MAD %; the line the app's report shows), then the machine's ICC(A,1), Krippendorff's alpha and mean absolute difference against each human and
against the human mean, per blendshape and pooled, with 95 % bootstrap intervals over poses. The
machine is never counted among the humans unless ``--machine-in-mean`` is given.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from effortface.core.docs import SCIENCE
from effortface.annotate.agreement import (FLAG_PCT, agreement_report, format_machine_report, format_report, gather_poses,
                                           gather_ratings, machine_ratings, machine_report, save_bland_altman_png)
from effortface.annotate.reliability import read_ratings
from effortface.core.blendshapes import DEFAULT_SET
from effortface.core.errors import UserError
from effortface.core.fileio import check_new_png


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (SCIENCE,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """SESSION | DIR | --ratings CSV, --threshold, --plot, --machine-in-mean."""
    parser.add_argument("target", nargs="?", metavar="SESSION|DIR",
                        help="a session folder or a folder of sessions")
    parser.add_argument("--ratings", metavar="CSV", help="long-format ratings pose_id,rater,blendshape,weight")
    parser.add_argument("--threshold", type=float, default=FLAG_PCT, metavar="PCT",
                        help=f"flag poses whose mean |difference| exceeds PCT %% of the weight range (default {FLAG_PCT:g})")
    parser.add_argument("--plot", metavar="PNG", help="also write the Bland-Altman plot to PNG (never overwrites)")
    parser.add_argument("--machine-in-mean", action="store_true",
                        help="also count the machine rater (machine/face_landmarker.csv) as a rater in the "
                             "humans' report; by default it is reported apart only")


def run(args: argparse.Namespace) -> int:
    """Gather the ratings, print the report, optionally draw the plot."""
    if (args.target is None) == (args.ratings is None):
        raise UserError("arguments: expected exactly one of SESSION|DIR or --ratings CSV, "
                        f"found {'both' if args.target else 'neither'}")
    if not 0.0 <= args.threshold <= 100.0:
        raise UserError(f"--threshold: expected a percentage from 0 to 100, found {args.threshold}")
    plot = _check_plot(args.plot) if args.plot else None
    if args.ratings is not None:
        path = Path(args.ratings)
        if not path.is_file():
            raise UserError(f"--ratings {path}: expected a CSV file, found {'a folder' if path.exists() else 'nothing'}")
        ratings, source = read_ratings(path, DEFAULT_SET), str(path)
    else:
        ratings, source = gather_ratings(args.target)
    machine, no_face = (machine_ratings(args.target, gather_poses(args.target)) if args.target is not None
                        else ([], []))
    pooled = [*ratings, *machine] if args.machine_in_mean else ratings
    report = agreement_report(pooled, flag_pct=args.threshold, source=source)
    print(format_report(report), end="")
    section = machine_report(ratings, machine, no_face=no_face, in_mean=args.machine_in_mean)
    if section is not None:
        print(format_machine_report(section), end="")
    elif args.machine_in_mean:
        print("\nMachine rater: no machine track at these poses (effortface preannotate SESSION writes one)")
    if plot is not None:
        try:
            save_bland_altman_png(report, plot)
        except FileExistsError as exc:
            raise UserError(f"--plot {args.plot}: expected a new file, found one exists (not overwritten)") from exc
        except OSError as exc:
            raise UserError(f"--plot {args.plot}: expected a writable PNG path, found "
                            f"{exc.strerror or exc}") from exc
        print(f"Bland-Altman plot: {args.plot}")
    return 0


def _check_plot(value: str) -> Path:
    """``--plot``: a new ``.png`` file in an existing folder (checked before any work is done)."""
    return check_new_png("--plot", value)
