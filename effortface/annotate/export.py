"""Exports of one rater's annotations (pure Python + numpy; the Annotate stage's Export menu).

- :func:`write_weights_csv`: per-frame weights ``frame,t_s,<blendshape>...`` (every video frame,
  the key-frame curves evaluated; empty cells where a blendshape has no key);
- :func:`write_keyframes_json`: the key-frame document (the ``annotations/<rater>.json`` format).

Both refuse to overwrite unless told (``FileExistsError``) and write atomically.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from effortface.annotate.keyframes import RaterAnnotations
from effortface.core.fileio import atomic_write_text, refuse_overwrite
from effortface.annotate.video_index import FrameTimes


def weights_table(annotations: RaterAnnotations, times: FrameTimes) -> tuple[list[str], np.ndarray]:
    """Header and rows ``frame, t_s, weights...`` for every video frame."""
    frames = np.arange(len(times))
    header = ["frame", "t_s", *annotations.blendshapes.names]
    return header, np.column_stack([frames, times.t_s, annotations.weights(frames)])


def write_weights_csv(annotations: RaterAnnotations, times: FrameTimes, path: str | os.PathLike, *,
                      overwrite: bool = False) -> Path:
    """Write the per-frame weights CSV.

    Parameters
    ----------
    annotations : RaterAnnotations
        The rater's tracks.
    times : FrameTimes
        The session's frame times (one row per frame).
    path : path-like
        Output file.
    overwrite : bool
        Replace an existing file.

    Returns
    -------
    Path

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.
    """
    path = refuse_overwrite(path, overwrite=overwrite)
    header, rows = weights_table(annotations, times)
    out = io.StringIO()
    out.write(",".join(header) + "\n")
    for row in rows:
        cells = [str(int(row[0])), f"{row[1]:.4f}"]
        cells += ["" if np.isnan(w) else f"{w:.4f}" for w in row[2:]]
        out.write(",".join(cells) + "\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, out.getvalue())
    return path


def write_keyframes_json(annotations: RaterAnnotations, path: str | os.PathLike, *,
                         overwrite: bool = False) -> Path:
    """Write the key-frame JSON (same format as ``annotations/<rater>.json``); FileExistsError unless ``overwrite``."""
    return annotations.save(path, overwrite=overwrite)
