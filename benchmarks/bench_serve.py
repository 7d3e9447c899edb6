"""``effortface serve`` latency and CPU at 120 Hz, with real LSL on loopback.

An LSL ``EffortWork`` outlet in this process pushes (w, p) at 120 Hz, each sample stamped with
``pylsl.local_clock()`` at push; ``effortface serve default`` runs as a subprocess (its own
interpreter, as in a lab) and re-stamps each output with the input's stamp, so the latency of one
sample is ``receive time in this process - input stamp`` (one machine, one clock): LSL in, the face
step, LSL out, LSL back in. Printed: median and p99 latency, and the server's CPU share (process
CPU time / wall time, from psutil) over the run. Baseline (same process): the face step alone,
``FaceProcessor.step`` in-process per frame, median and p99; the ratio says what the transport
costs on top of the model.

Run: ``python benchmarks/bench_serve.py [--seconds 20] [--rate 120]``
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import psutil
import pylsl

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from effortface.train.interop.serve import FaceProcessor  # noqa: E402
from effortface.train.runtime import Character, load_model  # noqa: E402


def _baseline_s(n: int) -> np.ndarray:
    """Per-frame time of the face step alone, in-process."""
    proc = FaceProcessor(load_model("default"), Character(), fps=120)
    out = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        proc.step([12.0, 18.0], 1 / 120)
        out[i] = time.perf_counter() - t0
    return out


def _served(seconds: float, rate_hz: float) -> tuple[np.ndarray, float, int, int]:
    """Latencies (s), server CPU share, samples pushed and received."""
    name = f"bench-{uuid.uuid4().hex[:8]}"
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", 2, rate_hz, "float32", name))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    server = subprocess.Popen([sys.executable, "-m", "effortface", "serve", "default", "--input-name", name,
                               "--name", name + "-face", "--report", "5"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    period = 1.0 / rate_hz
    t_end = time.perf_counter() + 2.0
    while time.perf_counter() < t_end:   # let the server find the input before it is measured
        outlet.push_sample([12.0, 18.0], pylsl.local_clock())
        time.sleep(period)
    found = pylsl.resolve_byprop("name", name + "-face", 1, 20)
    inlet = pylsl.StreamInlet(found[0], max_buflen=30)
    inlet.open_stream(10)
    ps = psutil.Process(server.pid)
    cpu0, wall0 = sum(ps.cpu_times()[:2]), time.perf_counter()
    latencies, pushed = [], 0
    next_t = time.perf_counter()
    t_end = next_t + seconds
    while time.perf_counter() < t_end:
        outlet.push_sample([12.0, 18.0], pylsl.local_clock())
        pushed += 1
        next_t += period
        while True:
            sample, stamp = inlet.pull_sample(timeout=max(0.0, next_t - time.perf_counter()))
            if sample is None:
                break
            latencies.append(pylsl.local_clock() - stamp)
    cpu_share = (sum(ps.cpu_times()[:2]) - cpu0) / (time.perf_counter() - wall0)
    server.send_signal(signal.SIGTERM)
    server.communicate(timeout=30)
    return np.array(latencies), cpu_share, pushed, len(latencies)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate", type=float, default=120.0)
    args = parser.parse_args()
    lat, cpu, pushed, received = _served(args.seconds, args.rate)
    base = _baseline_s(int(args.seconds * args.rate))
    med, p99 = np.median(lat) * 1e3, np.percentile(lat, 99) * 1e3
    bmed, bp99 = np.median(base) * 1e3, np.percentile(base, 99) * 1e3
    print(f"serve at {args.rate:g} Hz for {args.seconds:g} s: {received}/{pushed} samples back")
    print(f"  latency LSL in -> weights out -> LSL back: median {med:.2f} ms, p99 {p99:.2f} ms")
    print(f"  server CPU share: {cpu * 100:.1f} % of one core")
    print(f"  baseline (face step in-process): median {bmed:.3f} ms, p99 {bp99:.3f} ms")
    print(f"  ratio served / in-process: median {med / bmed:.0f}x, p99 {p99 / bp99:.0f}x")


if __name__ == "__main__":
    main()
