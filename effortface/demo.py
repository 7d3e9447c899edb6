"""The steps of ``effortface demo`` (the command, :mod:`effortface.commands.demo`, parses and prints).

1. **capture** (:func:`capture_step`): one sample session's strap recording (``serial/*.serlog``) is
   replayed through a pseudo-terminal by ``effortface replay`` and recorded by ``effortface capture``
   (two real processes, real serial I/O), into ``DIR/captured/``;
2. **decode** (:func:`decode_step`): ``effortface decode`` turns the captured raw bytes back into a
   heart-rate CSV;
3. **work** (:func:`work_step`): the lab's sessions are copied into ``DIR/lab/`` and
   ``effortface work`` derives each one's ``work.csv`` from its exercise log and motion clips, as in
   a real lab (the sample lab records no work: :func:`effortface.synth.work.derive_work`);
4. **train**: :func:`effortface.train.pipeline.run_training`, the one training run, on ``DIR/lab/``;
5. **evaluate**: :func:`effortface.train.evaluation.evaluate_bundle`, the one evaluation;
   then the machine rater (:func:`rater_step`) on one session of that copy;
6. **synthesize** (:func:`synth_step`): a clip's face curves with the trained bundle, written by
   :func:`effortface.synth.curves_io.write_curves`.

The output folder's rules are :func:`demo_out_dir`'s and :func:`replace_out`'s.
"""

from __future__ import annotations

import datetime as _dt
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd

from effortface.samplelab import repo_lab
from effortface.core.errors import UserError
from effortface.core.participant import Participant

#: replay speed and capture length: 12 s of capture at 25x = 5 minutes of the recording
REPLAY_SPEED = 25.0
CAPTURE_S = 12.0
#: significant digits of the demo's synth.csv
SYNTH_DIGITS = 5
#: a file written into every demo output folder: only such a folder (or an empty one) is replaced by --force
MARKER = ".effortface-demo"


def _contains(folder: Path, other: Path) -> bool:
    """Whether ``other`` is ``folder`` or inside it (both resolved)."""
    folder, other = folder.resolve(), other.resolve()
    return other == folder or folder in other.parents


def demo_out_dir(out_arg: str | None, force: bool = False, lab: str | Path | None = None) -> Path:
    """The output folder: a fresh timestamped one, or ``--out`` (refused if it exists without ``force``).

    ``force`` replaces only a previous demo output (a folder holding :data:`MARKER`) or an empty
    folder; never a file, another folder, the lab or the current directory. Nothing is removed here:
    :func:`replace_out` does it, once every option has been checked.

    Parameters
    ----------
    out_arg : str or None
        The ``--out`` option (None: a new ``effortface-demo-<time>`` folder in the current directory).
    force : bool
        The ``--force`` option.
    lab : path-like, optional
        The ``--lab`` folder (None: the sample lab), which is never replaced; nor is the repository's
        sample lab.

    Returns
    -------
    Path

    Raises
    ------
    UserError
        Naming ``--out`` and why it is not replaced.
    """
    if out_arg is None:
        return Path(f"effortface-demo-{_dt.datetime.now():%Y%m%d-%H%M%S}")
    out = Path(out_arg)
    if not out.exists() and not out.is_symlink():
        return out
    refusal = _not_replaceable(out, lab)
    if refusal is not None:  # --force would be refused too: the hint names another --out
        raise UserError(f"--out {out}: expected a new folder or one made by effortface demo, found {refusal} "
                        "(not replaced: choose another --out)")
    if not force:
        raise UserError(f"--out {out}: expected a new folder, found an existing one (pass --force)")
    return out


def _not_replaceable(out: Path, lab: str | Path | None) -> str | None:
    """Why ``--force`` may not replace the existing ``out`` (None: a previous demo output or empty)."""
    if out.is_symlink() or not out.is_dir():
        return "a symbolic link" if out.is_symlink() else "a file"
    protected_dirs = [("the current directory", Path.cwd()), ("the repository's sample lab", repo_lab())]
    if lab is not None:
        protected_dirs.append(("the --lab folder", Path(lab)))
    for name, protected in protected_dirs:
        if protected is not None and protected.exists() and _contains(out, protected):
            return f"{name} or a folder holding it"
    if not (out / MARKER).is_file() and any(out.iterdir()):
        return f"other files (no {MARKER})"
    return None


def replace_out(out: Path) -> None:
    """Remove a previous demo output that :func:`demo_out_dir` accepted, then make ``out`` afresh with its marker."""
    if out.is_dir():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    (out / MARKER).write_text("made by 'effortface demo'; 'effortface demo --force' may replace this folder\n",
                              encoding="utf-8")


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "effortface", *args]


def capture_step(session: Path, out: Path, seconds: float) -> Path:
    """Replay the session's strap log through a pseudo-terminal into ``effortface capture``.

    Parameters
    ----------
    session : Path
        A session folder with a ``serial/*.serlog`` recording.
    out : Path
        The demo folder: the new session goes into ``out/captured``.
    seconds : float
        Length of the live capture (the replay runs at :data:`REPLAY_SPEED`).

    Returns
    -------
    Path
        The captured session folder.

    Raises
    ------
    UserError
        No recording, or the replay or the capture failed (with its last error line).
    """
    from effortface.core.session.folder import read_session

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


def _participant_options(p: Participant) -> list[str]:
    """``--participant CODE --age ...`` for the recorded fields of a participant."""
    opts = ["--participant", p.code]
    for flag, name in (("--age", "age"), ("--sex", "sex"), ("--height", "height_m"),
                       ("--mass", "mass_kg"), ("--training-level", "training_level")):
        if getattr(p, name) is not None:
            opts += [flag, str(getattr(p, name))]
    return opts


def decode_step(captured: Path, out: Path) -> tuple[int, int]:
    """Decode the captured raw bytes with ``effortface decode`` into ``out/decoded_heart_rate.csv``.

    Parameters
    ----------
    captured : Path
        The session folder :func:`capture_step` made.
    out : Path
        The demo folder.

    Returns
    -------
    decoded, recorded : int
        Heart-rate rows decoded from the raw bytes, and rows the capture recorded live.
    """
    from effortface.core.session.folder import read_session

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


#: the folder of the demo output that holds the copied sessions and their derived work.csv
LAB_COPY = "lab"


def work_step(lab: Path, out: Path) -> tuple[Path, list[str]]:
    """Copy the lab's sessions into ``out/lab`` and run ``effortface work`` on them (a real process).

    Parameters
    ----------
    lab : Path
        The lab (its session folders are copied; it is never written to).
    out : Path
        The demo folder.

    Returns
    -------
    copy : Path
        ``out/lab``, whose sessions now hold a ``work.csv`` each.
    lines : list of str
        ``effortface work``'s summary line per session it derived (sessions of ``lab`` that
        already hold a work.csv keep theirs and are not derived).

    Raises
    ------
    UserError
        If ``effortface work`` fails (with its error line).
    """
    from effortface.core.session.folder import list_sessions

    from effortface.synth.work import WORK_CSV

    copy = out / LAB_COPY
    copy.mkdir()
    missing = []
    for session in list_sessions(lab):
        shutil.copytree(session, copy / session.name)
        if not (session / WORK_CSV).is_file():  # a work.csv of the --lab's own (maybe hand-made) is kept
            missing.append(str(copy / session.name))
    if not missing:
        return copy, []
    done = subprocess.run(_cli("work", *missing), capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise UserError(f"effortface work {copy}: expected exit 0, found {done.returncode}: "
                        f"{done.stderr.strip().splitlines()[-1] if done.stderr.strip() else ''}")
    return copy, done.stdout.strip().splitlines()


def rater_step(session: Path) -> str:
    """Run the machine rater on one session (of the demo's lab copy) and summarise it in one line.

    Parameters
    ----------
    session : Path
        A session folder with video; an existing machine rating is read, not replaced.

    Returns
    -------
    str
        The face-found rate and, per blendshape, Pearson r of the machine's raw (uncalibrated) weights,
        the effort mapping's, against the humans' mean at their key-frames; or why the rater was skipped.
    """
    import importlib.util

    import numpy as np

    if importlib.util.find_spec("ai_edge_litert") is None:
        return "skipped: the package ai-edge-litert is not installed (no wheel for this platform)"
    from effortface.annotate.machine.effort import session_weights
    from effortface.annotate.machine.mapping import human_keys
    from effortface.annotate.machine.preannotate import preannotate_session
    from effortface.annotate.machine.track import FOUR, machine_paths, read_machine_track

    if not machine_paths(session)[0].is_file():
        preannotate_session(session)
    track = read_machine_track(session)
    if track is None or track.t_s.size == 0:
        return f"{session.name}: no machine rating written"
    raw, _ = session_weights(session, track.scores, track.t_s)
    idx, keyed = human_keys(session, np.asarray(track.frame), FOUR)
    parts = []
    for j, name in enumerate(FOUR):
        frames = np.unique(idx[np.isfinite(keyed[:, j])])
        mean = np.array([np.nanmean(keyed[idx == f, j]) for f in frames])
        ok = np.isfinite(raw[frames, j])
        r = (float(np.corrcoef(raw[frames[ok], j], mean[ok])[0, 1])
             if ok.sum() > 2 and np.ptp(raw[frames[ok], j]) > 0 and np.ptp(mean[ok]) > 0 else float("nan"))
        parts.append(f"{name} {r:.2f}")
    found = 100.0 * float(np.mean(track.face))
    return (f"{session.name}: a face on {found:.1f} % of {track.t_s.size} frames; raw machine r vs the "
            f"human mean at their key-frames: " + ", ".join(parts))


def synth_step(model_dir: Path, lab: Path, out: Path) -> Path:
    """Face curves for a motion clip of the lab (or a session's work) with the trained bundle.

    Parameters
    ----------
    model_dir : Path
        The trained bundle.
    lab : Path
        The lab: its first clip, else its first session's work (``work.csv``, else derived as
        ``effortface work`` does); its first participant.
    out : Path
        The demo folder: the curves go to ``out/synth.csv`` (:data:`SYNTH_DIGITS` digits).

    Returns
    -------
    Path
        The CSV written.
    """
    from effortface.core.session.folder import list_sessions, read_session
    from effortface.synth.curves_io import write_curves
    from effortface.synth.runtime import Character, load_model
    from effortface.synth.work import WORK_CSV, derive_work, read_work_csv

    model = load_model(model_dir)
    sessions = list_sessions(lab)
    clips = [c for s in sessions for c in sorted((s / "motion").glob("*")) if c.suffix in (".bvh", ".npz")]
    p = read_session(sessions[0]).participant
    body: dict[str, Any] = {"age": p.age, "sex": p.sex, "height_m": p.height_m, "mass_kg": p.mass_kg,
                            "training_level": p.training_level}
    missing = [name for name, value in body.items() if value is None]
    if missing:
        raise UserError(f"{sessions[0] / 'session.json'}: participant {p.code}: expected "
                        f"{', '.join(missing)} for the synthesized character, found none")
    character = Character(**body)
    if clips:
        curves = model.synthesize(clips[0], character)
    else:
        if (sessions[0] / WORK_CSV).is_file():
            saved = read_work_csv(sessions[0] / WORK_CSV)
            t_s, w, p_ = saved.t_s, saved.w_per_kg, saved.p_per_kg
        else:
            table = derive_work(sessions[0])
            t_s, w, p_ = table.t_s, table.w_per_kg, table.p_per_kg
        curves = model.curves_from_work(t_s, w, p_, 1.0, character)
    return write_curves(out / "synth.csv", curves, model, digits=SYNTH_DIGITS)


def held_out_summary(metrics: dict) -> str:
    """One line of the training run's held-out scores (model.json metrics): heart rate of the
    training-level model on held-out participants and of the own model on held-out sessions; face
    SVR on held-out participants as a game uses it (NHR from work; expressiveness estimated without
    their key-frames), or on measured NHR for a bundle trained before that row existed."""
    hr = metrics.get("hr", {})
    rows = metrics.get("face_held_out", [])
    lead = "svr_as_game" if any(r.get("model") == "svr_as_game" for r in rows) else "svr"
    face = [r for r in rows if r.get("model") == lead and r.get("r") is not None]
    parts = [f"{label} r {hr[k]['r']:.2f}" for k, label in (("tl_regression", "heart rate TL model"),
                                                          ("per_participant", "own model on other sessions"))
             if k in hr and hr[k].get("r") is not None]
    if face:
        label = "face as a game uses it (NHR from work)" if lead == "svr_as_game" else "face"
        parts.append(f"{label} r {sum(r['r'] for r in face) / len(face):.2f}")
    return "held out (not fitted on the scored participant or session): " + "; ".join(parts)
