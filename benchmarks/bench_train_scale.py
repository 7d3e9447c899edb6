"""Issue 26: a whole ``effortface train --table T --out M`` run on long generated tables.

For P participants x 1 h (P = 10, 30 by default; 100 with ``--participants 10 30 100``) this builds a
long table (:func:`lab_table`), runs the command line in a subprocess, and prints per size: wall
time, peak RSS of the training process (``os.wait4``'s rusage of that child alone), the exit status,
the float32 ``face.onnx`` parity read back from ``model.json``, the face rows the card names, and the
growth of time and peak memory per row between consecutive sizes (the growth law). The baseline of
every ratio is the smallest size, measured in the same run.

The generated lab (:func:`lab_table`), one row per second:

- per participant a training level TL ~ U(0, 7.5), a body (sex, age, height, mass), an
  expressiveness per blendshape ~ U(0.3, 1);
- exercise levels (W/kg) changing every minute (a random level of the cardio or strength ladder,
  rest minutes among them); work = level + N(0, 0.4) noise per second, power = work x log-normal(0,
  0.2) noise;
- heart rate from the paper's NHR recursion at the participant's TL (``nhr_step``), mapped to bpm
  between rest and maximum, plus N(0, 2 bpm) strap noise;
- face weights = expressiveness x a smooth function of power and a slow fatigue term (the running
  mean of NHR over about 10 min), plus rater noise: AR(1) (0.9, sd 0.03) per blendshape and
  key-frame quantisation to 0.05.

What the trainer cannot know (so held-out errors have a floor): the fatigue term is a 10-minute
memory of NHR, while the features carry only the current NHR and EPOC; the rater noise is
autocorrelated; power differs from work by per-second noise that the weights follow but the heart
does not. The generator is not the trainer's own ``synthetic_table`` (bouts of 40-120 s, other
curves).

Run: ``python benchmarks/bench_train_scale.py [--participants 10 30] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SECONDS_PER_PARTICIPANT = 3600
#: minutes of one exercise level
LEVEL_S = 60
LADDERS = {"cardio": (0.1, 4.0, 8.0, 12.0, 20.0), "strength": (0.1, 2.0, 3.5, 6.0)}
BLENDSHAPES = ("mouthStretch", "browDown", "eyeSquint", "jawOpen")


def lab_table(n_participants: int, seconds: int = SECONDS_PER_PARTICIPANT, seed: int = 0) -> pd.DataFrame:
    """A long table of ``n_participants`` x ``seconds`` rows (module docstring), two sessions each
    (cardio then strength, half the seconds each)."""
    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.train.dataset import hr_max_bpm, hr_rest_bpm
    from effortface.synth.physiology import NhrParams, nhr_step

    rng = np.random.default_rng(seed)
    names = DEFAULT_SET.names
    half = seconds // 2
    frames = []
    for i in range(n_participants):
        code, tl = f"P{i + 1:03d}", float(rng.uniform(0, 7.5))
        sex, age = ("female", "male")[i % 2], float(rng.integers(20, 50))
        body = dict(sex=sex, age=age, height_m=float(rng.uniform(1.6, 1.9)), mass_kg=float(rng.uniform(55, 90)),
                    training_level=tl)
        expressiveness = rng.uniform(0.3, 1.0, len(names))
        rest, top = hr_rest_bpm(age, sex, tl), hr_max_bpm(age)
        params = NhrParams.from_training_level(tl)
        for s, kind in enumerate(LADDERS):
            levels = rng.choice(LADDERS[kind], -(-half // LEVEL_S))
            w = np.clip(np.repeat(levels, LEVEL_S)[:half] + rng.normal(0, 0.4, half), 0, None)
            p = w * rng.lognormal(0, 0.2, half)
            nhr = np.empty(half)
            state = np.asarray(0.05)
            for k in range(half):
                nhr[k] = state = nhr_step(state, w[k], params)
            fatigue = pd.Series(nhr).rolling(600, min_periods=1).mean().to_numpy()
            y = _face(p, fatigue, expressiveness, rng)
            frame = pd.DataFrame({"participant": code, "session": f"{code}_2026010{1 + s}-100000_{kind}",
                                  "t_s": np.arange(half, dtype=float), **body, "w_per_kg": w, "p_per_kg": p,
                                  "hr_bpm": rest + nhr * (top - rest) + rng.normal(0, 2.0, half),
                                  "exercise": kind})
            for j, name in enumerate(names):
                frame[name] = y[:, j]
            frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def _face(p_per_kg: np.ndarray, fatigue: np.ndarray, expressiveness: np.ndarray,
          rng: np.random.Generator) -> np.ndarray:
    """Weights (n, B): expressiveness x f(power, fatigue) + AR(1) rater noise, quantised to 0.05."""
    exertion = 1 - np.exp(-p_per_kg / 8.0)
    base = np.column_stack([0.7 * exertion + 0.3 * fatigue, 0.5 * exertion + 0.5 * fatigue ** 2,
                            exertion * (1 - 0.5 * fatigue), np.clip(1.2 * exertion - 0.2, 0, 1)])
    base = base[:, :len(expressiveness)]
    shocks = rng.normal(0, 0.03 * np.sqrt(1 - 0.9 ** 2), base.shape)
    noise = np.zeros_like(base)
    for k in range(1, len(base)):
        noise[k] = 0.9 * noise[k - 1] + shocks[k]
    return np.clip(np.round((base * expressiveness + noise) / 0.05) * 0.05, 0, 1)


def run_train(table_csv: Path, out: Path, extra: list[str]) -> dict:
    """``effortface train --table`` in a subprocess: exit status, wall time, its own peak RSS."""
    err = out.parent / f"{out.name}.stderr"
    t0 = time.perf_counter()
    with err.open("w") as stderr:
        proc = subprocess.Popen([sys.executable, "-m", "effortface", "train", "--table", str(table_csv),
                                 "--out", str(out), *extra], stdout=subprocess.DEVNULL, stderr=stderr)
        _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    result = {"exit": proc.returncode, "seconds": seconds, "peak_mb": usage.ru_maxrss / 1024.0,
              "stderr_tail": err.read_text().strip().splitlines()[-1:]}
    if (out / "model.json").is_file():
        metrics = json.loads((out / "model.json").read_text())
        engine = metrics["metrics"].get("engine_export", {})
        prov = metrics["provenance"]
        result.update(engine_status=engine.get("status"), f32_diff=engine.get("max_abs_diff_vs_runtime"),
                      face_rows=prov.get("n_face_rows"), seconds_in_table=prov.get("n_seconds"),
                      held_out_rmse=_mean_held_out(metrics["metrics"]))
        card = (out / "MODEL_CARD.md").read_text()
        result["card_face_rows"] = next((line for line in card.splitlines() if "face rows" in line), "")
    return result


def _mean_held_out(metrics: dict) -> float:
    rows = [r for r in metrics.get("face_held_out", []) if r.get("model") == "svr"]
    return float(np.mean([r["rmse_pct_unit"] for r in rows])) if rows else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--participants", type=int, nargs="+", default=[10, 30])
    parser.add_argument("--keep", type=Path, help="keep the tables and models in this folder")
    parser.add_argument("--train-args", default="", help="extra options of effortface train, quoted")
    args = parser.parse_args()
    work = args.keep or Path(tempfile.mkdtemp(prefix="bench_train_scale-"))
    work.mkdir(parents=True, exist_ok=True)
    from effortface.train.dataset import write_table

    print(f"issue 26: effortface train --table on generated labs of P participants x 1 h "
          f"({os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f})")
    previous = None
    for n in args.participants:
        t0 = time.perf_counter()
        table = lab_table(n)
        csv = write_table(table, work / f"lab_{n}.csv", overwrite=True)
        built = time.perf_counter() - t0
        rows = len(table)
        del table
        res = run_train(csv, work / f"model_{n}", ["--force", *args.train_args.split()])
        line = (f"  P={n:3d}: {rows:7d} rows (table built in {built:.0f} s): exit {res['exit']}, "
                f"{res['seconds']:6.1f} s, peak RSS {res['peak_mb']:7.0f} MB")
        if "engine_status" in res:
            line += (f", face.onnx {res['engine_status']} (float32 vs runtime {res['f32_diff']:.2g}), "
                     f"{res['face_rows']} face rows, held-out RMSE {res['held_out_rmse']:.2f} % of the unit")
        print(line + f"; load average {os.getloadavg()[0]:.1f}")
        print(f"         card: {res.get('card_face_rows', '').strip()}")
        if res["exit"] != 0:
            print(f"         stderr: {' '.join(res['stderr_tail'])}")
        if previous is not None:
            d_rows = rows - previous[0]
            print(f"         growth from the previous size: {1024 * (res['peak_mb'] - previous[2]) / d_rows:.2f} KB "
                  f"and {1e3 * (res['seconds'] - previous[1]) / d_rows:.3f} ms per row "
                  f"({res['peak_mb'] / previous[2]:.2f}x the memory, {res['seconds'] / previous[1]:.2f}x the time "
                  f"for {rows / previous[0]:.2f}x the rows)")
        previous = (rows, res["seconds"], res["peak_mb"])
    if args.keep is None:
        import shutil

        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
