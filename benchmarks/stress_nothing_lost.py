"""Stress: ``kill -9`` of capture, of recover and of an Annotate process at random moments, N times each,
and what was lost (issue 17; target: nothing beyond the last second of video).

- **capture**: ``effortface replay`` feeds the real HxM capture into a pseudo-terminal,
  ``effortface capture`` records it with a numbered video file; it is killed after a random
  1.5-6 s, then ``effortface recover`` finishes the session. Lost heart rate = samples the serial
  log decodes to that ``heart_rate.csv`` lacks (target 0); lost video = seconds between the last
  heart-rate bytes logged and the last frame kept (target under 1 s); every kept frame must show
  its own number (exact seeks) and the session must validate.
- **recover**: a killed capture's session is copied; ``effortface recover`` on the copy is killed
  at a random moment within the time an uninterrupted recovery takes, then run again; the result must equal an uninterrupted recovery of the
  original (same heart-rate rows, same frame table).
- **annotate**: a process opens the session's Annotate model (autosave on) and sets keys, printing
  each key once its save returned; it is killed at a random moment; the annotation file must read
  and hold every key printed (lost keys, target 0).

Usage: ``python benchmarks/stress_nothing_lost.py [--n 5] [--seed 1] [--keep DIR]``. Not part of the
test run (minutes of wall time).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from effortface.capture_tool.camera import index_video, read_frame  # noqa: E402
from effortface.capture_tool.recorder import decode_serlog  # noqa: E402
from effortface.capture_tool.serlog import read_serlog  # noqa: E402
from effortface.core.session.folder import read_session, validate_session  # noqa: E402
from tests.capture_tool.capture_helpers import (  # noqa: E402
    HXM_DAT,
    content,
    frame_number,
    make_numbered_video,
)

DATA = ROOT / "tests" / "data"
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}


def effortface(*args: object) -> list[str]:
    return [sys.executable, "-m", "effortface", *map(str, args)]


def run(*args: object) -> subprocess.CompletedProcess:
    return subprocess.run(effortface(*args), capture_output=True, text=True, errors="replace", env=ENV, timeout=300)


def killed_capture(work: Path, video: Path, rng: random.Random) -> tuple[Path, float]:
    """Record with a replayed strap and a video, kill -9 after a random delay; the session and the delay."""
    replay = subprocess.Popen(effortface("replay", DATA / HXM_DAT, "--speed", "4"), stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True, env=ENV)
    pty = replay.stdout.readline().strip()
    cap = subprocess.Popen(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P01",
                                      "--video", video, "--out", work / "out"),
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=ENV)
    path = Path(cap.stdout.readline().strip())
    delay_s = rng.uniform(1.5, 6.0)
    time.sleep(delay_s)
    cap.send_signal(signal.SIGKILL)
    cap.wait()
    replay.terminate()
    replay.wait()
    return path, delay_s


def losses(path: Path) -> dict[str, object]:
    """What a recovered session lost: heart-rate rows, video seconds, wrong frames, problems."""
    s = read_session(path)
    (log,) = sorted((path / "serial").glob("*.serlog"))
    want = content(decode_serlog(log))
    got = content(s.heart_rate)
    last_bytes_s = max((t for t, _ in read_serlog(log).data_chunks()), default=0.0)
    n = index_video(path / "video.avi") if (path / "video.avi").exists() else 0
    wrong = sum(frame_number(read_frame(path / "video.avi", k)) != k for k in {0, n // 2, n - 1} if n)
    return {"hr_rows_lost": len(want) - len(got) if got == want[:len(got)] else "mismatch",
            "video_lost_s": round(max(0.0, last_bytes_s - (s.frame_times_s[-1] if s.frame_times_s else 0.0)), 3),
            "frames": n, "wrong_frames": wrong, "problems": validate_session(path)}


def capture_trial(work: Path, video: Path, rng: random.Random) -> dict[str, object]:
    path, delay_s = killed_capture(work, video, rng)
    rec = run("recover", path)
    out = {"killed_after_s": round(delay_s, 2), "recover_status": rec.returncode}
    return out | losses(path) if rec.returncode == 0 else out | {"recover_error": rec.stderr.strip()[-200:]}


def recover_trial(work: Path, video: Path, rng: random.Random) -> dict[str, object]:
    path, _ = killed_capture(work, video, rng)
    reference = Path(shutil.copytree(path, work / "reference" / path.name))
    t0 = time.monotonic()
    assert run("recover", reference).returncode == 0
    took_s = time.monotonic() - t0  # kill within what an uninterrupted recovery takes
    proc = subprocess.Popen(effortface("recover", path), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)
    delay_s = rng.uniform(0.5 * took_s, took_s)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    again = run("recover", path)
    finished_first = again.returncode == 2 and "complete: true" in again.stderr
    a, b = read_session(path), read_session(reference)
    return {"killed_after_s": round(delay_s, 2), "finished_before_kill": finished_first,
            "second_status": again.returncode, "same_hr": content(a.heart_rate) == content(b.heart_rate),
            "same_frames": a.frame_times_s == b.frame_times_s, "problems": validate_session(path),
            "leftovers": sorted(p.name for p in path.glob(".*"))}


_ANNOTATE = """
import sys
from effortface.annotate.annotate_session import AnnotateSession
m = AnnotateSession(sys.argv[1], "R1", autosave=True)
for k in range(1, 100000):
    m.set_key((k % 100) / 100, frame=(7 * k) % m.n_frames)
    print((7 * k) % m.n_frames, flush=True)
"""


def annotate_trial(session: Path, work: Path, rng: random.Random) -> dict[str, object]:
    from effortface.annotate.keyframes import read_annotations

    folder = Path(shutil.copytree(session, work / "annotate" / session.name))
    proc = subprocess.Popen([sys.executable, "-c", _ANNOTATE, str(folder)], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, env=ENV)
    delay_s = rng.uniform(0.5, 3.0)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGKILL)
    lines = proc.stdout.read().split()
    acked = {int(line) for line in lines}
    proc.wait()
    path = folder / "annotations" / "R1.json"
    try:
        track = read_annotations(path).tracks[read_annotations(path).blendshapes.names[0]]
        kept = {int(k.frame) for k in track.keys}
    except Exception as exc:  # the file must always read: any error here is a loss
        return {"killed_after_s": round(delay_s, 2), "error": f"{type(exc).__name__}: {exc}"}
    return {"killed_after_s": round(delay_s, 2), "saves_acked": len(lines), "keyed_frames_acked": len(acked),
            "keys_lost": len(acked - kept), "tmp_left": len(list(path.parent.glob(".*.tmp")))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5, help="trials of each kind")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--keep", metavar="DIR", help="keep the sessions here")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    work = Path(args.keep or tempfile.mkdtemp(prefix="stress_nothing_lost_"))
    work.mkdir(parents=True, exist_ok=True)
    video = make_numbered_video(work / "numbered.avi", 600, fps=30.0)
    results: dict[str, list] = {"capture": [], "recover": [], "annotate": []}
    for i in range(args.n):
        results["capture"].append(capture_trial(work / f"c{i}", video, rng))
        print("capture", i, json.dumps(results["capture"][-1]), flush=True)
    for i in range(args.n):
        results["recover"].append(recover_trial(work / f"r{i}", video, rng))
        print("recover", i, json.dumps(results["recover"][-1]), flush=True)
    session = next(p for p in sorted((work / "c0" / "out").iterdir()) if (p / "video.avi").exists())
    for i in range(args.n):
        results["annotate"].append(annotate_trial(session, work / f"a{i}", rng))
        print("annotate", i, json.dumps(results["annotate"][-1]), flush=True)
    summary(results)
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0


def summary(results: dict[str, list]) -> None:
    cap, rec, ann = results["capture"], results["recover"], results["annotate"]
    hr_lost = [r.get("hr_rows_lost") for r in cap]
    video_lost = [r.get("video_lost_s", float("nan")) for r in cap]
    print("\nsummary")
    print(f"  capture  x{len(cap)}: heart-rate rows lost {hr_lost}; video lost (s) {video_lost} "
          f"(max {max(video_lost):.3f}); wrong frames {sum(r.get('wrong_frames', 0) for r in cap)}; "
          f"sessions with problems {sum(bool(r.get('problems', True)) for r in cap)}")
    print(f"  recover  x{len(rec)}: equal to an uninterrupted recovery {sum(r['same_hr'] and r['same_frames'] for r in rec)}"
          f"/{len(rec)}; with problems {sum(bool(r['problems']) for r in rec)}; leftovers "
          f"{sum(bool(r['leftovers']) for r in rec)}")
    print(f"  annotate x{len(ann)}: keys lost {[r.get('keys_lost', r.get('error')) for r in ann]} "
          f"of {[r.get('keyed_frames_acked') for r in ann]} keyed frames "
          f"({sum(r.get('saves_acked', 0) for r in ann)} saves) acknowledged")


if __name__ == "__main__":
    sys.exit(main())
