"""How a real face model reads the sample lab's faces: MediaPipe's Face Landmarker on every frame.

For each session of a lab folder (default ``sample_sessions/``) every frame of ``video.avi`` is rated
by MediaPipe's Face Landmarker (Tasks API, IMAGE mode, the bundle ``../shared/models/face_landmarker.task``
or ``--model``) and the raw ARKit scores are mapped to the four blendshapes with no calibration
(issue 23): ``mouth_open`` <- ``jawOpen``, ``mouth_stretch`` <- mean of ``mouthStretchLeft/Right``,
``eye_squint`` <- mean of ``eyeSquintLeft/Right``, ``brow_lower`` <- mean of ``browDownLeft/Right``.
Printed per session: the share of frames with a face, and Pearson's r of each machine curve against
the human raters' mean (the three raters' key-frame curves evaluated at every frame), with the same r
against the generator's true weights (``_ground_truth``) beside it as the ceiling. The baseline in the
same process: the r of one human rater (R1) against the other raters' mean.

Needs ``mediapipe`` (exit 2 with a message when it is missing). Run:
``python benchmarks/measure_sample_faces.py [LAB] [--model FILE] [--only SESSION_ID] [--every N]``

``--sheet PNG`` instead writes a contact sheet (no face model needed): per participant, the frames of
their strength session at the lowest, middle and highest true weights, each labelled with the four
true weights S(tretch) O(pen) Q (squint) B(row) (``docs/screenshots/sample_faces.png`` is made so).
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from effortface.annotate.keyframes import read_annotations  # noqa: E402

from effortface.core.blendshapes import DEFAULT_SET  # noqa: E402
from effortface.core.face_landmarker import DEFAULT_MODEL as SHIPPED_MODEL  # noqa: E402

ARKIT = {"mouth_stretch": ("mouthStretchLeft", "mouthStretchRight"), "mouth_open": ("jawOpen",),
         "eye_squint": ("eyeSquintLeft", "eyeSquintRight"), "brow_lower": ("browDownLeft", "browDownRight")}
#: the bundle the package ships (it moved with the engine to effortface.core: one path, the engine's)
DEFAULT_MODEL = SHIPPED_MODEL


def _landmarker(model: Path):
    from mediapipe.tasks.python import BaseOptions, vision

    opts = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(model)),
                                        running_mode=vision.RunningMode.IMAGE, num_faces=1,
                                        output_face_blendshapes=True)
    return vision.FaceLandmarker.create_from_options(opts)


def rate_video(video: Path, landmarker, every: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Frame numbers and the four raw machine weights per frame (NaN where no face)."""
    import cv2
    import mediapipe as mp

    cap = cv2.VideoCapture(str(video))
    frames, rows, k = [], [], 0
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        if k % every == 0:
            img = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(bgr[:, :, ::-1]))
            res = landmarker.detect(img)
            if res.face_blendshapes:
                s = {c.category_name: c.score for c in res.face_blendshapes[0]}
                rows.append([float(np.mean([s[a] for a in ARKIT[n]])) for n in DEFAULT_SET.names])
            else:
                rows.append([np.nan] * 4)
            frames.append(k)
        k += 1
    cap.release()
    return np.array(frames), np.array(rows, dtype=float)


def human_mean(session: Path, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The raters' mean curve at ``frames`` (n, 4) and R1's own curve (for the baseline)."""
    curves = []
    for path in sorted((session / "annotations").glob("*.json")):
        ann = read_annotations(path)
        curves.append(np.column_stack([ann.tracks[n].evaluate(frames) for n in DEFAULT_SET.names]))
    return np.mean(curves, axis=0), np.array(curves)


def truth(lab: Path, session: Path, frames: np.ndarray) -> np.ndarray | None:
    """The generator's true weights at ``frames`` (None without ``_ground_truth``)."""
    path = lab / "_ground_truth" / session.name / "blendshapes.csv"
    if not path.is_file():
        return None
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    table = np.array([[float(r[n]) for n in DEFAULT_SET.names] for r in rows])
    return table[frames]


def _r(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def contact_sheet(lab: Path, out: Path, per_row: int = 5, scale: int = 1) -> Path:
    """Frames at rising true weights, one row per participant, labelled with the weights."""
    import cv2

    rows = []
    for session in sorted(p for p in lab.iterdir() if (p / "video.avi").is_file() and p.name.endswith("_strength")):
        with open(lab / "_ground_truth" / session.name / "blendshapes.csv", newline="", encoding="utf-8") as fh:
            table = np.array([[float(r[n]) for n in DEFAULT_SET.names] for r in csv.DictReader(fh)])
        order = np.argsort(table.sum(axis=1))
        picks = order[np.linspace(0, len(order) - 1, per_row).round().astype(int)]
        cap = cv2.VideoCapture(str(session / "video.avi"))
        tiles = []
        for k in picks:
            cap.set(cv2.CAP_PROP_POS_FRAMES, int(k))
            ok, img = cap.read()
            if not ok:
                continue
            img = cv2.resize(img, (img.shape[1] * scale, img.shape[0] * scale), interpolation=cv2.INTER_NEAREST)
            label = " ".join(f"{a}{v:.2f}" for a, v in zip(("S", "O", "Q", "B"), table[k]))
            cv2.rectangle(img, (0, img.shape[0] - 13), (img.shape[1], img.shape[0]), (0, 0, 0), -1)
            cv2.putText(img, label, (3, img.shape[0] - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (255, 255, 255), 1,
                        cv2.LINE_AA)
            tiles.append(img)
        cap.release()
        head = np.zeros((tiles[0].shape[0], 44, 3), np.uint8)
        cv2.putText(head, session.name.split("_")[0], (4, head.shape[0] // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)
        rows.append(np.hstack([head, *tiles]))
    sheet = np.vstack(rows)
    cv2.imwrite(str(out), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return out


def main(argv: list[str] | None = None) -> int:
    """Print the table; return 0 (2 when mediapipe or the model is missing)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("lab", nargs="?", type=Path, default=ROOT / "sample_sessions")
    ap.add_argument("--model", type=Path, default=DEFAULT_MODEL)
    ap.add_argument("--only", help="one session id")
    ap.add_argument("--every", type=int, default=1, help="rate every Nth frame (default 1: all)")
    ap.add_argument("--per-row", type=int, default=5, help="frames per participant on the sheet")
    ap.add_argument("--sheet", type=Path, metavar="PNG", help="write a contact sheet instead (no face model)")
    args = ap.parse_args(argv)
    if args.sheet is not None:
        print(contact_sheet(args.lab, args.sheet, args.per_row))
        return 0
    try:
        import mediapipe  # noqa: F401
    except ImportError:
        print("measure_sample_faces: mediapipe is not installed; nothing measured", file=sys.stderr)
        return 2
    if not args.model.is_file():
        print(f"measure_sample_faces: --model: expected the Face Landmarker bundle, found no {args.model}",
              file=sys.stderr)
        return 2
    lm = _landmarker(args.model)
    names = DEFAULT_SET.names
    print(f"{'session':32s} {'face %':>6s}  " + "  ".join(f"{n[:13]:>13s}" for n in names)
          + "   (r machine~humans [machine~truth] | baseline R1~others)")
    worst = np.full(4, np.inf)
    for session in sorted(p for p in args.lab.iterdir() if (p / "video.avi").is_file()):
        if args.only and session.name != args.only:
            continue
        t0 = time.perf_counter()
        frames, machine = rate_video(session / "video.avi", lm, args.every)
        mean, each = human_mean(session, frames)
        true = truth(args.lab, session, frames)
        found = float(np.mean(np.isfinite(machine[:, 0])) * 100)
        rs = [_r(machine[:, j], mean[:, j]) for j in range(4)]
        rt = [_r(machine[:, j], true[:, j]) if true is not None else float("nan") for j in range(4)]
        base = [_r(each[0][:, j], each[1:].mean(0)[:, j]) for j in range(4)]
        worst = np.minimum(worst, rs)
        cells = "  ".join(f"{a:5.2f} [{b:4.2f}]|{c:4.2f}" for a, b, c in zip(rs, rt, base))
        print(f"{session.name:32s} {found:6.1f}  {cells}   {len(frames)} frames, "
              f"{len(frames) / (time.perf_counter() - t0):.0f} frames/s", flush=True)
    print("worst r per blendshape: " + ", ".join(f"{n} {v:.2f}" for n, v in zip(names, worst)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
