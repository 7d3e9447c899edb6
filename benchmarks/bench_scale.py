"""Issue 15 (scale): training on every annotated second, Dask, batch synthesis, long clips, crowds.

Prints figures and ratios against a baseline measured in the same run. Every time that is
repeated is given as its median first, with the best and the worst beside it, and every ratio is
taken between medians of the same work on both sides:

1. **Training** (the face part of a training run: grid search, final fit, held-out scores and the
   paper's protocols) on generated tables of P participants x 1 h (P = 10, 30, 100 by default):
   time (cluster start-up and close included), CPU time (this process, the workers and Dask's fork
   server, all the start-up's imports included), peak
   memory (the process's maximum RSS, and the largest worker's; each configuration runs in its own
   process), face rows used, method, mean held-out RMSE; serial and with ``--workers 2``, and the
   ratio serial / 2 workers; baseline: the old caps (300 rows per participant, 2,000 in all, exact
   SVR). On a shared machine the CPU times tell what the wall times cannot: the machine's load
   average is printed with each line. With ``--repeat N`` each configuration runs N times (serial
   and workers alternating): median, best and worst.
2. **Batch synthesis** of a folder of real clips: clips/s and frames/s in this process and on a
   local Dask cluster of 1 and 2 workers.
3. **Long BVH clips** (the real jumping-jacks clip tiled to 10 min and 1 h at 120 Hz): read time and
   peak memory (own process each), against the whole-file float64 parse (``BVH_CHUNK_FRAMES`` as
   large as the clip); whole-process ``effortface synth`` time for the 10-minute clip in x real time
   (interpreter start-up and imports included; median, best and worst of 3 runs), with the default model
   and with each ``--svr-model`` bundle.
4. **Crowd from positions**: characters per core at 60 FPS (one BLAS thread) with
   ``bench_runtime``'s SVR model (4 x ~2,250 = 8,996 support vectors; median frame first, best and
   worst beside it), through ``CrowdStream.step(positions)``: the exact face in float64 (the
   baseline), in float32 and the compact surrogate (``surrogate=True``); the time split between the
   energies and physiology + face (``step_work`` on the same work); each option's max
   |weight - float64| against its stated bound; scikit-learn's ``SVR.predict`` on the same features;
   the floor of an exact float32 face. The timing is ``bench_runtime.bench_crowd_positions`` (one
   helper for both benchmarks).
5. **Synth memory**: peak RSS of a whole ``effortface synth`` process (``os.wait4`` rusage of the
   child) on the jumping-jacks clip tiled forwards and backwards to 10, 30 and 60 minutes at 120 Hz,
   the growth per clip minute, and the ratio against the 1-minute clip measured in the same run.

Clips come from ``../shared/data``, else the repository's ``tests/data`` (``bench_data.py``).

Run: ``python benchmarks/bench_scale.py [--participants 10 30 100] [--repeat N]
[--skip memory,train,synth,bvh,crowd] [--synth-minutes 10 30 60] [--svr-model DIR] [--crowd 2500]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_data import DATA  # noqa: E402  (../shared/data, else tests/data)

CLIP = DATA / "motion" / "cmu_13_29_jumping_jacks_120fps.bvh"
SQUATS = DATA / "motion" / "cmu_13_29_squats_120fps.bvh"
#: whole-process runs of ``effortface synth`` timed on the 10-minute clip (best and median shown)
SYNTH_RUNS = 3


def spread(values: list[float]) -> tuple[float, float, float]:
    """(median, best, worst) of repeated timings: the median is the figure, the others its range."""
    import numpy as np

    return float(np.median(values)), float(min(values)), float(max(values))


def _max_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _cpu_s() -> float:
    """CPU seconds of this process and of every live process under it (Dask's fork server, workers)."""
    import psutil

    me = psutil.Process()
    return sum(sum(p.cpu_times()[:2]) for p in [me, *me.children(recursive=True)])


def _largest_child_peak_mb() -> float:
    """The largest peak RSS among the live processes under this one (a Dask worker), Linux."""
    import psutil

    peaks = [0.0]
    for child in psutil.Process().children(recursive=True):
        with contextlib.suppress(OSError, psutil.Error):
            status = Path(f"/proc/{child.pid}/status").read_text()
            peaks += [int(line.split()[1]) / 1024.0 for line in status.splitlines() if line.startswith("VmHWM:")]
    return max(peaks)


def _child(args: list[str]) -> dict:
    """Run this script on one configuration in its own process; its JSON result."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True, env=env,
                          cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


# --------------------------------------------------------------------------- 1. training


def one_training(n_participants: int, workers: int, legacy: bool) -> dict:
    """The face part of a training run on P participants x 1 h (this process)."""
    import numpy as np

    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.train.dataset import prepare, synthetic_table
    from effortface.train.face_fit import FaceFitConfig, fit_face_models, held_out_scores, protocol_scores
    from effortface.synth.parallel import ComputeSettings, compute_backend

    table = prepare(synthetic_table(n_participants=n_participants, seconds=1800, seed=1))
    config = FaceFitConfig(max_rows_per_participant=300, max_total_rows=2000) if legacy else FaceFitConfig()
    rss0 = _max_rss_mb()
    cpu0, t0 = _cpu_s(), time.perf_counter()
    with compute_backend(ComputeSettings(workers=workers) if workers else None):
        started = time.perf_counter() - t0
        fit = fit_face_models(table, DEFAULT_SET.names, config)
        held = held_out_scores(fit)
        protocol_scores(fit)
        cpu, worker_peak_mb = _cpu_s() - cpu0, _largest_child_peak_mb()  # before the workers end
    elapsed = time.perf_counter() - t0
    svr = held[held["model"] == "svr"]
    return {"seconds": elapsed, "cpu_s": cpu, "start_s": started, "load": os.getloadavg()[0],
            "rows": len(fit.data.x), "all_rows": int(table.dropna().shape[0]),
            "available": int(len(table)), "method": fit.method, "peak_mb": _max_rss_mb(),
            "worker_peak_mb": worker_peak_mb,
            "rss_before_mb": rss0, "rmse_pct": float(np.mean(svr["rmse_pct_unit"])),
            "r": float(np.mean(svr["r"]))}


def bench_training(sizes: list[int], workers_list: list[int], repeat: int) -> None:
    print("1. training (face part: grid search, final fit, held-out scores, protocols), P x 1 h"
          + (f"; the median of {repeat} runs of each (serial and workers alternating), best and worst beside it"
             if repeat > 1 else "; one run of each"))
    for p in sizes:
        base = _child(["--one-training", str(p), "0", "legacy"])
        print(f"  P={p:3d} baseline (old caps, exact SVR): {base['seconds']:7.1f} s, "
              f"{base['rows']:6d} of {base['available']} rows ({100 * base['rows'] / base['available']:.2f} %), "
              f"held-out RMSE {base['rmse_pct']:.2f} %, r {base['r']:.3f}, peak {base['peak_mb']:.0f} MB")
        tries: dict[int, list[dict]] = {w: [] for w in workers_list}
        for _ in range(repeat):
            for w in workers_list:
                tries[w].append(_child(["--one-training", str(p), str(w), "new"]))
        runs = {w: sorted(results, key=lambda r: r["seconds"])[(len(results) - 1) // 2]  # the median run
                for w, results in tries.items()}
        for w, res in runs.items():
            label = "serial" if w == 0 else f"{w} workers"
            workers = (f", cluster start-up {res['start_s']:.1f} s, largest worker peak "
                       f"{res['worker_peak_mb']:.0f} MB" if w else "")
            print(f"  P={p:3d} {label:>9} ({res['method']}): {res['seconds']:7.1f} s "
                  f"({res['seconds'] / base['seconds']:5.1f}x the old caps' time: not the same fit, more rows), CPU {res['cpu_s']:6.1f} s, "
                  f"{res['rows']:6d} rows ({100 * res['rows'] / res['available']:.0f} %), held-out RMSE "
                  f"{res['rmse_pct']:.2f} % (baseline {base['rmse_pct']:.2f} %), r {res['r']:.3f}, "
                  f"peak {res['peak_mb']:.0f} MB{workers}; load average {res['load']:.1f}"
                  + (" (median run; best {1:.1f} s, worst {2:.1f} s)".format(*spread([r["seconds"] for r in tries[w]]))
                     if repeat > 1 else ""))
        for w in (w for w in workers_list if w and 0 in runs):
            serial, par = runs[0], runs[w]
            print(f"  P={p:3d} serial / {w} workers (median runs): {serial['seconds'] / par['seconds']:.2f}x in wall time "
                  f"(> 1: the workers are faster), CPU {par['cpu_s'] / serial['cpu_s']:.2f}x the serial run's, "
                  f"same held-out RMSE: {serial['rmse_pct'] == par['rmse_pct']}")


# --------------------------------------------------------------------------- 2. batch synthesis


def bench_synth(n_clips: int) -> None:
    from effortface.synth.batch_synth import SynthOptions, synth_batch
    from effortface.synth.parallel import ComputeSettings
    from effortface.synth.runtime import Character

    print(f"2. batch synthesis: {n_clips} real clips (squats and jumping jacks, 120 Hz), default model")
    tmp = Path(tempfile.mkdtemp())
    clips = tmp / "clips"
    clips.mkdir()
    for k in range(n_clips):
        shutil.copy(SQUATS if k % 2 else CLIP, clips / f"clip{k:03d}.bvh")
    options = SynthOptions("default", Character(), force=True)
    base = None
    for label, compute in (("this process", None), ("1 worker", ComputeSettings(workers=1)),
                           ("2 workers", ComputeSettings(workers=2))):
        t0 = time.perf_counter()
        summary = synth_batch(clips, tmp / "out", options, compute)
        elapsed = time.perf_counter() - t0  # cluster start-up included
        rate = len(summary.results) / elapsed
        base = base or rate
        print(f"  {label:>12}: {rate:6.2f} clips/s, {summary.n_frames / elapsed:8.0f} frames/s "
              f"({summary.n_frames / elapsed / 120:6.0f}x real time; {rate / base:4.2f}x this process; "
              f"cluster start-up included), {len(summary.failed)} failed")
    shutil.rmtree(tmp)


# --------------------------------------------------------------------------- 3. long BVH clips


#: the whole-file baseline parse is run up to this length (1 h would need several GB)
WHOLE_FILE_MAX_MINUTES = 10


def tiled_bvh(minutes: float, folder: Path) -> Path:
    """The real clip's frame lines tiled to ``minutes`` at 120 Hz, forwards then backwards (a
    palindrome, as ``bench_runtime.tiled_clip``: no jumps at the seams)."""
    lines = CLIP.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().upper() == "MOTION")
    frames = [line for line in lines[at + 3:] if line.strip()]
    frames = frames + frames[::-1]
    n = int(minutes * 60 * 120)
    out = folder / f"jj_{minutes:g}min.bvh"
    with out.open("w") as f:
        f.write("\n".join(lines[:at + 1]) + f"\nFrames: {n}\nFrame Time: {1 / 120:.7f}\n")
        for k in range(0, n, len(frames)):
            f.write("\n".join(frames[: min(len(frames), n - k)]) + "\n")
    return out


def one_read(path: str, whole: bool) -> dict:
    """Read one BVH (this process): seconds, peak RSS above the start, dtype."""
    from effortface.synth import motion as mo

    if whole:
        mo.BVH_CHUNK_FRAMES = 10**9
    rss0 = _max_rss_mb()
    t0 = time.perf_counter()
    m = mo.read_bvh(path, dtype=float if whole else None)
    return {"seconds": time.perf_counter() - t0, "peak_mb": _max_rss_mb(), "start_mb": rss0,
            "frames": m.n_frames, "dtype": str(m.positions_m.dtype),
            "data_mb": (m.positions_m.nbytes + m.rotations.nbytes) / 2**20}


def synth_process(path: Path, model: str = "default") -> dict:
    """Run ``python -m effortface synth MODEL CLIP`` once in its own process (interpreter start-up
    and imports included): wall seconds, exit status and the child's peak RSS in MB (``os.wait4``'s
    rusage of that process alone). The output files are removed."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = path.with_name(path.stem + "_synth.csv")
    t0 = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-m", "effortface", "synth", model, str(path), "--out", str(out)],
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    wall_s = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    error = child.stderr.read().decode(errors="replace").strip() if child.stderr else ""
    if child.stderr:
        child.stderr.close()
    for f in (out, out.with_name(out.stem + ".units.json")):
        f.unlink(missing_ok=True)
    return {"wall_s": wall_s, "status": child.returncode, "peak_mb": usage.ru_maxrss / 1024.0, "error": error}


def _whole_process_synth(path: Path, model: str, duration_s: float) -> None:
    """Time ``python -m effortface synth MODEL CLIP`` (:func:`synth_process`; best and median of runs)."""
    walls, status = [], 0
    for _ in range(SYNTH_RUNS):
        run = synth_process(path, model)
        walls.append(run["wall_s"])
        status = status or run["status"]
    median, best, worst = spread(walls)
    print(f"       whole process `effortface synth {model if model == 'default' else 'SVR_BUNDLE'}` on it "
          f"({SYNTH_RUNS} runs): median {median:.2f} s = {duration_s / median:.0f}x real time (target >= 200x; "
          f"best {duration_s / best:.0f}x, worst {duration_s / worst:.0f}x), exit {status}"
          + ("" if model == "default" else f" [{model}]"))


def bench_bvh(minutes_list: list[float], svr_models: list[str]) -> None:
    print("3. long BVH clips (120 Hz, 38 joints): read time and peak memory (own process, whole RSS)")
    tmp = Path(tempfile.mkdtemp())
    for minutes in minutes_list:
        path = tiled_bvh(minutes, tmp)
        size_mb = path.stat().st_size / 2**20
        new = _child(["--one-read", str(path), "chunked"])
        line = (f"  {minutes:4g} min ({size_mb:.0f} MB file): chunked ({new['dtype']}) {new['seconds']:6.1f} s, "
                f"peak {new['peak_mb']:6.0f} MB ({new['data_mb']:.0f} MB of it the motion itself)")
        if minutes <= WHOLE_FILE_MAX_MINUTES:
            old = _child(["--one-read", str(path), "whole"])
            line += (f"; whole-file float64 parse {old['seconds']:6.1f} s, peak {old['peak_mb']:6.0f} MB -> "
                     f"{old['peak_mb'] / new['peak_mb']:4.1f}x less memory, "
                     f"{old['seconds'] / new['seconds']:4.2f}x the speed")
        print(line)
        if minutes == 10:
            for model in ["default", *svr_models]:
                _whole_process_synth(path, model, minutes * 60)
        path.unlink()
    shutil.rmtree(tmp)


# --------------------------------------------------------------------------- 5. synth memory


def bench_synth_memory(minutes_list: list[float], baseline_minutes: float = 1.0) -> None:
    """Peak RSS of whole ``effortface synth`` processes on long clips, against a short clip's."""
    print(f"5. `effortface synth default` peak memory (whole process, os.wait4 rusage), 120 Hz BVH "
          f"tiled forwards and backwards; baseline: the {baseline_minutes:g}-minute clip")
    tmp = Path(tempfile.mkdtemp())
    peaks: dict[float, float] = {}
    for minutes in [baseline_minutes, *minutes_list]:
        path = tiled_bvh(minutes, tmp)
        run = synth_process(path)
        path.unlink()
        if run["status"]:
            print(f"  {minutes:4g} min: exit {run['status']}: {run['error'][-300:]}")
            continue
        peaks[minutes] = run["peak_mb"]
        ratio = run["peak_mb"] / peaks[baseline_minutes]
        print(f"  {minutes:4g} min ({int(minutes * 60 * 120):,} frames): peak RSS {run['peak_mb']:6.0f} MB, "
              f"{run['wall_s']:6.1f} s = {minutes * 60 / run['wall_s']:4.0f}x real time; "
              f"{ratio:4.2f}x the {baseline_minutes:g}-minute clip's")
    longest = [m for m in minutes_list if m in peaks]
    if len(longest) >= 2:
        lo, hi = min(longest), max(longest)
        print(f"  growth {lo:g} -> {hi:g} min: {(peaks[hi] - peaks[lo]) / (hi - lo):+.2f} MB per clip minute "
              f"(target: an hour within 1024 MB: {'met' if peaks[hi] <= 1024 or hi < 60 else 'NOT met'})")
    shutil.rmtree(tmp)


# --------------------------------------------------------------------------- 4. crowd


def bench_crowd(n_chars: int, frames: int) -> None:
    """Section 4: the crowd from joint positions, timed by ``bench_runtime``'s helper (one definition)."""
    import numpy as np
    from bench_runtime import CROWD_FPS, bench_crowd_positions, fit_svrs, svr_model_dir
    from threadpoolctl import threadpool_limits

    from effortface.synth.face import SINGLE_PRECISION_ERROR_PER_ALPHA, SURROGATE_MAX_ERROR
    from effortface.synth.motion import read_motion
    from effortface.synth.runtime import load_model

    svrs, scaler = fit_svrs(2000)
    model = load_model(svr_model_dir(svrs, scaler, Path(tempfile.mkdtemp()) / "m"))
    n_sv = sum(len(s.support_) for s in svrs)
    print(f"4. crowd from positions, {n_chars} characters at {CROWD_FPS:g} FPS, SVR model ({n_sv} support vectors "
          f"in all), one core (BLAS limited to one thread), load average {os.getloadavg()[0]:.1f}")
    motion = read_motion(CLIP)
    with threadpool_limits(limits=1):
        bench_crowd_positions(model, svrs, scaler, n_chars, frames, motion,
                              labels=("float64", "float32", "surrogate"))
        floor_s = _exact_float32_floor(model, n_chars)
    face = model.face
    alpha = max(np.abs(a).sum() for a in face.dual_coef)
    surrogate = face.surrogate()
    print(f"  stated bounds: float32 {SINGLE_PRECISION_ERROR_PER_ALPHA:g} x sum|alpha| = "
          f"{SINGLE_PRECISION_ERROR_PER_ALPHA * alpha:.1e}; surrogate {SURROGATE_MAX_ERROR:g} "
          f"({surrogate.n_centres} centres, {surrogate.max_error.max():.1e} on its held-out points)")
    for how, (seconds, best, worst) in zip(("as one matrix", "in cached blocks of rows"), floor_s):
        print(f"  floor of the exact face in float32, one sgemm + one exp over {n_chars} x "
              f"{face._single.shape[1]} distinct support vectors {how}: median {seconds * 1e3:.2f} ms (best "
              f"{best * 1e3:.2f}, worst {worst * 1e3:.2f}) -> at most {n_chars / 60 / seconds:.0f} characters "
              f"per core with free energies and physiology")


def _exact_float32_floor(model, n_chars: int) -> tuple[tuple, tuple]:
    """(median, best, worst) seconds of one (n, 6) x (6, support vectors) sgemm and one in-place exp over it: as one
    matrix, and in blocks of rows that stay in the cache (as ``SvrModel`` evaluates it)."""
    import numpy as np

    block = model.face._single  # (features + 2, support vectors): exponents from [z, 1, |z|^2]
    x = np.array([25.0, 40.0, 1.0, 1.0]) * np.random.default_rng(0).uniform(size=(n_chars, 4))
    z = model.face.standardise(x)
    z = np.column_stack([z, np.ones(n_chars), np.einsum("ij,ij->i", z, z)]).astype(np.float32)
    whole = np.empty((n_chars, block.shape[1]), dtype=np.float32)
    rows = model.face._single_rows
    part = whole[:rows]

    def one_matrix() -> None:
        np.matmul(z, block, out=whole)
        np.exp(whole, out=whole)

    def in_blocks() -> None:
        for start in range(0, n_chars, rows):
            k = part[:len(z[start:start + rows])]
            np.matmul(z[start:start + rows], block, out=k)
            np.exp(k, out=k)

    spreads = []
    for run in (one_matrix, in_blocks):
        times = []
        for _ in range(15):
            t0 = time.perf_counter()
            run()
            times.append(time.perf_counter() - t0)
        spreads.append(spread(times))
    return spreads[0], spreads[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", type=int, nargs="+", default=[10, 30, 100])
    parser.add_argument("--workers", type=int, nargs="+", default=[0, 2], help="0 = serial")
    parser.add_argument("--repeat", type=int, default=1,
                        help="training: run each configuration N times (median, best and worst shown)")
    parser.add_argument("--clips", type=int, default=8)
    parser.add_argument("--minutes", type=float, nargs="+", default=[10, 60])
    parser.add_argument("--synth-minutes", type=float, nargs="+", default=[10, 30, 60],
                        help="clip lengths of the synth memory section (5)")
    parser.add_argument("--crowd", type=int, default=2500)
    parser.add_argument("--crowd-frames", type=int, default=20)
    parser.add_argument("--svr-model", action="append", default=[], metavar="DIR",
                        help="also time the whole-process synth with this model bundle (e.g. the sample "
                             "lab's: effortface train sample_sessions --out DIR)")
    parser.add_argument("--skip", default="", help="comma-separated sections to skip")
    parser.add_argument("--one-training", nargs=3, metavar=("P", "WORKERS", "KIND"), help=argparse.SUPPRESS)
    parser.add_argument("--one-read", nargs=2, metavar=("PATH", "KIND"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one_training:
        p, w, kind = args.one_training
        print(json.dumps(one_training(int(p), int(w), kind == "legacy")))
        return
    if args.one_read:
        print(json.dumps(one_read(args.one_read[0], args.one_read[1] == "whole")))
        return
    skip = set(args.skip.split(","))
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    if "memory" not in skip:
        bench_synth_memory(args.synth_minutes)
    if "bvh" not in skip:
        bench_bvh(args.minutes, args.svr_model)
    if "crowd" not in skip:
        bench_crowd(args.crowd, args.crowd_frames)
    if "synth" not in skip:
        bench_synth(args.clips)
    if "train" not in skip:
        bench_training(args.participants, args.workers, args.repeat)


if __name__ == "__main__":
    main()
