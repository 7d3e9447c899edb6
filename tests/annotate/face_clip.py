"""A short 640 x 480 clip of real faces with stretches of no face, built from tests/data/faces.

The three photographs (official White House photographs, public domain: tests/data/faces/README.md)
are framed as a camera would see them: each held for a stretch of frames while the view pans and
zooms slowly (so the rater tracks from frame to frame), with faceless stretches between them (the
empty corner of a photograph, where no face is). Nothing is drawn on a face.

Used by tests/annotate/test_machine_rater.py and benchmarks/bench_rater.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

FACES = Path(__file__).resolve().parents[1] / "data" / "faces"
WIDTH, HEIGHT = 640, 480
#: (photo or None for no face, frames) in order
SCRIPT: tuple[tuple[str | None, int], ...] = (
    (None, 15),
    ("obama_2012_portrait.jpg", 40),
    (None, 20),
    ("obama_2009_address.jpg", 40),
    ("biden_2010_blue_room.jpg", 40),
    (None, 15),
)
OPEN_MOUTH = "obama_2009_address.jpg"  # speaking: jaw open
CLOSED_MOUTH = "biden_2010_blue_room.jpg"  # lips together


def _cv2():  # type: ignore[no-untyped-def]
    import cv2

    return cv2


def photo(name: str) -> np.ndarray:
    """A photograph of tests/data/faces as BGR."""
    image = _cv2().imread(str(FACES / name))
    assert image is not None, name
    return np.asarray(image)


def _framed(image: np.ndarray, k: int, n: int) -> np.ndarray:
    """Frame ``k`` of ``n`` of a photograph: scaled to fill the height, panning and zooming slowly."""
    cv2 = _cv2()
    h, w = image.shape[:2]
    zoom = HEIGHT / h * (1.0 + 0.12 * k / max(n - 1, 1))
    dx = WIDTH / 2 - w * zoom / 2 + 30 * np.sin(k / 9.0)
    dy = HEIGHT / 2 - h * zoom / 2 + 10 * np.cos(k / 7.0)
    matrix = np.array([[zoom, 0, dx], [0, zoom, dy]], dtype=np.float64)
    return np.asarray(cv2.warpAffine(image, matrix, (WIDTH, HEIGHT), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REFLECT))


def _no_face(k: int) -> np.ndarray:
    """A faceless frame: the top-left corner of the Blue Room photograph (wall and curtain), enlarged."""
    cv2 = _cv2()
    corner = photo(CLOSED_MOUTH)[:90, :120]
    frame = cv2.resize(corner, (WIDTH, HEIGHT), interpolation=cv2.INTER_LINEAR)
    return np.asarray(np.roll(frame, 3 * k, axis=1))


def frames() -> list[tuple[np.ndarray, str | None]]:
    """Every frame of the clip (BGR) with the photograph it shows (None: no face)."""
    out: list[tuple[np.ndarray, str | None]] = []
    for name, n in SCRIPT:
        image = photo(name) if name is not None else None
        for k in range(n):
            out.append((_framed(image, k, n) if image is not None else _no_face(k), name))
    return out


def write_clip(path: Path, fps: float = 30.0) -> list[str | None]:
    """Write the clip as an MJPG AVI (as a camera session stores it); return the photograph of each frame."""
    cv2 = _cv2()
    writer = cv2.VideoWriter(str(path), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*"MJPG"), fps, (WIDTH, HEIGHT))
    assert writer.isOpened(), path
    names = []
    try:
        for image, name in frames():
            writer.write(image)
            names.append(name)
    finally:
        writer.release()
    return names
