"""Jitter of the blendshape weights before and after the output filter, and the filter's cost.

On the real CMU jumping-jacks clip (``tests/data/motion``, 120 Hz, looped 10 times = 37 s so
heart rate and fatigue build up), with an SVR bundle trained here on the sample lab (``effortface
train sample_sessions``, in a temporary folder; or ``--model DIR``) and with the built-in rule model:

1. **Jitter**: the median over frames of the largest frame-to-frame step of any blendshape
   weight (:func:`effortface.synth.face.jitter`), raw (``filter_tau_s=0``) and filtered (the
   model's time constant, 0.15 s by default); also each weight's mean, to show the face keeps
   its level. Ratio raw / filtered.
2. **Cost per frame**: one :class:`~effortface.synth.face.WeightFilter` step, against a baseline
   measured in the same process: one step of the live stream the filter sits in
   (``model.stream(...).step``: energies, physiology, face model and filter). Also the whole-clip
   filter (:func:`~effortface.synth.face.filter_weights`) against the whole-clip synthesis.

Run: ``python benchmarks/bench_jitter.py [--model DIR] [--loops 10]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scipy.interpolate import CubicSpline  # noqa: E402

from effortface.synth.energy import G_M_PER_S2, EnergyStream, work_and_power  # noqa: E402
from effortface.synth.face import WeightFilter, filter_weights, jitter  # noqa: E402
from effortface.synth.motion import Motion, motion_from_positions, read_motion  # noqa: E402
from effortface.synth.segments import BodyModel, build_body  # noqa: E402
from effortface.synth.runtime import Character, FaceModel, load_model  # noqa: E402

CLIP = ROOT / "tests" / "data" / "motion" / "cmu_13_29_jumping_jacks_120fps.bvh"
REAL_CLIPS = ("amp_humanoid_walk.npz", "amp_humanoid_run.npz", "cmu_13_29_jumping_jacks_120fps.bvh")


def looped_clip(loops: int) -> Motion:
    """The clip played forwards then backwards ``loops`` times (a palindrome: no jumps at the seams)."""
    clip = read_motion(CLIP)
    order = np.r_[np.arange(clip.n_frames), np.arange(clip.n_frames)[::-1]]
    idx = np.resize(order, loops * clip.n_frames)
    assert clip.rotations is not None
    return dataclasses.replace(clip, positions_m=clip.positions_m[idx], rotations=clip.rotations[idx])


def train_model(folder: Path) -> Path:
    """An SVR bundle trained on the sample lab with the command line (small grid)."""
    out = folder / "model"
    subprocess.run([sys.executable, "-m", "effortface", "train", str(ROOT / "sample_sessions"),
                    "--out", str(out)], check=True, cwd=ROOT, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return out


def _weights(curves: dict[str, np.ndarray], model: FaceModel) -> np.ndarray:
    return np.column_stack([curves[n] for n in model.blendshapes.names])


def jitter_figures(model: FaceModel, motion: Motion, label: str) -> None:
    """Print jitter and mean weights, raw and filtered."""
    hero = Character()
    raw = _weights(model.synthesize(motion, hero, filter_tau_s=0), model)
    smooth = _weights(model.synthesize(motion, hero), model)
    j_raw, j_smooth = jitter(raw), jitter(smooth)
    print(f"{label}: tau = {model.filter_tau_s[0]:g} s, {motion.n_frames} frames at {motion.fps:g} Hz")
    print(f"  jitter (median largest frame-to-frame step): raw {j_raw:.5f}, filtered {j_smooth:.5f}, "
          f"ratio {j_raw / j_smooth:.1f}x")
    print(f"  largest step anywhere: raw {np.abs(np.diff(raw, axis=0)).max():.4f}, "
          f"filtered {np.abs(np.diff(smooth, axis=0)).max():.4f}")
    for i, name in enumerate(model.blendshapes.names):
        print(f"  {name:14s} mean raw {raw[:, i].mean():.3f}  filtered {smooth[:, i].mean():.3f}")


def _per_call_s(fn, n: int) -> float:
    """Best of 3 runs of ``n`` calls: seconds per call."""
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(n):
            fn(k)
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def cost_figures(model: FaceModel, motion: Motion, label: str) -> None:
    """Print the filter's cost per frame and per clip, with same-process baselines."""
    hero = Character()
    dt = 1.0 / motion.fps
    n = min(2000, motion.n_frames)
    raw = _weights(model.synthesize(motion, hero, filter_tau_s=0), model)
    filt = WeightFilter(model.filter_tau_s)
    filter_s = _per_call_s(lambda k: filt.step(raw[k], dt), n)
    live = model.stream(hero, motion)
    assert motion.rotations is not None
    rot = motion.rotations
    stream_s = _per_call_s(lambda k: live.step(motion.positions_m[k % motion.n_frames], dt,
                                               rot[k % motion.n_frames]), n)
    clip_filter_s = _per_call_s(lambda k: filter_weights(raw, dt, model.filter_tau_s), 3)
    clip_synth_s = _per_call_s(lambda k: model.synthesize(motion, hero), 1)
    print(f"{label}: filter step {filter_s * 1e6:.1f} us/frame; baseline live stream step "
          f"{stream_s * 1e6:.1f} us/frame; filter share {filter_s / stream_s:.1%}")
    print(f"  whole clip: filter {clip_filter_s * 1e3:.2f} ms, synthesize {clip_synth_s * 1e3:.1f} ms, "
          f"filter share {clip_filter_s / clip_synth_s:.1%} "
          f"({clip_filter_s / motion.n_frames * 1e9:.0f} ns/frame)")


def _frame_times(fps: float, jitter_frac: float, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Frame times from 0 and each frame's dt_s: 1 / fps times 1 +- ``jitter_frac`` (seeded)."""
    rng = np.random.default_rng(28)
    dt_s = (1.0 + rng.uniform(-jitter_frac, jitter_frac, int(duration_s * fps * 1.5) + 2)) / fps
    t_s = np.concatenate([[0.0], np.cumsum(dt_s[1:])])
    keep = t_s <= duration_s
    return t_s[keep], dt_s[keep]


def _streamed_w(body: BodyModel, positions_at, t_s: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """w (W/kg) of each step of a stream on a 60 fps skeleton fed the positions at ``t_s``."""
    stream = EnergyStream(body, 60.0)
    pos = positions_at(t_s)
    return np.array([stream.step(pos[k], dt_s[k])[0] for k in range(t_s.size)])


def _rod_body() -> BodyModel:
    return BodyModel(segment_names=("rod",), mass_kg=70.0, segment_mass_kg=np.array([70.0]),
                     length_m=np.array([0.4]), com_frac=np.array([0.5]), radii=np.array([(0.3, 0.25, 0.1)]),
                     proximal_weights=np.array([[1.0, 0.0]]), distal_weights=np.array([[0.0, 1.0]]),
                     frame_joint=np.array([0]), hip_joints=(0, 1), load_kg=np.zeros(1))


def _rod(com_m: np.ndarray) -> np.ndarray:
    half = np.array([0.0, 0.2, 0.0])
    return np.stack([com_m - half, com_m + half], axis=1)


def frame_time_figures() -> None:
    """Print the live work of a glide, a free fall and three real clips under frame-time jitter."""
    def glide(t_s: np.ndarray) -> np.ndarray:
        return _rod(np.column_stack([3.4 * t_s, np.zeros_like(t_s), np.ones_like(t_s)]))

    def fall(t_s: np.ndarray) -> np.ndarray:
        return _rod(np.column_stack([np.zeros_like(t_s), np.zeros_like(t_s), 30.0 - 0.5 * G_M_PER_S2 * t_s**2]))

    print("live work under +-30 % frame-time jitter (stream on a 60 fps skeleton; reference 0 W/kg)")
    for name, fn in (("glide 3.4 m/s", glide), ("free fall", fall)):
        cells = []
        for fps in (30.0, 60.0, 120.0):
            t_s, dt_s = _frame_times(fps, 0.3, 2.5)
            cells.append(f"{fps:g} fps {_streamed_w(_rod_body(), fn, t_s, dt_s)[t_s >= 1.5].max():.5f}")
        print(f"  {name:14s} largest w after 1.5 s: " + ", ".join(cells) + " W/kg")
    print("real clips: mean w after 1 s, ratio to the steady 60 fps stream (baseline)")
    for name in REAL_CLIPS:
        motion = read_motion(ROOT / "tests" / "data" / "motion" / name)
        pos = motion.positions_m
        pairs = motion.n_frames // 2
        held = bool(np.all(np.abs(pos[1:2 * pairs:2] - pos[0:2 * pairs:2]) < 1e-9))
        idx = np.arange(0, motion.n_frames, 2) if held else np.arange(motion.n_frames)
        spline = CubicSpline(idx / motion.fps, pos[idx], axis=0)
        end_s = float(idx[-1] / motion.fps)
        body = build_body(motion.joint_names, motion.parents, 70.0, "female", reference_positions_m=pos)
        means = {}
        for label, fps, jit in (("steady 60", 60.0, 0.0), ("30 +-30%", 30.0, 0.3), ("60 +-30%", 60.0, 0.3)):
            t_s, dt_s = _frame_times(fps, jit, end_s)
            w = _streamed_w(body, spline, t_s, dt_s)
            means[label] = np.average(w[t_s >= 1.0], weights=dt_s[t_s >= 1.0])
        t60 = np.arange(int(end_s * 60) + 1) / 60.0
        clip60 = motion_from_positions(spline(t60), motion.joint_names, motion.parents, 60.0)
        for label, zp in (("offline causal", False), ("offline zero-phase", True)):
            w = work_and_power(clip60, body, zero_phase=zp, use_rotations=False).w_per_kg
            means[label] = w[(t60 >= 1.0) & (t60 <= end_s - (0.2 if zp else 0.0))].mean()
        base = means.pop("steady 60")
        print(f"  {name} ({'poses held twice, played at 30 Hz' if held else 'every frame a pose'}): "
              f"steady 60 fps {base:.3f} W/kg; " + ", ".join(f"{k} {v / base:.3f}x" for k, v in means.items()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=None, help="trained bundle (default: train one)")
    parser.add_argument("--loops", type=int, default=10, help="clip passes (default 10)")
    parser.add_argument("--frame-times", action="store_true",
                        help="print only the live work under frame-time jitter (no training)")
    args = parser.parse_args(argv)
    frame_time_figures()
    if args.frame_times:
        return 0
    motion = looped_clip(args.loops)
    with tempfile.TemporaryDirectory() as tmp:
        model_dir = args.model or train_model(Path(tmp))
        trained = load_model(model_dir)
        for model, label in ((trained, f"trained SVR bundle ({model_dir.name})"),
                             (load_model("default"), "built-in rule model")):
            jitter_figures(model, motion, label)
            cost_figures(model, motion, label)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
