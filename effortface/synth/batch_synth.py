"""Batch synthesis: every motion clip of a folder -> one curves file per clip (``effortface synth
MODEL CLIPS_DIR --out OUT_DIR``).

Each clip is one task (:func:`effortface.synth.parallel.map_unordered`: in this process, or on a
Dask cluster with ``--workers N`` / ``--scheduler ADDRESS``). A clip that cannot be read or
synthesized is reported and skipped; it never stops the batch. The clips are the files of the
folder (not its sub-folders) that :func:`effortface.synth.motion.read_motion` reads: ``.bvh``,
``.npz``, joint-positions ``.csv`` and ``.c3d``. Clip ``walk.bvh`` gives ``OUT_DIR/walk.csv`` (the
per-frame CSV or, with ``--format livelink``, the Live Link Face CSV). On a remote scheduler the
workers must see the model folder, the clips and ``OUT_DIR`` at the same paths.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from effortface.core.errors import UserError
from effortface.synth.curves_io import output_files, write_curves
from effortface.synth.motion import MOTION_SUFFIXES
from effortface.synth.plausibility import read_checked, reading_record
from effortface.synth.read_options import MotionReadOptions
from effortface.synth.parallel import ComputeSettings, compute_backend, map_unordered
from effortface.synth.runtime import Character, FaceModel, load_model

#: suffixes of the clips a batch takes (those :func:`read_motion` reads)
CLIP_SUFFIXES = MOTION_SUFFIXES


@dataclasses.dataclass(frozen=True)
class SynthOptions:
    """What every clip of a batch shares: the model, the character and the output settings."""

    model_dir: str
    character: Character
    fmt: str = "csv"
    force: bool = False
    mapping: Any = None
    unit_m: float | None = None
    filter_tau_s: Any = None
    up: str | None = None
    trust_skeleton: bool = False


@dataclasses.dataclass(frozen=True)
class ClipResult:
    """One clip's outcome: the file written and its frames, or the error (one line)."""

    clip: Path
    out: Path
    n_frames: int = 0
    duration_s: float = 0.0
    error: str | None = None


@dataclasses.dataclass
class BatchSummary:
    """The outcome of a batch."""

    results: list[ClipResult]
    elapsed_s: float

    @property
    def failed(self) -> list[ClipResult]:
        """The clips that were skipped, in clip order."""
        return sorted((r for r in self.results if r.error), key=lambda r: r.clip.name)

    @property
    def n_frames(self) -> int:
        """Frames synthesized (good clips)."""
        return sum(r.n_frames for r in self.results if not r.error)


def list_clips(folder: Path) -> list[Path]:
    """The clips of ``folder`` (by suffix, sorted by name).

    Raises
    ------
    UserError
        A folder without any clip.
    """
    clips = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in CLIP_SUFFIXES)
    if not clips:
        raise UserError(f"{folder}: expected motion clips ({', '.join(CLIP_SUFFIXES)}), found none")
    return clips


def output_paths(clips: list[Path], out_dir: Path, force: bool, fmt: str = "csv") -> dict[Path, Path]:
    """The curves file of every clip (``OUT_DIR/<clip stem>.csv``, and its units sidecar for the
    ``csv`` format), checked before any work.

    Raises
    ------
    UserError
        Two clips with one stem, an existing file without ``force``, or ``--out`` a file.
    """
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out {out_dir}: expected a folder for a folder of clips, found a file")
    outs: dict[Path, Path] = {}
    seen: dict[str, Path] = {}
    for clip in clips:
        if clip.stem in seen:
            raise UserError(f"{clip}: expected one clip per name, found also {seen[clip.stem].name} "
                            f"(both would write {clip.stem}.csv)")
        seen[clip.stem] = clip
        outs[clip] = out_dir / f"{clip.stem}.csv"
    existing = [t for o in outs.values() for t in output_files(o, fmt) if t.exists()]
    if existing and not force:
        raise UserError(f"--out {out_dir}: expected new files, found {len(existing)} existing "
                        f"(first {existing[0].name}; use --force to replace them)")
    return outs


@functools.lru_cache(maxsize=4)
def _model(model_dir: str) -> FaceModel:
    """The model, loaded once per process (each Dask worker loads it at its first clip)."""
    return load_model(model_dir)


def synth_clip(task: tuple[Path, Path, SynthOptions]) -> ClipResult:
    """Synthesize one clip and write its file; any failure becomes the result's one-line error."""
    clip, out, opts = task
    try:
        model = _model(opts.model_dir)
        motion, body = read_checked(clip, MotionReadOptions(opts.unit_m, opts.up, opts.mapping,
                                                            opts.trust_skeleton))
        curves = model.synthesize(motion, opts.character, mapping=opts.mapping,
                                  filter_tau_s=opts.filter_tau_s)
        write_curves(out, curves, model, fmt=opts.fmt, force=opts.force, reading=reading_record(motion, body))
        return ClipResult(clip, out, motion.n_frames, motion.n_frames / motion.fps)
    except Exception as exc:  # a bad clip is reported and skipped, never stops the batch
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if not isinstance(exc, UserError):
            text = f"{type(exc).__name__}: {text}"
        return ClipResult(clip, out, error=text)


def synth_batch(clips_dir: Path, out_dir: Path, options: SynthOptions,
                compute: ComputeSettings | None = None,
                on_result: Callable[[ClipResult], object] | None = None) -> BatchSummary:
    """Synthesize every clip of ``clips_dir`` into ``out_dir`` (created if missing).

    Parameters
    ----------
    clips_dir : Path
        The folder of clips (:func:`list_clips`).
    out_dir : Path
        The folder of curves files (its parent must exist).
    options : SynthOptions
        Model, character and output settings (checked by the caller).
    compute : ComputeSettings, optional
        Where the clips run (default: this process).
    on_result : callable, optional
        Called with each :class:`ClipResult` as it finishes (a progress bar).

    Returns
    -------
    BatchSummary

    Raises
    ------
    UserError
        No clips, outputs that exist without ``force``, or an ``--out`` that cannot be made.
    """
    clips = list_clips(clips_dir)
    outs = output_paths(clips, out_dir, options.force, options.fmt)
    if not out_dir.parent.is_dir():
        raise UserError(f"--out {out_dir}: expected an existing parent folder, found no {out_dir.parent}")
    out_dir.mkdir(exist_ok=True)
    start = time.perf_counter()
    results = []
    with compute_backend(compute):
        for result in map_unordered(synth_clip, [(c, outs[c], options) for c in clips]):
            results.append(result)
            if on_result:
                on_result(result)
    return BatchSummary(results, time.perf_counter() - start)
