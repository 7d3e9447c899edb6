"""Generate the sample lab: ``python -m effortface.samplelab.generate --out DIR [--only SESSION_ID]
[--seed N] [--force]`` (``python sample_sessions/generate.py`` in the repository, whose default
``--out`` is that folder; :func:`effortface.samplelab.sample_lab` builds a user-cache copy on first use).

Deterministic from the seed: every session draws from its own random stream
(``SeedSequence([seed, session index])``), so ``--only`` regenerates a session exactly as the full
run does. Writes, under ``--out``:

- one session folder per plan of :mod:`simlab.lab` (session format v1, see DESIGN.md): ``session.json``,
  ``serial/<protocol>.serlog`` (real protocol bytes), ``heart_rate.csv`` (decoded from that serlog
  by the project's own decoders), ``events.csv`` (the exercise log in the catalog's vocabulary,
  as an operator records it: no work value), ``video.avi`` + ``video_frames.csv``,
  ``annotations/R1.json`` ... ``R3.json``, and for one strength session ``motion/`` (the real CMU
  squats clip, assembled to the set's length, with ``motion.json`` as ``effortface motion attach``
  writes it). No ``work.csv``: ``effortface work`` derives it, as in a real lab;
- ``reliability/poses.csv`` + ``ratings.csv``: 18 poses rated blind by the three raters;
- ``participants.tsv``: the lab's participant registry (:mod:`effortface.capture_tool.participants`),
  one row per participant with the values of their ``session.json``;
- ``_ground_truth/``: what the stages must recover (true curves, heart parameters, rater errors).

An existing output is never overwritten unless ``--force`` (which replaces only what this run writes).
"""

from __future__ import annotations

import argparse
import datetime as dt
import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from effortface.annotate.reliability import Pose, write_poses, write_ratings
from effortface.capture_tool.participants import REGISTRY_TSV, register
from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.recorder import decode_serlog
from effortface.capture_tool.serlog import DATA, SerlogWriter, read_serlog
from effortface.core.session.folder import (
    EVENTS_CSV, HEART_RATE_CSV, SERIAL_DIR, VIDEO_AVI, VIDEO_FRAMES_CSV, Event, EventWriter,
    FrameTimeWriter, HrWriter, Participant, SessionInfo, create_session, write_json_atomic,
)
from effortface.core.blendshapes import DEFAULT_SET
from effortface.core.version import __version__
from effortface.samplelab.simlab import expression, heart, raters, streams, video
from effortface.samplelab.simlab.lab import PEOPLE, Person, SessionPlan, build_plans, phase_at, work_at

#: the real CMU squats clip, shipped with the package (``data/README.md``): the lab builds anywhere
PACKAGED_MOTION = Path(__file__).resolve().parent / "data"

DEFAULT_SEED = 2015
GROUND_TRUTH = "_ground_truth"
RELIABILITY = "reliability"
#: the session whose first loaded squat set also ships as motion capture
MOTION_SESSION_INDEX = 1
#: the session whose USB cable is pulled for 3 s (text lines, a USB PulseSensor)
UNPLUG_SESSION_INDEX = 3
#: the ANT+ session that sends extended messages (device number 3404)
EXTENDED_ANT_SESSION_INDEX = 4
#: the reliability round draws its 18 poses (3 each) from the first week's six sessions (one per
#: participant, both kinds), as the paper's 18 poses came from its recordings
POSE_SESSION_INDICES = range(6)
SQUATS_CLIP = "cmu_13_29_squats_120fps.bvh"
MOTION_DECIMATE = 4  # 120 Hz -> 30 Hz keeps the clip small; w is frame-rate invariant (SCIENCE 2)


def _rngs(seed: int, index: int, n: int = 6) -> list[np.random.Generator]:
    """Independent generators for one session (heart, faults, bytes, video, raters, face)."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence([seed, index]).spawn(n)]


def participant_heart(person: Person, seed: int) -> heart.HeartParams:
    """A participant's true heart, the same in all their sessions (its own random stream)."""
    return heart.heart_params(person, np.random.default_rng([seed, 1000, PEOPLE.index(person)]))


def _faults(plan: SessionPlan, rng: np.random.Generator) -> streams.LinkFaults:
    """One 8-12 s contact loss and four radio drop-outs (three short, one long)."""
    d = plan.duration_s
    start = round(float(rng.uniform(0.35, 0.6) * d), 2)
    loss = (start, round(start + float(rng.uniform(8, 12)), 2))
    drops = []
    for frac, length in ((0.15, 1.2), (0.3, 2.0), (0.75, 1.5), (0.88, 5.0)):
        a = round(float(frac * d + rng.uniform(-5, 5)), 2)
        drops.append((a, round(a + length * float(rng.uniform(0.8, 1.2)), 2)))
    return streams.LinkFaults(loss, tuple(drops), n_corrupt_bytes=4)


def _serial_header(plan: SessionPlan) -> dict:
    port = {"ant": "/dev/ttyUSB0", "hxm": "/dev/rfcomm0", "hrmi": "/dev/ttyUSB1", "lines": "/dev/ttyACM0"}
    settings = {"baudrate": streams.BAUD[plan.protocol], "bytesize": 8, "parity": "N", "stopbits": 1,
                "xonxoff": False, "dsrdtr": False, "rtscts": False, "timeout": 0.1,
                "write_timeout": None, "inter_byte_timeout": None}
    return {"protocol": plan.protocol, "port": port[plan.protocol], "device": plan.protocol,
            "settings": settings}


def _speed_at(plan: SessionPlan) -> Callable[[float], float]:
    """Treadmill speed (m/s) at a time, for the HxM speed field."""
    def speed(t: float) -> float:
        ph = phase_at(plan, t)
        return float(ph.speed_m_s or 0.0) if ph else 0.0
    return speed


def write_serial(folder: Path, plan: SessionPlan, beats: np.ndarray, faults: streams.LinkFaults,
                 rng: np.random.Generator) -> tuple[Path, list[dict], list[tuple[float, float]]]:
    """Encode the beats, spoil them a little, write ``serial/<protocol>.serlog``.

    One text-lines session also loses its USB cable for 3 s (a ``device_gap`` then a
    ``reconnect`` record, as the link writes them). Returns the path, the corrupted bytes and the
    unplug windows.
    """
    device_number = 3404 if plan.index == EXTENDED_ANT_SESSION_INDEX else None
    chunks = streams.chunks_for(plan.protocol, beats, faults, plan.duration_s, rng,
                                device_number=device_number, speed_at=_speed_at(plan))
    chunks, corrupted = streams.corrupt(chunks, faults.n_corrupt_bytes, rng)
    unplugs = [(round(0.22 * plan.duration_s, 2), round(0.22 * plan.duration_s + 3.0, 2))] \
        if plan.index == UNPLUG_SESSION_INDEX else []
    path = folder / SERIAL_DIR / f"{plan.protocol}.serlog"
    header = _serial_header(plan)
    with SerlogWriter(path, header) as log:
        pending = list(unplugs)
        for t, data in chunks:
            while pending and t >= pending[0][0]:
                a, b = pending.pop(0)
                log.write_event(a, "device_gap", plan.protocol, "[Errno 5] Input/output error")
                log.write_event(b, "reconnect", plan.protocol, header["port"])
            if not any(a <= t < b for a, b in unplugs):
                log.write(round(t, 6), data)
    return path, corrupted, unplugs


def link_events(serlog: Path) -> list[Event]:
    """The link events a live capture would have logged: decoder state changes, gaps, reconnects."""
    log = read_serlog(serlog)
    decoder = get_decoder(str(log.header["protocol"]))
    out: list[Event] = []
    for rec in log.records:
        if rec.kind == DATA:
            decoder.feed(rec.payload, rec.t_s)
            out += [Event(e.t_s, e.kind, e.label, e.value) for e in decoder.pop_events()]
        else:
            ev = rec.event()
            out.append(Event(rec.t_s, ev["kind"], ev.get("label", ""), ev.get("value", "")))
            if ev["kind"] == "device_gap":
                decoder.finish()
    return out


def write_heart_rate(folder: Path, serlog: Path) -> int:
    """``heart_rate.csv`` decoded from the serlog exactly as a capture does; return the rows."""
    samples = decode_serlog(serlog)
    writer = HrWriter(folder / HEART_RATE_CSV)
    for s in samples:
        writer.write(s)
    writer.close()
    return len(samples)


def phase_events(plan: SessionPlan) -> list[Event]:
    """The exercise log as an operator records it (DESIGN.md "Exercise log"): catalog ids on
    ``phase_start`` / ``phase_end`` with no value, the treadmill's speed and grade when set, the back
    load before a set (and back to 0 after it), a ``reps`` row per repetition (the hotkey counter)
    for squats, and the count at the end of a jumping-jacks set. No true work anywhere."""
    out = [Event(0.0, "sync", "session_start", "")]
    load_kg, speed, grade = 0.0, None, 0.0
    for ph in plan.phases:
        out.append(Event(ph.start_s, "phase_start", ph.exercise, ""))
        if ph.exercise == "treadmill":
            if ph.speed_m_s != speed:
                out.append(Event(ph.start_s + 0.5, "speed", "treadmill", f"{ph.speed_m_s:.1f}"))
            if ph.grade_pct != grade:
                out.append(Event(ph.start_s + 0.5, "grade", "treadmill", f"{ph.grade_pct:g}"))
            speed, grade = ph.speed_m_s, ph.grade_pct
        if ph.exercise == "squats" and ph.load_kg != load_kg:
            out.append(Event(ph.start_s - 5.0, "load", "back_kg", f"{ph.load_kg:g}"))
            load_kg = ph.load_kg
        if ph.exercise == "squats":
            out += [Event(t, "reps", ph.exercise, str(k + 1)) for k, t in enumerate(ph.rep_times_s)]
        elif ph.rep_times_s:
            out.append(Event(ph.rep_times_s[-1], "reps", ph.exercise, str(ph.reps)))
        out.append(Event(ph.end_s - 0.01, "phase_end", ph.exercise, ""))
        if ph.exercise == "squats" and load_kg:
            out.append(Event(ph.end_s + 3.0, "load", "back_kg", "0"))
            load_kg = 0.0
    return out


def write_events(folder: Path, events: list[Event]) -> None:
    """``events.csv`` in time order."""
    writer = EventWriter(folder / EVENTS_CSV)
    for ev in sorted(events, key=lambda e: e.t_s):
        writer.write(ev)
    writer.close()


def write_frames_and_video(folder: Path, plan: SessionPlan, grid_t: np.ndarray, curves: np.ndarray,
                           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Frame times, ``video_frames.csv`` and the rendered ``video.avi``; returns (times, true weights)."""
    times = video.frame_times(plan.duration_s, rng)
    truth = expression.at_times(grid_t, curves, times)
    writer = FrameTimeWriter(folder / VIDEO_FRAMES_CSV)
    for i, t in enumerate(times):
        writer.write(i, float(t))
    writer.close()
    poses = video.head_motion(times, work_at(plan, times), rng)
    who = PEOPLE.index(plan.person)  # the same face in both of a participant's sessions
    video.write_video(folder / VIDEO_AVI, truth, poses, video.lighting(times, rng), who, rng)
    return np.round(times, 4), truth


def write_annotations(folder: Path, plan: SessionPlan, times: np.ndarray, truth: np.ndarray,
                      rng: np.random.Generator) -> None:
    """``annotations/R1.json`` ... ``R3.json`` from the simulated raters."""
    for design in raters.RATERS:
        ann = raters.annotate(plan.session_id, times, truth, design, rng)
        ann.save(folder / "annotations" / f"{design.rater}.json")


def write_motion(folder: Path, plan: SessionPlan, shared_motion: Path) -> dict | None:
    """The first loaded squat set as motion capture: the real CMU squats clip, decimated to 30 Hz
    and looped forwards then backwards (no jump at the seams) to the set's length;
    ``motion/motion.json`` holds its offset to session time."""
    src = shared_motion / SQUATS_CLIP
    phase = next((p for p in plan.phases if p.exercise == "squats" and p.load_kg > 0), None)
    if phase is None or not src.is_file():
        return None
    lines = src.read_text(encoding="utf-8").splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("Frame Time"))
    frames = lines[at + 1:][::MOTION_DECIMATE]
    frames += frames[-2:0:-1]  # ping-pong: a loop without a jump at the seam
    dt_s = float(lines[at].split(":")[1]) * MOTION_DECIMATE
    n = int((phase.end_s - phase.start_s) / dt_s)
    body = [frames[i % len(frames)] for i in range(n)]
    out = folder / "motion"
    out.mkdir()
    header = lines[:at - 1] + [f"Frames: {n}", f"Frame Time: {dt_s:.7f}"]
    (out / "squats_set2.bvh").write_text("\n".join(header + body) + "\n", encoding="utf-8")
    meta = {"files": [{"path": "squats_set2.bvh", "offset_s": phase.start_s, "format": "bvh",
                       "aligned": "offset", "duration_s": round(n * dt_s, 3),
                       "source": f"../shared/data/motion/{SQUATS_CLIP} (CMU Graphics Lab Motion "
                                 "Capture Database, subject 13 trial 29), every "
                                 f"{MOTION_DECIMATE}th frame, looped forwards and backwards"}]}
    write_json_atomic(out / "motion.json", meta)
    return meta


def _participant(person: Person) -> Participant:
    """The participant record a capture writes (session.json and participants.tsv alike)."""
    return Participant(person.code, person.sex, person.age, person.height_m, person.mass_kg,
                       person.training_level)


def write_participants(out: Path, plans: Sequence[SessionPlan]) -> Path:
    """``participants.tsv``: one registry row per participant, in code order, as captures register them."""
    path = out / REGISTRY_TSV
    for person in sorted({p.person.code: p.person for p in plans}.values(), key=lambda q: q.code):
        register(path, _participant(person))
    return path


def _session_info(plan: SessionPlan, seed: int) -> SessionInfo:
    """``session.json`` as the recorder writes it, marked as simulated (complete once all is written)."""
    p = plan.person
    created = (plan.start - dt.timedelta(hours=1)).strftime("%Y-%m-%dT%H:%M:%SZ")  # lab at UTC+1
    camera = {"source": "simulated", "width": video.WIDTH, "height": video.HEIGHT, "fps": video.FPS,
              "codec": "MJPG"}
    return SessionInfo(
        session_id=plan.session_id,
        participant=_participant(p),
        devices={"heart_rate": _serial_header(plan), "camera": camera},
        complete=False, created_utc=created,
        software={"name": "effortface", "version": __version__},
        extra={"simulated": {"generator": "sample_sessions/generate.py", "seed": seed,
                             "kind": plan.kind}},
    )


def generate_session(out: Path, plan: SessionPlan, seed: int, shared_motion: Path) -> dict:
    """Write one session folder and its ground truth; return what the pose set needs."""
    r_heart, r_faults, r_bytes, r_video, r_raters, r_face, r_day = _rngs(seed, plan.index, 7)
    hp = participant_heart(plan.person, seed)
    day = heart.day_state(r_day)
    grid_t, drive, hr = heart.simulate_hr(plan, hp, day)
    beats = heart.beat_times(grid_t, hr, hp, r_heart)
    faults = _faults(plan, r_faults)
    info = _session_info(plan, seed)
    folder = create_session(out, info)
    serlog, corrupted, unplugs = write_serial(folder, plan, beats, faults, r_bytes)
    n_hr = write_heart_rate(folder, serlog)
    write_events(folder, phase_events(plan) + link_events(serlog))
    nhr = heart.normalised(hr, hp)
    d = expression.drivers(plan, grid_t, drive, nhr, hp, day, r_face)
    curves = expression.true_curves(d, plan.person.expressiveness, r_face)
    times, truth = write_frames_and_video(folder, plan, grid_t, curves, r_video)
    write_annotations(folder, plan, times, truth, r_raters)
    motion = write_motion(folder, plan, shared_motion) if plan.index == MOTION_SESSION_INDEX else None
    info.complete = True
    info.extra["stats"] = {"heart_rate_rows": n_hr, "video_frames": int(times.size)}
    info.save(folder, overwrite=True)
    truth_meta = {"heart": hp.__dict__, "day": day.__dict__, "phases": [
                      {"start_s": ph.start_s, "end_s": ph.end_s, "exercise": ph.exercise,
                       "true_w_per_kg": round(ph.w_per_kg, 3), "demand_w_per_kg": round(ph.drive_w_per_kg, 3),
                       "speed_m_s": ph.speed_m_s, "grade_pct": ph.grade_pct, "load_back_kg": ph.load_kg,
                       "rep_times_s": list(ph.rep_times_s)} for ph in plan.phases],
                  "faults": {"contact_loss_s": faults.contact_loss,
                  "dropouts_s": faults.dropouts, "corrupted_bytes": corrupted, "unplugs_s": unplugs},
                  "beats": int(beats.size), "motion": motion}
    d["work"] = work_at(plan, grid_t)
    _write_truth(out / GROUND_TRUTH / plan.session_id, grid_t, drive, hr, nhr, d, times, truth, truth_meta)
    return {"index": plan.index, "times": times, "truth": truth,
            "nhr_frames": np.interp(times, grid_t, nhr)}


def _write_truth(folder: Path, grid_t: np.ndarray, drive: np.ndarray, hr: np.ndarray, nhr: np.ndarray,
                 d: dict, times: np.ndarray, truth: np.ndarray, meta: dict) -> None:
    """Per-frame true weights, 1 Hz true physiology and the session's hidden facts."""
    folder.mkdir(parents=True)
    names = ",".join(DEFAULT_SET.names)
    rows = [f"{i},{t:.4f}," + ",".join(f"{v:.4f}" for v in w) for i, (t, w) in enumerate(zip(times, truth))]
    (folder / "blendshapes.csv").write_text(f"frame,t_s,{names}\n" + "\n".join(rows) + "\n", encoding="utf-8")
    step = int(round(1.0 / heart.DT_S))
    phys = ["t_s,w_per_kg,drive_w_per_kg,hr_bpm,nhr,relative_intensity,exertion,fatigue,ventilation,strain"] + [
        f"{grid_t[k]:.1f},{d['work'][k]:.3f},{drive[k]:.3f},{hr[k]:.2f},{nhr[k]:.4f}," + ",".join(
            f"{d[name][k]:.4f}" for name in ("relative_intensity", "exertion", "fatigue", "ventilation", "strain"))
        for k in range(0, grid_t.size, step)]
    (folder / "physiology.csv").write_text("\n".join(phys) + "\n", encoding="utf-8")
    write_json_atomic(folder / "session_truth.json", meta)


def write_lab_truth(out: Path, plans: Sequence[SessionPlan], seed: int) -> None:
    """``_ground_truth/lab.json``: participants' hidden traits and the raters' designed errors."""
    people: dict[str, dict] = {}
    for plan in plans:
        entry = people.setdefault(plan.person.code, {
            **plan.person.__dict__, "sessions": {},
            "heart": participant_heart(plan.person, seed).__dict__})
        entry["sessions"][plan.session_id] = {"kind": plan.kind, "protocol": plan.protocol}
    doc = {"seed": seed, "blendshapes": list(DEFAULT_SET.names), "participants": people,
           "raters": {r.rater: {**r.__dict__, "designed_mae": r.designed_mae()} for r in raters.RATERS}}
    (out / GROUND_TRUTH).mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / GROUND_TRUTH / "lab.json", doc)


def write_reliability(out: Path, made: dict[str, dict], seed: int) -> float:
    """18 poses (3 from each first-week session, see ``POSE_SESSION_INDICES``) and the three
    raters' blind ratings; return the disagreement %."""
    from effortface.annotate.reliability import mean_abs_disagreement_pct

    poses: list[Pose] = []
    truth_by_pose: dict[str, np.ndarray] = {}
    for sid, m in made.items():
        if m["index"] not in POSE_SESSION_INDICES:
            continue
        chosen = raters.choose_poses(sid, m["times"], m["nhr_frames"], m["truth"], len(poses) + 1)
        for pose in chosen:
            truth_by_pose[pose.pose_id] = m["truth"][pose.frame]
        poses += chosen
    ratings = raters.rate_poses(poses, truth_by_pose, np.random.default_rng([seed, 999]))
    folder = out / RELIABILITY
    folder.mkdir()
    write_poses(folder / "poses.csv", poses)
    write_ratings(folder / "ratings.csv", ratings)
    truth_rows = [f"{pid}," + ",".join(f"{v:.4f}" for v in w) for pid, w in truth_by_pose.items()]
    (out / GROUND_TRUTH / "poses_truth.csv").write_text(
        "pose_id," + ",".join(DEFAULT_SET.names) + "\n" + "\n".join(truth_rows) + "\n", encoding="utf-8")
    return mean_abs_disagreement_pct(ratings)


def _targets(out: Path, plans: Sequence[SessionPlan], only: str | None) -> list[Path]:
    """What this run writes (and what --force may replace)."""
    paths = [out / p.session_id for p in plans] + [out / GROUND_TRUTH / p.session_id for p in plans]
    if only is None:
        paths += [out / RELIABILITY, out / GROUND_TRUTH, out / REGISTRY_TSV]
    return paths


def _parser(default_out: Path | None) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description="Regenerate the simulated sample lab (deterministic).")
    if default_out is None:
        ap.add_argument("--out", type=Path, required=True, help="output folder")
    else:
        ap.add_argument("--out", type=Path, default=default_out, help=f"output folder (default: {default_out})")
    ap.add_argument("--only", metavar="SESSION_ID", help="generate this session only")
    ap.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"master seed (default {DEFAULT_SEED})")
    ap.add_argument("--force", action="store_true", help="replace an existing output of this run")
    ap.add_argument("--shared-motion", type=Path, default=PACKAGED_MOTION,
                    help="folder with the real CMU squats clip (default: the copy shipped with effortface)")
    return ap


def build_lab(out: Path, plans: Sequence[SessionPlan] | None = None, seed: int = DEFAULT_SEED,
              shared_motion: Path = PACKAGED_MOTION, say: Callable[[str], object] = print) -> None:
    """Write the sessions of ``plans`` (default: the whole lab, with its reliability round) under ``out``.

    Parameters
    ----------
    out : Path
        Output folder (made if missing); the targets must not exist (:func:`main` checks ``--force``).
    plans : sequence of SessionPlan, optional
        A subset of :func:`~effortface.samplelab.simlab.lab.build_plans` (``--only``); the lab-wide
        truth and the reliability round are written only for the whole lab.
    seed : int
        Master seed.
    shared_motion : Path
        Folder holding the CMU squats clip.
    say : callable
        Receives one progress line per session (``print`` by default).
    """
    whole = plans is None
    plans = build_plans(seed) if plans is None else plans
    made = {}
    for plan in plans:
        made[plan.session_id] = generate_session(out, plan, seed, shared_motion)
        say(f"{plan.session_id}: {plan.duration_s:.0f} s, {plan.protocol}")
    if whole:
        write_participants(out, plans)
        write_lab_truth(out, plans, seed)
        pct = write_reliability(out, made, seed)
        say(f"reliability: 18 poses, mean disagreement {pct:.1f} % of the weight range")


def main(argv: Sequence[str] | None = None, default_out: Path | None = None) -> int:
    """Command-line entry point; returns the exit status (2 with one line on a usage error).

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments (default: ``sys.argv[1:]``).
    default_out : Path, optional
        ``--out`` when not given (the repository's ``sample_sessions/`` for its wrapper script);
        without it ``--out`` is required.
    """
    args = _parser(default_out).parse_args(argv)
    plans = build_plans(args.seed)
    if args.only is not None:
        plans = tuple(p for p in plans if p.session_id == args.only)
        if not plans:
            ids = ", ".join(p.session_id for p in build_plans())
            print(f"generate.py: error: --only: expected one of {ids}, found {args.only!r}", file=sys.stderr)
            return 2
    existing = [p for p in _targets(args.out, plans, args.only)
                if p.is_file() or (p.is_dir() and any(p.iterdir()))]
    if existing and not args.force:
        print(f"generate.py: error: {existing[0]}: output exists; refusing to overwrite (use --force)",
              file=sys.stderr)
        return 2
    for p in existing:
        if p.is_file():
            p.unlink()
        elif p.exists():  # a session's truth goes with _ground_truth/ when that is replaced
            shutil.rmtree(p)
    build_lab(args.out, None if args.only is None else plans, args.seed, args.shared_motion,
              say=lambda line: print(line, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
