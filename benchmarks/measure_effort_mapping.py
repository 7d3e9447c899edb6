"""The effort mapping before -> after on real face videos (docs/guide/machine-rater-effort-mapping.md).

    python benchmarks/measure_effort_mapping.py [VIDEO ...] [--rest-s 0.6]

Each video (by default the four GRID clips of tests/data/faces/grid) becomes a session as a camera
stores it (tests/annotate/grid_clips.py: MJPG ``video.avi``, its frame times, a first rest phase over
the first ``--rest-s`` seconds; 0 for none) in a temporary folder and is rated by ``effortface
preannotate``. Per clip and blendshape it prints the median and 95th percentile of the definition
mapping (before) and the effort mapping (after), and the Pearson r with the blendshape's look-alike:
mean eyeBlink for eye_squint, mean mouthSmile for mouth_stretch, browInnerUp for brow_lower, mouthClose
for mouth_open.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from effortface.annotate.machine.landmarker import ARKIT_NAMES  # noqa: E402
from effortface.annotate.machine.mapping import default_mapping, map_scores  # noqa: E402
from effortface.annotate.machine.preannotate import preannotate_session  # noqa: E402
from effortface.annotate.machine.track import FOUR, read_machine_track  # noqa: E402
from tests.annotate import grid_clips  # noqa: E402

LOOK_ALIKE = {"mouth_stretch": ("mouthSmileLeft", "mouthSmileRight"), "mouth_open": ("mouthClose",),
              "eye_squint": ("eyeBlinkLeft", "eyeBlinkRight"), "brow_lower": ("browInnerUp",)}


def _r(a: np.ndarray, b: np.ndarray) -> float:
    return float("nan") if np.ptp(a) == 0 or np.ptp(b) == 0 else float(np.corrcoef(a, b)[0, 1])


def measure(video: Path, lab: Path, code: str, rest_s: float) -> list[tuple[str, str, str, str, str]]:
    """Table rows (clip, blendshape, median, p95, r) of one video, ``before -> after``."""
    session = grid_clips.clip_session(video, lab, code, rest_s=rest_s)
    preannotate_session(session, num_threads=1)
    track = read_machine_track(session)
    assert track is not None
    face = track.face
    before = map_scores(track.scores, default_mapping(), FOUR)[face]
    after = track.weights[face]
    index = {a: i for i, a in enumerate(ARKIT_NAMES)}
    rows = []
    for j, name in enumerate(FOUR):
        alike = track.scores[face][:, [index[a] for a in LOOK_ALIKE[name]]].mean(axis=1)
        rows.append((video.stem, name, f"{np.median(before[:, j]):.2f} -> {np.median(after[:, j]):.2f}",
                     f"{np.percentile(before[:, j], 95):.2f} -> {np.percentile(after[:, j], 95):.2f}",
                     f"{_r(before[:, j], alike):.2f} -> {_r(after[:, j], alike):.2f}"))
    return rows


def main(argv: list[str] | None = None) -> int:
    """Print the before -> after table as Markdown rows."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("videos", nargs="*", type=Path,
                        default=[grid_clips.GRID / f"{c}.mpg" for c in grid_clips.CLIPS])
    parser.add_argument("--rest-s", type=float, default=grid_clips.REST_S)
    args = parser.parse_args(argv)
    print("| clip | blendshape | median | p95 | r with look-alike |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k, video in enumerate(args.videos):
            for row in measure(video, Path(tmp), f"V{k + 1:02d}", args.rest_s):
                print("| `" + row[0] + "` | " + " | ".join(row[1:]) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
