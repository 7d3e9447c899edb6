"""Runtime speed and memory, against baselines measured in the same process (one core).

1. **Whole pipeline** (motion -> energies -> physiology -> face) on a 10-minute 120 Hz clip, made
   by tiling the real CMU jumping-jacks clip forwards then backwards (a palindrome, so there are no
   jumps at the seams): speed as a multiple of real time (target >= 200x), for the rule model and for
   an SVR bundle with ~2,000 support vectors per blendshape. Baseline: the same frames through the
   per-frame stream (``model.stream(...).step``), the way a game loop would run them.
2. **Crowd** at 60 FPS with the ~2,000-support-vector SVR: characters kept in real time per core
   (target >= 1,000) with ``CrowdStream.step_work`` (physiology + SVR vectorised over characters;
   the engine supplies w and p), and with ``CrowdStream.step`` (joint positions in, one energy
   stream per character). Baselines: scikit-learn ``SVR.predict`` called per frame, once per
   blendshape on all characters (batched) and once per character and blendshape (naive).
   Target: >= 10x against calling scikit-learn per frame.
3. **Memory** per streaming character (tracemalloc), single streams and crowd members.

Run: ``python benchmarks/bench_runtime.py [--minutes 10] [--crowd 1000] [--support 2000]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, as the targets say

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_data import DATA  # noqa: E402

from effortface.core.blendshapes import DEFAULT_SET  # noqa: E402
from effortface.synth.bundle import ModelBundle, write_bundle  # noqa: E402
from effortface.synth.face import SvrModel  # noqa: E402
from effortface.synth.motion import Motion, read_motion  # noqa: E402
from effortface.synth.physiology import NhrParams, NhrRegression  # noqa: E402
from effortface.synth.runtime import Character, FaceModel, load_model  # noqa: E402

CLIP = DATA / "motion" / "cmu_13_29_jumping_jacks_120fps.bvh"


def tiled_clip(minutes: float) -> Motion:
    """The real clip tiled as a palindrome (forwards, backwards, ...) to ``minutes``."""
    clip = read_motion(CLIP)
    pos, rot = clip.positions_m[1:], clip.rotations[1:]
    n = int(minutes * 60 * clip.fps)
    order = np.r_[np.arange(len(pos)), np.arange(len(pos))[::-1]]
    idx = np.resize(order, n)
    return dataclasses.replace(clip, positions_m=pos[idx], rotations=rot[idx])


def fit_svrs(n_support: int, seed: int = 0):
    """Four scikit-learn SVRs with about ``n_support`` support vectors each, and their scaler."""
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVR

    rng = np.random.default_rng(seed)
    n = int(n_support * 1.15)
    x = np.column_stack([rng.uniform(0, 25, n), rng.uniform(0, 40, n), rng.uniform(0, 1, n),
                         rng.uniform(0, 1, n)])
    scaler = StandardScaler().fit(x)
    z = scaler.transform(x)
    svrs = []
    for _ in DEFAULT_SET.names:
        y = np.tanh(z @ rng.normal(size=4)) * 0.4 + 0.5 + 0.05 * rng.normal(size=n)
        svrs.append(SVR(C=100.0, gamma=0.05, epsilon=0.002).fit(z, y))
    return svrs, scaler


def svr_model_dir(svrs, scaler, folder: Path) -> Path:
    """Write the fitted SVRs as a model bundle."""
    model = SvrModel.from_estimators(svrs, scaler.mean_, scaler.scale_)
    bundle = ModelBundle(
        blendshapes=DEFAULT_SET, scaler_mean=scaler.mean_, scaler_scale=scaler.scale_,
        nhr_coefficients=NhrParams(7.13, 0.0056, 0.0009), nhr_regression=NhrRegression(),
        svr_hyperparameters=[{"C": 100.0, "gamma": 0.05, "epsilon": 0.002} for _ in svrs],
        support_vectors=model.support_vectors, dual_coef=model.dual_coef,
        intercept=model.intercept, provenance={"data": "benchmark, random"})
    return write_bundle(bundle, folder, overwrite=True)


def _best_of(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def bench_pipeline(model: FaceModel, label: str, motion: Motion, stream_frames: int) -> None:
    """Whole clip vs the per-frame stream on the same frames."""
    hero = Character()
    duration_s = motion.n_frames / motion.fps
    whole_s = _best_of(lambda: model.synthesize(motion, hero), repeats=2)
    live = model.stream(hero, motion)
    dt = 1.0 / motion.fps
    t0 = time.perf_counter()
    for k in range(stream_frames):
        live.step(motion.positions_m[k], dt, motion.rotations[k])
    per_frame_s = (time.perf_counter() - t0) / stream_frames
    stream_s = per_frame_s * motion.n_frames
    print(f"  {label:<28} whole clip {whole_s:6.2f} s = {duration_s / whole_s:7.0f}x real time "
          f"(target >= 200x); per-frame stream {per_frame_s * 1e6:6.0f} us/frame = "
          f"{duration_s / stream_s:5.0f}x real time; whole/stream speed-up {stream_s / whole_s:5.1f}x")


def _crowd_frame_s(crowd, w: np.ndarray, p: np.ndarray) -> tuple[float, np.ndarray]:
    """Seconds per crowd frame (step_work), and the last weights."""
    t0 = time.perf_counter()
    for k in range(len(w)):
        out = crowd.step_work(w[k], p[k], 1 / 60)
    return (time.perf_counter() - t0) / len(w), out


def bench_crowd(model: FaceModel, svrs, scaler, n_chars: int, frames: int, skeleton: Motion) -> None:
    """Characters per core at 60 FPS, against scikit-learn called per frame."""
    rng = np.random.default_rng(1)
    chars = [Character(training_level=float(rng.uniform(0, 10)), mass_kg=float(rng.uniform(50, 110)))
             for _ in range(n_chars)]
    w = rng.uniform(0, 25, (frames, n_chars))
    p = rng.uniform(0, 40, (frames, n_chars))
    ours_s, double = _crowd_frame_s(model.stream_batch(chars, skeleton), w, p)
    single_s, single = _crowd_frame_s(model.stream_batch(chars, skeleton, single_precision=True),
                                      w, p)
    surrogate_s, surrogate = _crowd_frame_s(model.stream_batch(chars, skeleton, surrogate=True), w, p)
    x = np.column_stack([w[0], p[0], rng.uniform(0, 1, n_chars), rng.uniform(0, 1, n_chars)])
    z = scaler.transform(x)
    batched_s = _best_of(lambda: [s.predict(z) for s in svrs], repeats=2)
    few = min(n_chars, 100)
    naive_s = _best_of(lambda: [s.predict(z[i:i + 1]) for i in range(few) for s in svrs],
                       repeats=1) * n_chars / few
    per_core = n_chars * (1 / 60) / ours_s
    print(f"  step_work, {n_chars} characters: {ours_s * 1e3:6.2f} ms/frame -> "
          f"{per_core:6.0f} characters in real time at 60 FPS per core (target >= 1000)")
    print(f"  step_work, float32 kernels: {single_s * 1e3:6.2f} ms/frame -> "
          f"{n_chars * (1 / 60) / single_s:6.0f} characters per core; max |weight - float64| "
          f"{np.abs(single - double).max():.1e}")
    print(f"  step_work, compact surrogate (SvrSurrogate): {surrogate_s * 1e3:6.2f} ms/frame -> "
          f"{n_chars * (1 / 60) / surrogate_s:6.0f} characters per core; max |weight - float64| "
          f"{np.abs(surrogate - double).max():.1e}")
    print(f"    vs scikit-learn per frame, batched per blendshape: {batched_s * 1e3:7.2f} ms/frame "
          f"-> ratio {batched_s / ours_s:5.1f}x; one call per character and blendshape: "
          f"{naive_s * 1e3:7.1f} ms/frame -> ratio {naive_s / ours_s:6.1f}x (target >= 10x); "
          f"float32 ratios {batched_s / single_s:5.1f}x and {naive_s / single_s:6.1f}x")


def bench_crowd_positions(model: FaceModel, n_chars: int, frames: int, motion: Motion) -> None:
    """The full crowd path: joint positions in, one causal energy stream per character."""
    chars = [Character(training_level=5.0) for _ in range(n_chars)]
    crowd = model.stream_batch(chars, motion)
    t0 = time.perf_counter()
    for k in range(frames):
        pos = np.stack([motion.positions_m[(k + 13 * i) % motion.n_frames] for i in range(n_chars)])
        crowd.step(pos, 1 / 60)
    per_frame = (time.perf_counter() - t0) / frames
    print(f"  step (positions in), {n_chars} characters: {per_frame * 1e3:6.2f} ms/frame -> "
          f"{n_chars * (1 / 60) / per_frame:5.0f} characters in real time per core "
          "(energies vectorised over the characters, exact float64 face)")


def bench_memory(model: FaceModel, skeleton: Motion, n: int = 50) -> None:
    """tracemalloc: bytes per single stream and per crowd member (after one step)."""
    hero = Character()
    model.stream(hero, skeleton).step(skeleton.positions_m[0], 1 / 60)  # warm caches
    tracemalloc.start()
    base = tracemalloc.take_snapshot()
    streams = [model.stream(hero, skeleton) for _ in range(n)]
    for s in streams:
        s.step(skeleton.positions_m[0], 1 / 60)
    single = sum(st.size_diff for st in tracemalloc.take_snapshot().compare_to(base, "filename")) / n
    del streams
    base = tracemalloc.take_snapshot()
    crowd = model.stream_batch([hero] * 1000, skeleton)
    crowd.step_work(np.full(1000, 5.0), np.full(1000, 5.0), 1 / 60)
    member = sum(st.size_diff for st in tracemalloc.take_snapshot().compare_to(base, "filename")) / 1000
    tracemalloc.stop()
    del crowd
    print(f"  memory: {single / 1024:6.1f} KiB per streaming character (CharacterStream), "
          f"{member / 1024:6.1f} KiB per crowd member (CrowdStream of 1000, incl. its energy stream)")


def main() -> None:
    """Run all benchmarks and print figures and ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--crowd", type=int, default=1000)
    parser.add_argument("--support", type=int, default=2000)
    parser.add_argument("--frames", type=int, default=30, help="crowd frames to time")
    args = parser.parse_args()
    import tempfile

    print(f"clip: {CLIP.name} tiled to {args.minutes:g} min at 120 Hz")
    motion = tiled_clip(args.minutes)
    t0 = time.perf_counter()
    svrs, scaler = fit_svrs(args.support)
    n_sv = [len(s.support_) for s in svrs]
    print(f"SVR: fitted 4 scikit-learn SVRs in {time.perf_counter() - t0:.1f} s, support vectors "
          f"{n_sv}")
    with tempfile.TemporaryDirectory() as tmp:
        svr_model = load_model(svr_model_dir(svrs, scaler, Path(tmp) / "model"))
    rule_model = load_model("default")
    print("1. whole pipeline")
    bench_pipeline(rule_model, "rule model", motion, stream_frames=2000)
    bench_pipeline(svr_model, f"SVR model ({sum(n_sv)} SVs)", motion, stream_frames=1000)
    print("2. crowd at 60 FPS, SVR model")
    bench_crowd(svr_model, svrs, scaler, args.crowd, args.frames, motion)
    bench_crowd_positions(svr_model, min(args.crowd, 200), 10, motion)
    print("3. memory")
    bench_memory(svr_model, motion)


if __name__ == "__main__":
    main()
