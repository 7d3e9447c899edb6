"""``effortface demo [--out DIR] [--force]``: the whole pipeline on the sample lab, in a few minutes.

1. **capture**: one sample session's strap recording (``serial/*.serlog``) is replayed through a
   pseudo-terminal by ``effortface replay`` and recorded by ``effortface capture`` (two real
   processes, real serial I/O), into ``DIR/captured/``;
2. **decode**: ``effortface decode`` turns the captured raw bytes back into a heart-rate CSV;
3. **train**: the heart-rate and face models on every sample session (``DIR/model/``, with its report);
4. **evaluate**: the exported bundle re-scored through the runtime (``DIR/evaluation.md``);
5. **synthesize**: a clip's face curves with the trained bundle (``DIR/synth.csv``).

It ends by printing where the report is. An existing ``--out`` is refused unless ``--force``, which
replaces only a previous demo output (it holds a ``.effortface-demo`` file) or an empty folder; by
default a fresh timestamped folder is made in the current directory.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from effortface.core.errors import UserError
from effortface import SAMPLE_LAB
from effortface.train.face_fit import MIN_ROWS_PER_PARTICIPANT

#: replay speed and capture length: 12 s of capture at 25x = 5 minutes of the recording
REPLAY_SPEED = 25.0
CAPTURE_S = 12.0
#: a file written into every demo output folder: only such a folder (or an empty one) is replaced by --force
MARKER = ".effortface-demo"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface demo``."""
    parser.add_argument("--out", metavar="DIR", help="output folder (default: effortface-demo-<time>)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out made by a previous demo (or empty)")
    parser.add_argument("--lab", default=str(SAMPLE_LAB), metavar="DIR", help="the sessions to use")
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


def _contains(folder: Path, other: Path) -> bool:
    """Whether ``other`` is ``folder`` or inside it (both resolved)."""
    folder, other = folder.resolve(), other.resolve()
    return other == folder or folder in other.parents


def _out_dir(args: argparse.Namespace) -> Path:
    """The output folder: a fresh timestamped one, or --out (refused if it exists without --force).

    ``--force`` replaces only a previous demo output (a folder holding :data:`MARKER`) or an empty
    folder; never a file, another folder, the lab or the current directory. Nothing is removed here:
    :func:`_replace_out` does it, once every option has been checked.
    """
    if args.out is None:
        return Path(f"effortface-demo-{_dt.datetime.now():%Y%m%d-%H%M%S}")
    out = Path(args.out)
    if not out.exists() and not out.is_symlink():
        return out
    if not args.force:
        raise UserError(f"--out {out}: expected a new folder, found an existing one (pass --force)")
    if out.is_symlink() or not out.is_dir():
        raise UserError(f"--out {out}: expected a folder made by effortface demo, found "
                        f"{'a symbolic link' if out.is_symlink() else 'a file'} (not replaced)")
    lab = Path(getattr(args, "lab", None) or SAMPLE_LAB)
    for name, protected in (("the current directory", Path.cwd()), ("the --lab folder", lab),
                            ("the sample lab", SAMPLE_LAB)):
        if protected.exists() and _contains(out, protected):
            raise UserError(f"--out {out}: expected a folder made by effortface demo, found {name} "
                            "or a folder holding it (not replaced)")
    if not (out / MARKER).is_file() and any(out.iterdir()):
        raise UserError(f"--out {out}: expected a folder made by effortface demo (with {MARKER}) or an "
                        "empty folder, found other files (not replaced)")
    return out


def _replace_out(out: Path) -> None:
    """Remove a previous demo output that :func:`_out_dir` accepted, then make ``out`` afresh with its marker."""
    if out.is_dir():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    (out / MARKER).write_text("made by 'effortface demo'; 'effortface demo --force' may replace this folder\n",
                              encoding="utf-8")


def _say(step: str, text: str) -> None:
    print(f"[{step}] {text}", flush=True)


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "effortface", *args]


def capture_step(session: Path, out: Path, seconds: float) -> Path:
    """Replay the session's strap log through a pseudo-terminal into ``effortface capture``."""
    from effortface.capture_tool.session import read_session

    s = read_session(session)
    logs = s.serlog_paths()
    if not logs:
        raise UserError(f"{session / 'serial'}: expected a .serlog strap recording, found none")
    protocol = str(s.devices.get("heart_rate", {}).get("protocol", logs[0].stem))
    with subprocess.Popen(_cli("replay", str(logs[0]), "--speed", str(REPLAY_SPEED)),
                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True) as replay:
        try:
            port = replay.stdout.readline().strip() if replay.stdout else ""
            if not port:
                raise UserError(f"{logs[0]}: expected 'effortface replay' to print a port, found nothing")
            cmd = _cli("capture", "--port", port, "--protocol", protocol, "--no-video",
                       *_participant_options(s.participant), "--label", "demo",
                       "--duration", str(seconds), "--out", str(out / "captured"))
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=seconds + 60)
        finally:
            replay.terminate()  # our own child: the replay would otherwise play to the end
    if done.returncode != 0:
        raise UserError(f"effortface capture on {port}: expected exit 0, found {done.returncode}: "
                        f"{done.stderr.strip().splitlines()[-1] if done.stderr.strip() else ''}")
    return Path(done.stdout.strip().splitlines()[0])


def _participant_options(p: object) -> list[str]:
    """``--participant CODE --age ...`` for the recorded fields of a participant."""
    opts = ["--participant", p.code]  # type: ignore[attr-defined]
    for flag, name in (("--age", "age"), ("--sex", "sex"), ("--height", "height_m"),
                       ("--mass", "mass_kg"), ("--training-level", "training_level")):
        if getattr(p, name) is not None:
            opts += [flag, str(getattr(p, name))]
    return opts


def decode_step(captured: Path, out: Path) -> tuple[int, int]:
    """Decode the captured raw bytes with ``effortface decode``; (decoded rows, recorded rows)."""
    from effortface.capture_tool.session import read_session

    s = read_session(captured)
    log = s.serlog_paths()[0]
    protocol = str(s.devices.get("heart_rate", {}).get("protocol", log.stem))
    target = out / "decoded_heart_rate.csv"
    with open(target, "w", encoding="utf-8") as fh:
        done = subprocess.run(_cli("decode", "--protocol", protocol, str(log)), stdout=fh,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    if done.returncode != 0:
        raise UserError(f"effortface decode {log}: expected exit 0, found {done.returncode}: "
                        f"{done.stderr.strip()}")
    decoded = len(pd.read_csv(target))
    return decoded, len(s.heart_rate)


def synth_step(model_dir: Path, lab: Path, out: Path) -> Path:
    """Face curves for a motion clip of the lab (or a session's work.csv) with the trained bundle."""
    from effortface.capture_tool.session import list_sessions, read_session
    from effortface.train.runtime import Character, load_model

    model = load_model(model_dir)
    sessions = list_sessions(lab)
    clips = [c for s in sessions for c in sorted((s / "motion").glob("*")) if c.suffix in (".bvh", ".npz")]
    p = read_session(sessions[0]).participant
    character = Character(age=p.age, sex=p.sex, height_m=p.height_m, mass_kg=p.mass_kg,
                          training_level=p.training_level)
    if clips:
        curves = model.synthesize(clips[0], character)
    else:
        work = pd.read_csv(sessions[0] / "work.csv")
        curves = model.curves_from_work(work["t_s"], work["w_per_kg"], work["p_per_kg"], 1.0, character)
    target = out / "synth.csv"
    pd.DataFrame(curves).to_csv(target, index=False, float_format="%.5g")
    return target


def held_out_summary(metrics: dict) -> str:
    """One line of the training run's held-out scores (model.json metrics): heart rate of the
    training-level model on held-out participants and of the own model on held-out sessions; face
    SVR on held-out participants with expressiveness estimated without their key-frames."""
    hr = metrics.get("hr", {})
    face = [r for r in metrics.get("face_held_out", []) if r.get("model") == "svr" and r.get("r") is not None]
    parts = [f"{label} r {hr[k]['r']:.2f}" for k, label in (("tl_regression", "heart rate TL model"),
                                                          ("per_participant", "own model on other sessions"))
             if k in hr and hr[k].get("r") is not None]
    if face:
        parts.append(f"face r {sum(r['r'] for r in face) / len(face):.2f}")
    return "held out (not fitted on the scored participant or session): " + "; ".join(parts)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``effortface demo``."""
    from effortface.capture_tool.session import list_sessions
    from effortface.train.commands.evaluate import evaluate_bundle
    from effortface.train.commands.train import run_training
    from effortface.train.dataset import sessions_table
    from effortface.train.face_fit import FaceFitConfig
    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.train.report import _md

    _check_options(args)
    lab = Path(args.lab)
    sessions = list_sessions(lab)
    if not sessions:
        raise UserError(f"--lab {lab}: expected session folders, found none "
                        "(run python sample_sessions/generate.py)")
    out = _out_dir(args)
    _replace_out(out)
    t0 = time.monotonic()
    _say("capture", f"replaying {sessions[0].name}'s strap at {REPLAY_SPEED:g}x into effortface capture")
    captured = capture_step(sessions[0], out, args.capture_seconds)
    decoded, recorded = decode_step(captured, out)
    _say("decode", f"{captured.name}: {recorded} samples recorded live, {decoded} decoded from the raw bytes")
    table = sessions_table([lab], DEFAULT_SET)
    _say("train", f"{table['participant'].nunique()} participants, {table['session'].nunique()} sessions, "
                  f"{len(table)} participant-seconds")
    result = run_training(table, DEFAULT_SET, out / "model",
                          config=FaceFitConfig(max_rows_per_participant=args.max_rows),
                          sources=[str(lab)], rater_policy="mean")
    ev = evaluate_bundle(out / "model", table, str(lab))
    (out / "evaluation.md").write_text(f"# Evaluation of {out / 'model'} on {lab}\n\n{_md(ev.hr)}\n\n"
                                       f"{_md(ev.face)}\n", encoding="utf-8")
    _say("evaluate", f"in-sample (the model re-scored on the lab it was trained on): heart rate r "
                     f"{ev.hr['r'].mean():.2f}; face r {ev.face['r'].mean():.2f} ({out / 'evaluation.md'})")
    _say("evaluate", held_out_summary(result.metrics))
    _say("synth", f"face curves: {synth_step(out / 'model', lab, out)}")
    _say("done", f"in {time.monotonic() - t0:.0f} s")
    print(f"report: {result.report}")
    return 0
