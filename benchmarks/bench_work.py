"""``effortface work`` on a generated 1-hour session: seconds and ratio to real time.

The session (made here, in a temporary folder): one hour of 1 Hz heart rate, 30 fps video frame
times, and an exercise log in the current vocabulary: a circuit of treadmill walks and runs (speed
and grade changes), cycle-ergometer bouts (power and cadence), squat, lunge and jumping-jack sets
with reps and back / hand loads, strength-machine sets (machine_kg, rom) and rests, about 40 phases
and 200 parameter rows. A second copy also has the real CMU 13_29 full routine (38 s at 30 fps,
tests/data/motion) attached at two offsets, so two stretches come from motion.

Measured in one process (best of ``--repeat`` runs, each on a fresh copy so work.csv is new):

- baseline: ``read_session`` alone (parsing the session's files: the floor any command pays);
- ``effortface work`` (the command's ``run``) on the log-only session, and on the session with motion.

Printed: seconds, ratio to the baseline, and real-time ratio (3600 s of session per second of work).

Run: ``python benchmarks/bench_work.py [--repeat 5]``
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from effortface.capture_tool.protocols import HrSample  # noqa: E402
from effortface.core.session.folder import (Event, EventWriter, FrameTimeWriter, HrWriter, Participant,  # noqa: E402
                                             SessionInfo, create_session, read_session)
from effortface.synth.attach import attach_clip  # noqa: E402
from effortface.synth.work import write_works  # noqa: E402

HOUR_S = 3600.0
CLIP = ROOT / "tests" / "data" / "motion" / "cmu_13_29_full_30fps.bvh"


def _circuit(rng: np.random.Generator) -> list[Event]:
    """About 40 phases of a gym circuit with their parameters, over one hour."""
    out, t = [Event(0.0, "sync", "session_start")], 0.0
    plan = [("rest", 60), ("treadmill", 300), ("cycle_ergometer", 240), ("squats", 60), ("rest", 60),
            ("jumping_jacks", 45), ("lunges", 60), ("strength_machine", 60), ("rest", 75)]
    while t < HOUR_S - 400:
        for exercise, length_s in plan:
            out.append(Event(t, "phase_start", exercise))
            out += _parameters(exercise, t, length_s, rng)
            out.append(Event(t + length_s - 0.01, "phase_end", exercise))
            t += length_s
    return out


def _parameters(exercise: str, t: float, length_s: float, rng: np.random.Generator) -> list[Event]:
    """Parameter rows of one phase (speed / grade steps, power, reps, loads)."""
    if exercise == "treadmill":
        return [e for k in range(10) for e in (Event(t + 30 * k, "speed", exercise, f"{rng.uniform(1.0, 3.8):.1f}"),
                                               Event(t + 30 * k, "grade", exercise, f"{rng.integers(0, 8)}"))]
    if exercise == "cycle_ergometer":
        return [Event(t + 60 * k, "power", exercise, f"{rng.integers(80, 250)}") for k in range(4)] + \
            [Event(t, "cadence", exercise, "85")]
    if exercise in ("squats", "lunges", "jumping_jacks"):
        return [Event(t, "load", "back_kg", f"{rng.choice([0, 10, 20])}"),
                Event(t, "load", "left_kg", f"{rng.choice([0, 5])}"),
                Event(t + length_s - 1, "reps", exercise, f"{rng.integers(10, 40)}")]
    if exercise == "strength_machine":
        return [Event(t, "load", "machine_kg", f"{rng.integers(20, 60)}"), Event(t, "rom", exercise, "0.5"),
                Event(t + length_s - 1, "reps", exercise, "12")]
    return []


def make_session(out_dir: Path, seed: int = 0) -> Path:
    """The generated 1-hour session (see the module docstring)."""
    rng = np.random.default_rng(seed)
    part = Participant("B01", sex="male", age=30, height_m=1.8, mass_kg=75, training_level=5)
    folder = create_session(out_dir, SessionInfo("B01_20260101-120000_hour", part, complete=True))
    hr = HrWriter(folder / "heart_rate.csv")
    for t in np.arange(0.0, HOUR_S):
        hr.write(HrSample(float(t), float(rng.uniform(70, 170)), device="bench"))
    hr.close()
    frames = FrameTimeWriter(folder / "video_frames.csv")
    for k, t in enumerate(np.arange(0.0, HOUR_S, 1 / 30)):
        frames.write(k, float(t))
    frames.close()
    events = EventWriter(folder / "events.csv")
    for ev in _circuit(rng):
        events.write(ev)
    events.close()
    return folder


def _median_s(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _timed_work(template: Path, scratch: Path, repeat: int) -> float:
    """Median seconds of ``effortface work`` on fresh copies of the template (no work.csv before)."""
    times = []
    for _ in range(repeat):
        copy = scratch / template.name
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(template, copy)
        start = time.perf_counter()
        write_works([copy])
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        log_only = make_session(root / "log")
        with_motion = Path(shutil.copytree(log_only, root / "motion" / log_only.name))
        attach_clip(with_motion, CLIP, offset_s=400.0)
        second = root / "second.bvh"
        shutil.copyfile(CLIP, second)
        attach_clip(with_motion, second, offset_s=2000.0)
        n_events = len(read_session(log_only).events)  # also warms the imports and the file cache
        _timed_work(with_motion, root / "scratch", 1)
        base = _median_s(lambda: read_session(log_only), args.repeat)
        log_s = _timed_work(log_only, root / "scratch", args.repeat)
        motion_s = _timed_work(with_motion, root / "scratch", args.repeat)
    print(f"1-hour session: 3600 s of heart rate, 108000 frame times, {n_events} events "
          f"(best of {args.repeat}: the machine is shared)")
    print(f"{'case':<44} {'seconds':>8} {'x baseline':>11} {'x real time':>12}")
    for name, secs in (("baseline: read_session", base), ("effortface work, exercise log only", log_s),
                       ("effortface work, log + 2 motion clips (76 s)", motion_s)):
        print(f"{name:<44} {secs:8.3f} {secs / base:11.2f} {HOUR_S / secs:12.0f}")


if __name__ == "__main__":
    main()
