"""Baking in Blender: a 10-minute 120 Hz action, against a baseline measured in the same process.

The action: the real CMU jumping-jacks clip tiled forwards then backwards (a palindrome: no jumps at
the seams) to ``--minutes``, written as a BVH file and imported with Blender's own importer. The
bake (``bpy.ops.effortface.bake_face()``: Blender evaluates the armature at every frame, the runtime
synthesizes, seven shape keys and four custom properties are keyed) must take less than 1/20 of the
action's duration (30 s for 10 minutes). Baseline: the runtime on the same BVH file outside Blender
(``load_model("default").synthesize(path, character)``, what ``effortface synth`` does), so the
ratio is the cost of Blender's evaluation and keying.

Run: ``python benchmarks/bench_blender.py [--minutes 10]`` from the project's environment. Blender
runs in an interpreter of its own, found as the Blender tests find it (tests/blender/bpy_env.py):
``EFFORTFACE_BPY_PYTHON`` if set, else the cached virtual environment with pyproject.toml's
``blender`` extra (bpy 4.5 and its numpy 1.26), made on first use. The script starts itself again in
that interpreter (``--in-blender``, this checkout on PYTHONPATH: the runtime needs numpy only), where
the baseline and the bake are measured in one process.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "examples"))

from bench_data import DATA  # noqa: E402

CLIP = DATA / "motion" / "cmu_13_29_jumping_jacks_120fps.bvh"
#: the target: bake time / action duration
TARGET_RATIO = 1 / 20


def tiled_bvh(minutes: float, out: Path) -> tuple[Path, int]:
    """The clip's frame lines tiled as a palindrome to ``minutes`` at its 120 Hz; (path, frames)."""
    lines = CLIP.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().startswith("Frame Time"))
    frames = [f for f in lines[at + 1:] if f.strip()]
    n = int(round(minutes * 60 * 120))
    cycle = frames + frames[-2:0:-1]
    body = [cycle[k % len(cycle)] for k in range(n)]
    out.write_text("\n".join(lines[:at - 1] + [f"Frames: {n}", lines[at]] + body) + "\n")
    return out, n


def main() -> int:
    """Start the measurement in Blender's interpreter (or, with ``--in-blender``, measure); its exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--in-blender", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.in_blender:
        return measure(args.minutes)
    from tests.blender.bpy_env import NoBlender, bpy_python, clean_env

    try:
        blender = bpy_python()
    except NoBlender as exc:
        print(f"bench_blender: {exc}", file=sys.stderr)
        return 2
    print(f"Blender's interpreter: {blender.how}", flush=True)
    env = dict(clean_env(), PYTHONPATH=str(ROOT))
    return subprocess.run([str(blender.python), __file__, "--minutes", str(args.minutes), "--in-blender"],
                          env=env).returncode


def measure(minutes: float) -> int:
    """Measure and print, in an interpreter with bpy; 0 when the bake is within the target."""
    import bpy

    import blender_demo_scene as demo
    from effortface.synth.runtime import Character, load_model

    with tempfile.TemporaryDirectory() as tmp:
        path, n = tiled_bvh(minutes, Path(tmp) / "tiled.bvh")
        duration_s = n / 120
        t0 = time.perf_counter()
        load_model("default").synthesize(path, Character())
        baseline_s = time.perf_counter() - t0
        print(f"add-on: {demo.ensure_addon()}")
        t0 = time.perf_counter()
        demo.build_scene(path)
        import_s = time.perf_counter() - t0
        t0, cpu0 = time.perf_counter(), time.process_time()
        result = bpy.ops.effortface.bake_face()
        bake_s, bake_cpu_s = time.perf_counter() - t0, time.process_time() - cpu0
    ok = result == {"FINISHED"} and bake_s < TARGET_RATIO * duration_s
    print(f"{n} frames ({duration_s / 60:.1f} min at 120 Hz); Blender's BVH import {import_s:.1f} s (not counted)")
    print(f"bake_face: {bake_s:.2f} s = 1/{duration_s / bake_s:.0f} of the action's duration "
          f"(target < 1/{1 / TARGET_RATIO:.0f}: {'met' if ok else 'NOT met'}); "
          f"CPU time {bake_cpu_s:.2f} s = 1/{duration_s / bake_cpu_s:.0f} (wall time waits for a busy machine)")
    print(f"baseline, the runtime on the BVH file outside Blender: {baseline_s:.2f} s; "
          f"bake / baseline = {bake_s / baseline_s:.2f}")
    sys.stdout.flush()
    os._exit(0 if ok else 1)  # the bpy module can hang at interpreter exit


if __name__ == "__main__":
    sys.exit(main())
