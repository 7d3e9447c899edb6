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

With ``--hr-only`` it runs instead, in this process, only the heart-rate evaluation
(``evaluate_hr_models``, the step that refitted everyone once per participant) on the same generated
tables, and prints its seconds per size and the growth between sizes (time ratio against row ratio:
1 is linear). Below ``--hr-reference-max`` participants it also times the plain refit (every
held-out model fitted again on the other participants' sessions, every session simulated on its
own: the evaluation as it was) on the same table, checks that both give the same scores, and prints
the ratio: the same evaluation on both sides.

Run: ``python benchmarks/bench_train_scale.py [--participants 10 30] [--keep DIR]``, or
``python benchmarks/bench_train_scale.py --hr-only --participants 10 30 100``.
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


def refit_evaluation(series: list) -> dict[str, dict[str, float]]:
    """The heart-rate evaluation the plain way (the baseline): per held-out participant the pooled
    tree and the training-level model refitted on everyone else, each session simulated alone.
    Returns the summary, to be compared with ``evaluate_hr_models``'s."""
    from effortface.train.hr_fit import (HrEvaluation, by_participant, fit_hr_model, fit_participant,
                                         held_out_time_blocks, score_series, simulate_series)

    fit = fit_hr_model(series)
    scores = []
    for code, own in by_participant(series).items():
        rest = fit_hr_model([s for s in series if s.participant != code])
        for s in own:
            for name, coef in (("per_participant_in_sample", fit.per_participant[code]),
                               ("pooled_threshold", rest.pooled),
                               ("tl_regression", rest.tl_regression.at(own[0].training_level))):
                scores.append(score_series(s, simulate_series(s, coef), name))
        for fit_on, score_on in held_out_time_blocks(own):
            try:
                coef = fit_participant(fit_on)
            except ValueError:
                continue
            scores += [score_series(b, simulate_series(b, coef), "per_participant") for b in score_on]
    return HrEvaluation(scores, {}, fit).summary()


def hr_only(sizes: list[int], reference_max: int) -> None:
    """Time ``evaluate_hr_models`` in this process on generated tables of each size (module docstring)."""
    from effortface.train.dataset import hr_series, prepare
    from effortface.train.hr_fit import evaluate_hr_models

    print(f"heart-rate evaluation (evaluate_hr_models) on generated labs of P participants x 1 h, in-process "
          f"({os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f})")
    previous = None
    for n in sizes:
        prepared = prepare(lab_table(n))
        rows = len(prepared)
        series = hr_series(prepared)
        del prepared
        t0 = time.perf_counter()
        summary = evaluate_hr_models(series).summary()
        seconds = time.perf_counter() - t0
        line = (f"  P={n:3d}: {rows:7d} rows, {len(series)} sessions: {seconds:6.2f} s; pooled tree held-out "
                f"RMSE {summary['pooled_threshold']['rmse_pct']:.3f} %, TL model {summary['tl_regression']['rmse_pct']:.3f} %")
        if previous is not None:
            line += (f"; growth {seconds / previous[1]:.2f}x the time for {rows / previous[0]:.2f}x the rows "
                     f"({seconds / previous[1] / (rows / previous[0]):.2f} per unit of rows, 1 = linear)")
        print(line + f"; load average {os.getloadavg()[0]:.1f}", flush=True)
        if n <= reference_max:
            t0 = time.perf_counter()
            ref = refit_evaluation(series)
            ref_s = time.perf_counter() - t0
            same = all(abs(ref[m][k] - summary[m][k]) <= 1e-12 * max(1.0, abs(ref[m][k]))
                       for m in ref for k in ref[m])
            print(f"         baseline, plain refit (same evaluation): {ref_s:6.2f} s, {ref_s / seconds:.1f}x "
                  f"the time; summaries {'identical to 1e-12' if same else 'DIFFER'}", flush=True)
        previous = (rows, seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--participants", type=int, nargs="+", default=[10, 30])
    parser.add_argument("--keep", type=Path, help="keep the tables and models in this folder")
    parser.add_argument("--train-args", default="", help="extra options of effortface train, quoted")
    parser.add_argument("--hr-only", action="store_true",
                        help="time only the heart-rate evaluation, in-process (no training run)")
    parser.add_argument("--hr-reference-max", type=int, default=30,
                        help="with --hr-only: also time the plain refit up to this many participants")
    args = parser.parse_args()
    if args.hr_only:
        hr_only(args.participants, args.hr_reference_max)
        return
    work = args.keep or Path(tempfile.mkdtemp(prefix="bench_train_scale-"))
    work.mkdir(parents=True, exist_ok=True)
    from effortface.train.dataset import write_table

    print(f"issue 26: effortface train --table on generated labs of P participants x 1 h "
          f"({os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f})")
    previous = None
    sizes: list[tuple[int, float, float]] = []
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
        sizes.append(previous)
    if len(sizes) > 1:
        (r0, s0, m0), (r1, s1, m1) = sizes[-2], sizes[-1]
        print(f"growth law ({r0} -> {r1} rows): {1024 * (m1 - m0) / (r1 - r0):.2f} KB of peak RSS and "
              f"{1e3 * (s1 - s0) / (r1 - r0):.3f} ms of wall time per row (goal: < 1 KB per row)")
    if args.keep is None:
        import shutil

        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
