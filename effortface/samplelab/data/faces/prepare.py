"""Rebuild the shipped face crops and their landmarks (run once; the generator never imports this).

``python effortface/samplelab/data/faces/prepare.py ASTRONAUT_PNG MEMBER_PHOTOS_DIR [--model TASK]``

Needs ``mediapipe`` (Tasks API) and the Face Landmarker bundle (``../shared/models/face_landmarker.task``).
For each source in :data:`SOURCES` it finds the face, crops a 4:3 window whose face oval fills
:data:`FACE_FILL` of the height, resizes it to :data:`CROP_SIZE`, writes ``<name>.jpg`` (JPEG quality
:data:`JPEG_QUALITY`), then runs the landmarker again on the written JPEG and saves the 478 landmarks
in crop pixels as ``<name>_landmarks.npy`` (float32, shape (478, 2)). PROVENANCE.md lists the sources.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

from effortface.core.opencv import import_cv2

cv2 = import_cv2()

HERE = Path(__file__).resolve().parent
CROP_SIZE = (240, 180)
FACE_FILL = 0.8
JPEG_QUALITY = 92
#: (name, source file relative to its folder): astronaut from scikit-image, the rest from
#: voteview/member_photos images/bio_guide/
SOURCES = (("astronaut", "astronaut.png"), ("bio_022117", "022117.jpg"), ("bio_021506", "021506.jpg"),
           ("bio_021342", "021342.jpg"), ("bio_021937", "021937.jpg"), ("bio_022126", "022126.jpg"))


def _landmarks(lm: object, bgr: np.ndarray) -> np.ndarray | None:
    import mediapipe as mp

    img = mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(bgr[:, :, ::-1]))
    res = lm.detect(img)  # type: ignore[attr-defined]
    if not res.face_landmarks:
        return None
    h, w = bgr.shape[:2]
    return np.array([[p.x * w, p.y * h] for p in res.face_landmarks[0]], dtype=np.float32)


def main(argv: list[str] | None = None) -> int:
    """Write the crops, landmarks and print their sha256."""
    from mediapipe.tasks.python import BaseOptions, vision

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("astronaut", type=Path)
    ap.add_argument("member_photos", type=Path)
    ap.add_argument("--model", type=Path, default=Path("../shared/models/face_landmarker.task"))
    args = ap.parse_args(argv)
    opts = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(args.model)),
                                        running_mode=vision.RunningMode.IMAGE, num_faces=1)
    lm = vision.FaceLandmarker.create_from_options(opts)
    for name, src in SOURCES:
        path = args.astronaut if name == "astronaut" else args.member_photos / src
        img = cv2.imread(str(path))
        if img is None:
            print(f"{path}: expected an image, found none", file=sys.stderr)
            return 2
        pts = _landmarks(lm, img)
        if pts is None:
            print(f"{path}: no face", file=sys.stderr)
            return 2
        top, bottom = pts[10], pts[152]  # forehead, chin
        face_h = float(np.hypot(*(bottom - top))) * 1.15  # hairline above landmark 10
        ch = face_h / FACE_FILL
        cw = ch * CROP_SIZE[0] / CROP_SIZE[1]
        cx, cy = (top + bottom) / 2
        x0 = float(np.clip(cx - cw / 2, 0, max(0.0, img.shape[1] - cw)))
        y0 = float(np.clip(cy - ch / 2 - 0.03 * ch, 0, max(0.0, img.shape[0] - ch)))
        sx, sy = CROP_SIZE[0] / cw, CROP_SIZE[1] / ch
        mat = np.array([[sx, 0, -x0 * sx], [0, sy, -y0 * sy]])
        crop = cv2.warpAffine(img, mat, CROP_SIZE, flags=cv2.INTER_AREA if sx < 1 else cv2.INTER_CUBIC,
                              borderMode=cv2.BORDER_REPLICATE)
        out = HERE / f"{name}.jpg"
        cv2.imwrite(str(out), crop, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        written = cv2.imread(str(out))
        again = None if written is None else _landmarks(lm, written)
        if again is None:
            print(f"{out}: no face in the crop", file=sys.stderr)
            return 2
        np.save(HERE / f"{name}_landmarks.npy", again)
        digest = hashlib.sha256(out.read_bytes()).hexdigest()
        print(f"{name}: source {path.name} {img.shape[1]}x{img.shape[0]}, crop x0={x0:.1f} y0={y0:.1f} "
              f"w={cw:.1f} h={ch:.1f} -> {CROP_SIZE[0]}x{CROP_SIZE[1]}, sha256 {digest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
