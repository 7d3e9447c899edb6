"""Capture benchmark: minutes of 640x480 video at 30 fps from a file plus a replayed HxM strap.

Runs ``effortface capture`` as a subprocess on a pseudo-terminal fed by :class:`PtyReplay` (the
real HxM capture, looped) and a generated video file, and prints:

- dropped frames (target 0) and frames written against the frames offered;
- CPU share of the capture process (psutil), against a baseline measured here: a loop that only
  decodes the same video at its real rate;
- delay from a chunk written to the pseudo-terminal to its row appearing in ``heart_rate.csv``
  (target median under 20 ms), against a baseline: the same pty write -> pyserial read, no capture.

Usage: ``python benchmarks/bench_capture.py [--duration 300] [--keep DIR]`` (default: the full
five minutes; ``--duration 30`` for a quick look).
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil
import serial

from effortface.capture_tool.captures import read_timed_capture
from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.replay import PtyReplay, TimedChunk, start_replay_thread

from bench_data import DATA  # ../shared/data, else tests/data

ROOT = Path(__file__).resolve().parents[1]
HXM = DATA / "serial" / "zephyr-bt" / "120-second-bt-stream-hxm.dat"
SIZE = (640, 480)
FPS = 30.0


def make_video(path: Path, duration_s: float) -> Path:
    """A 640x480 MJPG AVI with texture and motion (realistic JPEG sizes), ``duration_s`` long."""
    import cv2

    w, h = SIZE
    rng = np.random.default_rng(1)
    texture = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    texture = cv2.GaussianBlur(texture, (0, 0), 3)
    writer = cv2.VideoWriter(str(path), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*"MJPG"), FPS, SIZE)
    for k in range(int(duration_s * FPS)):
        frame = np.roll(texture, 4 * k, axis=1)
        cv2.circle(frame, (w // 2, h // 2), 60 + k % 40, (255, 255, 255), 3)
        writer.write(frame)
    writer.release()
    return path


def strap_chunks(duration_s: float) -> list[TimedChunk]:
    """The real HxM capture, looped to cover ``duration_s``."""
    base = read_timed_capture(HXM)
    period = base[-1][0] + 1.0
    out: list[TimedChunk] = []
    k = 0
    while k * period < duration_s:
        out += [TimedChunk(t + k * period, d) for t, d in base if t + k * period < duration_s]
        k += 1
    return out


def chunk_of_each_row(chunks: list[TimedChunk]) -> list[int]:
    """Index of the chunk whose arrival completes each heart-rate row (decoded in process)."""
    dec = get_decoder("hxm")
    rows: list[int] = []
    for i, c in enumerate(chunks):
        rows += [i] * len(dec.feed(c.data, c.t_s))
    return rows


def baseline_pty_latency_ms(n: int = 200) -> float:
    """Median pty write -> pyserial read delay in this process, no capture involved."""
    rp = PtyReplay([])
    delays = []
    with serial.Serial(rp.path, timeout=1.0) as ser:
        for _ in range(n):
            t = time.monotonic()
            rp._write_all(b"\x02" * 60)
            got = b""
            while len(got) < 60:
                got += ser.read(max(1, ser.in_waiting))
            delays.append((time.monotonic() - t) * 1000)
            time.sleep(0.002)
    rp.close()
    return statistics.median(delays)


def baseline_decode_cpu(video: Path, seconds: float = 10.0) -> float:
    """CPU share (fraction of one core) of decoding the video at its real rate, in this process."""
    import cv2

    cap = cv2.VideoCapture(str(video))
    proc = psutil.Process()
    c0, t0 = sum(proc.cpu_times()[:2]), time.monotonic()
    n = 0
    while time.monotonic() - t0 < seconds and cap.read()[0]:
        n += 1
        time.sleep(max(0.0, t0 + n / FPS - time.monotonic()))
    cap.release()
    return (sum(proc.cpu_times()[:2]) - c0) / (time.monotonic() - t0)


class RowWatcher(threading.Thread):
    """Tails heart_rate.csv every millisecond; records when each row first appears."""

    def __init__(self, csv_path: Path) -> None:
        super().__init__(daemon=True)
        self.path = csv_path
        self.seen: list[float] = []
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            if self.path.exists():
                n = self.path.read_bytes().count(b"\n") - 1
                now = time.monotonic()
                self.seen += [now] * max(0, n - len(self.seen))
            time.sleep(0.001)


def run_capture(video: Path, chunks: list[TimedChunk], duration_s: float, out: Path) -> dict:
    """Record ``duration_s`` through a pty; return the figures."""
    rp = PtyReplay(chunks)
    cmd = [sys.executable, "-m", "effortface", "capture", "--port", rp.path, "--protocol", "hxm",
           "--video", str(video), "--participant", "B01", "--age", "30", "--sex", "female", "--height", "1.70",
           "--mass", "65", "--training-level", "5", "--duration", str(duration_s), "--out", str(out)]
    cap = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    start_replay_thread(rp)
    session = Path(cap.stdout.readline().strip())
    watcher = RowWatcher(session / "heart_rate.csv")
    watcher.start()
    proc = psutil.Process(cap.pid)
    t0, cpu = time.monotonic(), 0.0
    while cap.poll() is None:
        try:
            cpu = sum(proc.cpu_times()[:2])
        except psutil.NoSuchProcess:
            break
        time.sleep(0.5)
    wall = time.monotonic() - t0
    watcher.stop.set()
    watcher.join()
    rp.stop()
    rp.close()
    stats = json.loads((session / "session.json").read_text())["stats"]
    rows = chunk_of_each_row(chunks)
    writes = dict((i, t) for t, i in rp.write_times)
    delays = [(seen - writes[rows[k]]) * 1000 for k, seen in enumerate(watcher.seen) if k < len(rows) and rows[k] in writes]
    return {"session": session, "stats": stats, "cpu_share": cpu / wall, "delays_ms": delays, "rc": cap.returncode,
            "stderr": cap.stderr.read()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0, help="seconds to record (default 300)")
    parser.add_argument("--keep", type=Path, help="keep the generated video and session here")
    args = parser.parse_args()
    tmp = args.keep or Path(tempfile.mkdtemp(prefix="bench_capture_"))
    tmp.mkdir(parents=True, exist_ok=True)
    t = time.monotonic()
    video = make_video(tmp / "face_640x480.avi", args.duration + 5)
    print(f"video: {int((args.duration + 5) * FPS)} frames 640x480 MJPG, {video.stat().st_size / 1e6:.0f} MB, "
          f"generated in {time.monotonic() - t:.0f} s")
    base_ms = baseline_pty_latency_ms()
    base_cpu = baseline_decode_cpu(video, min(10.0, args.duration))
    r = run_capture(video, strap_chunks(args.duration), args.duration, tmp / "sessions")
    s = r["stats"]
    d = sorted(r["delays_ms"])
    offered = s["video_frames"] + s["dropped_frames"]
    print(f"capture exit status {r['rc']}, session {r['session']}")
    print(f"frames: {s['video_frames']} written of {offered} offered; dropped {s['dropped_frames']} (target 0)")
    print(f"heart-rate rows: {s['hr_samples']}; bad bytes {s['decoder']['bytes_dropped']}")
    print(f"CPU share of the capture process: {100 * r['cpu_share']:.1f} % of one core; baseline (decode "
          f"the video only): {100 * base_cpu:.1f} %; ratio {r['cpu_share'] / base_cpu:.2f}x")
    if d:
        med = statistics.median(d)
        print(f"byte -> heart_rate.csv row delay: median {med:.1f} ms (target < 20), p90 "
              f"{d[int(0.9 * (len(d) - 1))]:.1f} ms, max {d[-1]:.1f} ms over {len(d)} rows; baseline pty "
              f"write -> read {base_ms:.2f} ms; ratio {med / base_ms:.1f}x")
    if args.keep is None:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0 if r["rc"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
