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
2b. **Crowd from joint positions** (``CrowdStream.step``, the crowd built at 60 FPS: one energy tick
   a frame) at 2,500 characters with the same model (4 x ~2,250 = 8,996 support vectors): characters
   at 60 FPS per core by the median frame, best and worst beside it, exact float64 and float32 faces
   (target >= 2,500 in float32), the energies split off, float32's max |weight - float64|, and the
   ratio of scikit-learn's ``SVR.predict`` on the same features to our whole step.
3. **Memory** per streaming character (tracemalloc), single streams and crowd members.

Run: ``python benchmarks/bench_runtime.py [--minutes 10] [--crowd 1000] [--support 2000]
[--crowd-positions 2500] [--skip pipeline,crowd,positions,memory]``
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


#: the crowd's face options timed from positions, each against the float64 exact face
CROWD_OPTIONS = (("float64", {}), ("float32", {"single_precision": True}),
                 ("surrogate", {"surrogate": True}))
#: frames of the crowd timed through scikit-learn (spread over the run)
SKLEARN_FRAMES = 5
#: the game's frame rate in the crowd benchmarks: one energy tick per frame (the crowd's ``fps``)
CROWD_FPS = 60.0


@dataclasses.dataclass(frozen=True)
class CrowdTiming:
    """One crowd option stepped from joint positions: seconds per frame and the weights."""

    label: str
    n_chars: int
    step_s: np.ndarray     # seconds of every timed ``step`` (positions in)
    face_s: np.ndarray     # seconds of ``step_work`` on the same work (physiology + face + filter)
    weights: np.ndarray    # (frames, N, B) weights of every timed step
    features: np.ndarray   # (frames, N, 4) the face's features [w, p, NHR, EPOC_norm] of every step

    def per_core(self, seconds: float) -> float:
        """Characters kept at :data:`CROWD_FPS` on one core at ``seconds`` per frame."""
        return self.n_chars / CROWD_FPS / seconds

    def line(self) -> str:
        """Characters at 60 FPS per core: median frame first, best and worst beside it."""
        med, best, worst = np.median(self.step_s), self.step_s.min(), self.step_s.max()
        energy = np.median(self.step_s) - np.median(self.face_s)
        return (f"{self.label:>9}: {self.per_core(med):5.0f} characters at 60 FPS per core by the median frame "
                f"(best {self.per_core(best):5.0f}, worst {self.per_core(worst):5.0f}); "
                f"{med * 1e3:6.2f} ms/frame = energies {energy * 1e3:5.2f} + physiology, face and filter "
                f"{np.median(self.face_s) * 1e3:5.2f}")


def crowd_positions(n_chars: int, frames: int, motion: Motion) -> list[np.ndarray]:
    """Joint positions (N, J, 3) for ``frames + 1`` frames: character i plays the clip 13 i frames on."""
    offsets = 13 * np.arange(n_chars)
    return [motion.positions_m[(k + offsets) % motion.n_frames] for k in range(frames + 1)]


def time_crowd(model: FaceModel, label: str, options: dict, positions: list[np.ndarray],
               skeleton: Motion, fps: float = CROWD_FPS) -> CrowdTiming:
    """Step a crowd from positions (the first frame untimed), then replay its work through
    ``step_work`` on a fresh crowd to split the energies from the rest."""
    n_chars = len(positions[0])
    chars = [Character()] * n_chars
    crowd = model.stream_batch(chars, skeleton, fps=fps, **options)  # a surrogate is fitted here, once
    crowd.step(positions[0], 1 / fps)
    steps, weights, features = [], [], []
    for pos in positions[1:]:
        t0 = time.perf_counter()
        weights.append(crowd.step(pos, 1 / fps))
        steps.append(time.perf_counter() - t0)
        last = crowd.last
        features.append(np.column_stack([last["w_per_kg"], last["p_per_kg"], last["nhr"], last["epoc_norm"]]))
    replay = model.stream_batch(chars, skeleton, fps=fps, **options)
    faces = []
    for x in features:
        t0 = time.perf_counter()
        replay.step_work(x[:, 0], x[:, 1], 1 / fps)
        faces.append(time.perf_counter() - t0)
    return CrowdTiming(label, n_chars, np.array(steps), np.array(faces), np.array(weights), np.array(features))


def bench_crowd_positions(model: FaceModel, svrs, scaler, n_chars: int, frames: int, motion: Motion,
                          labels: tuple[str, ...] = ("float64", "float32")) -> dict[str, CrowdTiming]:
    """The full crowd path, joint positions in: characters at 60 FPS per core for each face option,
    the float32 error against float64, and scikit-learn's ``SVR.predict`` on the same features."""
    positions = crowd_positions(n_chars, frames, motion)
    results = {label: time_crowd(model, label, options, positions, motion)
               for label, options in CROWD_OPTIONS if label in labels}
    exact = results["float64"]
    for timing in results.values():
        print("  " + timing.line())
    for label, timing in results.items():
        if label != "float64":
            print(f"  {label}: max |weight - float64| {np.abs(timing.weights - exact.weights).max():.1e} "
                  f"over {frames} frames x {n_chars} characters")
    sklearn_s = []
    for x in exact.features[::max(1, len(exact.features) // SKLEARN_FRAMES)]:  # about a second each
        z = scaler.transform(x)
        t0 = time.perf_counter()
        for s in svrs:
            s.predict(z)
        sklearn_s.append(time.perf_counter() - t0)
    sk = float(np.median(sklearn_s))
    ratios = ", ".join(f"{label} {sk / np.median(t.step_s):4.1f}x" for label, t in results.items())
    print(f"  scikit-learn SVR.predict on the same features (one call per blendshape, all characters): "
          f"{sk * 1e3:6.2f} ms/frame median for the face alone = {exact.per_core(sk):5.0f} characters at 60 FPS; "
          f"ratio scikit-learn face / our whole step (energies included), median frames "
          f"({len(sklearn_s)} frames of scikit-learn): {ratios}")
    return results


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
    parser.add_argument("--crowd-positions", type=int, default=2500,
                        help="characters of the crowd stepped from joint positions")
    parser.add_argument("--skip", default="", help="comma-separated sections to skip: pipeline,crowd,positions,memory")
    args = parser.parse_args()
    skip = set(args.skip.split(","))
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
    if "pipeline" not in skip:
        print("1. whole pipeline")
        bench_pipeline(rule_model, "rule model", motion, stream_frames=2000)
        bench_pipeline(svr_model, f"SVR model ({sum(n_sv)} SVs)", motion, stream_frames=1000)
    if "crowd" not in skip:
        print("2. crowd at 60 FPS, SVR model")
        bench_crowd(svr_model, svrs, scaler, args.crowd, args.frames, motion)
    if "positions" not in skip:
        print(f"2b. crowd from joint positions, {args.crowd_positions} characters at {CROWD_FPS:g} FPS "
              f"(crowd fps={CROWD_FPS:g}: one energy tick per frame), SVR model ({sum(n_sv)} support vectors), "
              f"one core, load average {os.getloadavg()[0]:.1f}")
        bench_crowd_positions(svr_model, svrs, scaler, args.crowd_positions, args.frames, motion)
    if "memory" not in skip:
        print("3. memory")
        bench_memory(svr_model, motion)


if __name__ == "__main__":
    main()
