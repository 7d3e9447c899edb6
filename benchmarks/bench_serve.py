"""``effortface serve`` latency and CPU at 120 Hz, with real LSL on loopback.

An LSL ``EffortWork`` outlet in this process pushes (w, p) at 120 Hz, each sample stamped with
``pylsl.local_clock()`` at push; ``effortface serve default`` runs as a subprocess (its own
interpreter, as in a lab) and re-stamps each output with the input's stamp, so the latency of one
sample is ``receive time in this process - input stamp`` (one machine, one clock): LSL in, the face
step, LSL out, LSL back in. Printed: median and p99 latency, and the server's CPU share (process
CPU time / wall time, from psutil) over the run. Baseline (same process): the face step alone,
``FaceProcessor.step`` in-process per frame, median and p99; the ratio says what the transport
costs on top of the model.

Soak (issue 29): ``--soak S`` runs the server S seconds at ``--rate`` with the input dropping (its
outlet destroyed, 2 s of silence, a new one) every ``--drop-every`` seconds and a malformed burst
every ``--burst-every`` seconds (NaN, inf and 1e308 samples on the input, and a same-named stream of
the wrong width). Printed: the server's resident memory after the first minute (or the first
quarter of a shorter soak) and at the end, the longest output gap minus the input gap around it,
the server's ``bad`` count, and whether it survived. Baseline (same process): its memory at the
start of the measured window.

Run: ``python benchmarks/bench_serve.py [--seconds 20] [--rate 120]`` or ``--soak 600``
"""

from __future__ import annotations

import argparse
import math
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

from effortface.interop.serve import FaceProcessor  # noqa: E402
from effortface.synth.runtime import Character, load_model  # noqa: E402


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


def _soak(seconds: float, rate_hz: float, drop_every_s: float, burst_every_s: float) -> dict[str, float]:
    """Run the server through drops and malformed bursts; return its figures (see the module doc)."""
    name = f"soak-{uuid.uuid4().hex[:8]}"

    def outlet_of(width: int = 2) -> pylsl.StreamOutlet:
        return pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", width, rate_hz, "float32", uuid.uuid4().hex))

    outlet = outlet_of()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    server = subprocess.Popen([sys.executable, "-m", "effortface", "serve", "default", "--input-name", name,
                               "--name", name + "-face", "--report", "5"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    found = pylsl.resolve_byprop("name", name + "-face", 1, 30)
    inlet = pylsl.StreamInlet(found[0], max_buflen=30)
    inlet.open_stream(10)
    ps = psutil.Process(server.pid)
    period, start = 1.0 / rate_hz, time.perf_counter()
    warm_s = min(60.0, seconds / 4)
    rss_warm = rss_end = 0.0
    in_gaps: list[tuple[float, float]] = []  # (start, end) of the input's silences, local_clock
    out_stamps: list[float] = []
    next_t, next_drop, next_burst = start, start + drop_every_s, start + burst_every_s
    while time.perf_counter() - start < seconds:
        now = time.perf_counter()
        if now >= next_drop:  # the input vanishes for 2 s and returns as a new stream
            t_gap = pylsl.local_clock()
            del outlet
            time.sleep(2.0)
            outlet = outlet_of()
            in_gaps.append((t_gap, pylsl.local_clock()))
            next_drop += drop_every_s
            next_t = time.perf_counter()
        if now >= next_burst:  # malformed samples, and a same-named stream of the wrong width
            for bad in ([math.nan, 1.0], [math.inf, 1.0], [1e38, 1.0], [1.0, -math.inf]) * 5:
                outlet.push_sample(bad, pylsl.local_clock())
            wrong = outlet_of(5)
            wrong.push_sample([1.0] * 5)
            del wrong
            next_burst += burst_every_s
        outlet.push_sample([12.0, 18.0], pylsl.local_clock())
        next_t += period
        while True:
            sample, stamp = inlet.pull_sample(timeout=max(0.0, next_t - time.perf_counter()))
            if sample is None:
                break
            out_stamps.append(stamp)
        if not rss_warm and time.perf_counter() - start >= warm_s:
            rss_warm = ps.memory_info().rss
    alive = server.poll() is None
    rss_end = ps.memory_info().rss if alive else 0.0
    server.send_signal(signal.SIGTERM)
    _, err = server.communicate(timeout=30)
    bad = [int(line.rsplit(", ", 1)[1].split()[0]) for line in err.splitlines() if line.endswith(" bad")]
    gaps = np.diff(np.array(out_stamps)) if len(out_stamps) > 1 else np.array([0.0])
    excess = [g - max((b - a for a, b in in_gaps if out_stamps[k] <= b and out_stamps[k + 1] >= a), default=period)
              for k, g in enumerate(gaps)]
    return {"alive": float(alive), "rss_warm_mb": rss_warm / 2**20, "rss_end_mb": rss_end / 2**20,
            "max_excess_gap_s": float(max(excess)), "bad": float(bad[-1] if bad else 0),
            "outputs": float(len(out_stamps)), "drops": float(len(in_gaps))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate", type=float, default=120.0)
    parser.add_argument("--soak", type=float, default=None, metavar="S", help="soak for S seconds instead")
    parser.add_argument("--drop-every", type=float, default=60.0, metavar="S")
    parser.add_argument("--burst-every", type=float, default=30.0, metavar="S")
    args = parser.parse_args()
    if args.soak is not None:
        got = _soak(args.soak, args.rate, args.drop_every, args.burst_every)
        growth = (got["rss_end_mb"] / got["rss_warm_mb"] - 1) * 100 if got["rss_warm_mb"] else float("nan")
        print(f"soak {args.soak:g} s at {args.rate:g} Hz: {int(got['drops'])} input drops, bursts every "
              f"{args.burst_every:g} s; server {'alive' if got['alive'] else 'DEAD'}")
        print(f"  memory: {got['rss_warm_mb']:.1f} MiB after warm-up (baseline), {got['rss_end_mb']:.1f} MiB at "
              f"the end: ratio {got['rss_end_mb'] / max(got['rss_warm_mb'], 1e-9):.3f} ({growth:+.1f} %)")
        print(f"  longest output gap beyond the input's own gap: {got['max_excess_gap_s']:.3f} s; "
              f"{int(got['outputs'])} outputs, bad {int(got['bad'])}")
        return
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
