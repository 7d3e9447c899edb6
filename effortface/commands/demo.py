"""``effortface demo [--out DIR] [--force]``: the whole pipeline on the sample lab, in a few minutes.

1. **capture**: one sample session's strap recording (``serial/*.serlog``) is replayed through a
   pseudo-terminal by ``effortface replay`` and recorded by ``effortface capture`` (two real
   processes, real serial I/O), into ``DIR/captured/``;
2. **decode**: ``effortface decode`` turns the captured raw bytes back into a heart-rate CSV;
3. **work**: the sessions are copied into ``DIR/lab/`` and ``effortface work`` derives their
   ``work.csv`` from the exercise log and motion clips (the sample lab, like a real one, records none);
   the machine rater (``effortface preannotate``) rates one session of the copy: one line with its
   face-found rate and its r against the humans' mean (or why it was skipped);
4. **train**: the heart-rate and face models on those sessions (``DIR/model/``, with its report);
5. **evaluate**: the exported bundle re-scored through the runtime (``DIR/evaluation.md``);
6. **synthesize**: a clip's face curves with the trained bundle (``DIR/synth.csv``).

It ends by printing where the report is. An existing ``--out`` is refused unless ``--force``, which
replaces only a previous demo output (it holds a ``.effortface-demo`` file) or an empty folder; by
default a fresh timestamped folder is made in the current directory. The steps are
:mod:`effortface.demo`'s; this module parses the options and prints.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from effortface.core.errors import UserError
from effortface.demo import (CAPTURE_S, REPLAY_SPEED, capture_step, decode_step, demo_out_dir, held_out_summary,
                             rater_step, replace_out, synth_step, work_step)
from effortface.samplelab import sample_lab
from effortface.train.face_fit import MIN_ROWS_PER_PARTICIPANT


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface demo``."""
    parser.add_argument("--out", metavar="DIR", help="output folder (default: effortface-demo-<time>)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out made by a previous demo (or empty)")
    parser.add_argument("--lab", default=None, metavar="DIR",
                        help="the sessions to use (default: the sample lab; built into the user cache on "
                             "first use when effortface is not run from its repository)")
    parser.add_argument("--capture-seconds", type=float, default=CAPTURE_S, metavar="S",
                        help=f"length of the live capture step (default {CAPTURE_S:g})")
    parser.add_argument("--max-rows", type=int, default=200, metavar="N",
                        help="face training rows per participant (default 200)")


def _check_options(args: argparse.Namespace) -> None:
    """UserError for a bad ``--capture-seconds`` or ``--max-rows``, before anything is made or removed."""
    if not math.isfinite(args.capture_seconds) or args.capture_seconds <= 0:
        raise UserError(f"--capture-seconds: expected seconds above 0, found {args.capture_seconds:g}")
    if args.max_rows < MIN_ROWS_PER_PARTICIPANT:
        raise UserError(f"--max-rows: expected at least {MIN_ROWS_PER_PARTICIPANT} (as effortface train), "
                        f"found {args.max_rows}")


def _say(step: str, text: str) -> None:
    print(f"[{step}] {text}", flush=True)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``effortface demo``."""
    from effortface.core.session.folder import list_sessions
    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.train.evaluation import evaluate_bundle, write_evaluation
    from effortface.train.pipeline import TrainSettings, run_training, training_table

    _check_options(args)
    out = demo_out_dir(args.out, args.force, args.lab)  # checked before the lab is built: a bad --out costs nothing
    lab = Path(args.lab) if args.lab is not None else sample_lab()
    sessions = list_sessions(lab)
    if not sessions:
        raise UserError(f"--lab {lab}: expected session folders, found none "
                        "(run python sample_sessions/generate.py)")
    replace_out(out)
    t0 = time.monotonic()
    _say("capture", f"replaying {sessions[0].name}'s strap at {REPLAY_SPEED:g}x into effortface capture")
    captured = capture_step(sessions[0], out, args.capture_seconds)
    decoded, recorded = decode_step(captured, out)
    _say("decode", f"{captured.name}: {recorded} samples recorded live, {decoded} decoded from the raw bytes")
    lab_copy, lines = work_step(lab, out)
    _say("work", f"effortface work: {len(lines)} sessions' work.csv derived from their exercise logs and "
                 f"motion clips into {lab_copy}")
    _say("rater", rater_step(list_sessions(lab_copy)[0]))
    table, sources = training_table([lab_copy], None, DEFAULT_SET)
    _say("train", f"{table['participant'].nunique()} participants, {table['session'].nunique()} sessions, "
                  f"{len(table)} participant-seconds")
    result = run_training(table, DEFAULT_SET, out / "model",
                          settings=TrainSettings(max_rows_per_participant=args.max_rows), sources=sources)
    ev = evaluate_bundle(out / "model", table, str(lab_copy))
    write_evaluation(ev, out / "evaluation.md", out / "model", str(lab_copy))
    _say("evaluate", f"in-sample (the model re-scored on the lab it was trained on): heart rate r "
                     f"{ev.hr['r'].mean():.2f}; face r {ev.face['r'].mean():.2f} ({out / 'evaluation.md'})")
    _say("evaluate", held_out_summary(result.metrics))
    _say("synth", f"face curves: {synth_step(out / 'model', lab_copy, out)}")
    _say("done", f"in {time.monotonic() - t0:.0f} s")
    print(f"report: {result.report}")
    return 0
