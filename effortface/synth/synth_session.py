"""The Synthesize stage's model (Qt-free): a clip, a model, a character, the curves and a play head.

:class:`SynthSession` follows the stage-model convention of :mod:`effortface.core`: the widgets of
:mod:`effortface.synth.gui.synth_stage` call its methods and connect to its ``<thing>_changed``
emitters; a QTimer calls :meth:`SynthSession.advance` with the wall time elapsed, so the play head
moves in real time whatever the frame rate of the display (the rule: a view writes back only through model methods and keeps widget state only).

Curves are recomputed for the whole clip whenever the character or the model changes, at once or,
for the GUI, in the core :class:`~effortface.core.jobs.Jobs`, whose newest result
:meth:`SynthSession.poll` applies on the stage's QTimer (a looped
2-minute clip through an SVR bundle takes about 0.1 s); the work and power of the clip depend only on the body
(mass, sex, loads), so they are cached and reused when only the training level, age, height or
expressiveness change. ``loops`` repeats the clip end to end (:func:`effortface.synth.energy.looped`: the work
window runs across the seam, which is not re-filtered), so that a short clip shows heart rate and
fatigue building up over minutes.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import refuse_overwrite
from effortface.core.jobs import JobResult, Jobs
from effortface.synth.curves_io import CURVE_FORMATS, write_curves
from effortface.synth.energy import EnergyCurves, looped, work_and_power
from effortface.synth.motion import MOTION_SUFFIXES, Motion, read_motion
from effortface.synth.plausibility import check_plausible, reading_record
from effortface.synth.read_options import MotionReadOptions, check_unit_m, check_up
from effortface.synth.motion_csv import is_positions_csv
from effortface.synth.runtime import Character, FaceModel, load_model
from effortface.core.events import Emitter

EXPORT_FORMATS = CURVE_FORMATS
MAX_LOOPS = 200


def find_clips(folder: str | os.PathLike, limit: int = 200) -> list[Path]:
    """Motion clips (``.bvh``, ``.npz``, ``.c3d``, joint-positions ``.csv``) in ``folder`` and below,
    sorted, at most ``limit``; a ``.csv`` counts only with a joint-positions header (so a session's
    ``heart_rate.csv`` is not offered)."""
    root = Path(folder)
    if not root.is_dir():
        return []
    found = sorted(p for ext in MOTION_SUFFIXES for p in root.rglob(f"*{ext}")
                   if p.is_file() and (p.suffix != ".csv" or is_positions_csv(p)))
    return found[:limit]


def stick_pairs(parents: Any) -> np.ndarray:
    """(K, 2) joint index pairs, one per bone (joint, parent), for drawing the skeleton."""
    parents = np.asarray(parents, dtype=int)
    child = np.flatnonzero(parents >= 0)
    return np.column_stack([child, parents[child]])


def view_axes(motion: Motion) -> dict[str, np.ndarray]:
    """Horizontal unit vectors (2,) of the ``front`` and ``side`` views of a Z-up skeleton.

    The front view looks at the body's left-right axis: the mean of joints named ``left...`` minus
    the mean of joints named ``right...`` (any case), over the clip; x if the names say nothing.
    """
    names = [n.lower() for n in motion.joint_names]
    left = [i for i, n in enumerate(names) if n.startswith("left")]
    right = [i for i, n in enumerate(names) if n.startswith("right")]
    lateral = np.array([1.0, 0.0])
    if left and right:
        pos = motion.positions_m[:, :, :2]
        d = (pos[:, left].mean(axis=1) - pos[:, right].mean(axis=1)).mean(axis=0)
        if np.linalg.norm(d) > 1e-6:
            lateral = d / np.linalg.norm(d)
    return {"front": lateral, "side": np.array([-lateral[1], lateral[0]])}


class SynthSession:
    """A motion clip played through a face model for one character.

    Parameters
    ----------
    model : str, path or FaceModel
        ``"default"`` (the built-in rule model) or a bundle folder.
    character : Character, optional
        Who moves (default: :class:`effortface.synth.runtime.Character` defaults).
    background : bool
        Recompute curves in background jobs (the GUI: a 2-minute clip through an SVR bundle takes
        about 0.1 s); :meth:`poll` then applies the newest result. False computes at once.

    Notes
    -----
    Emitters (:class:`~effortface.core.events.Emitter`): ``model_changed()``,
    ``motion_changed()``, ``curves_changed()``, ``character_changed()``, ``position_changed(frame)``,
    ``playing_changed(playing)``, ``status_changed(text, is_error)``.
    """

    def __init__(self, model: str | os.PathLike | FaceModel = "default",
                 character: Character | None = None, *, background: bool = False) -> None:
        self.model = model if isinstance(model, FaceModel) else load_model(model)
        self.character = self._fit_character(character or Character())
        self.motion: Motion | None = None
        self.motion_path: Path | None = None
        self.loops = 1
        #: a user joint-to-segment mapping (``--mapping``), or None for the built-in conventions
        self.mapping: dict | None = None
        self.mapping_path: Path | None = None
        #: how clips are read: ``--unit-m``, ``--up``, ``--trust-skeleton`` (None: from the file)
        self.read = MotionReadOptions()
        #: how the clip was read and the body the plausibility gate measured (``.units.json``'s "reading")
        self.reading: dict[str, Any] = {}
        self.curves: dict[str, np.ndarray] = {}
        self.position_s = 0.0
        self.playing = False
        self._work_cache: tuple[Motion, tuple, EnergyCurves] | None = None
        self.jobs = Jobs(workers=1, name="synth-curves") if background else None
        self._generation = 0
        self.model_changed, self.motion_changed = Emitter(), Emitter()
        self.curves_changed, self.character_changed = Emitter(), Emitter()
        self.position_changed, self.playing_changed = Emitter(), Emitter()
        self.status_changed = Emitter()

    # ---- inputs
    def _fit_character(self, character: Character) -> Character:
        """The character with one expressiveness value per blendshape of the model (1 if it differs)."""
        n = len(self.model.blendshapes)
        if len(character.expressiveness) != n:
            character = dataclasses.replace(character, expressiveness=(1.0,) * n)
        return character

    def load_model(self, path: str | os.PathLike | FaceModel) -> None:
        """Use a bundle folder, ``"default"`` or a loaded model (UserError keeps the old model)."""
        self.model = path if isinstance(path, FaceModel) else load_model(path)
        self.character = self._fit_character(self.character)
        self.model_changed.emit()
        self.character_changed.emit()
        self._recompute()
        self.status_changed.emit(f"model: {self.model.name}", False)

    def load_motion(self, path: str | os.PathLike | Motion) -> None:
        """Read a clip (``.bvh`` / ``.npz``) or take a Motion; the play head goes to 0.

        The repeat count goes back to 1: a count chosen for one clip would silently stretch the
        next (40 repeats of a 38 s clip are 1,520 s); the status line says so when it was above 1.
        A file is read with :attr:`read` (unit, up axis) and goes through the plausibility gate.

        Raises
        ------
        UserError
            An unreadable clip, or a body outside the human ranges without ``trust_skeleton``
            (one line naming the file and the figure; the old clip is kept).
        """
        if isinstance(path, Motion):
            motion, self.reading = path, reading_record(path)
        else:  # the gate, not the mapping: an unmapped clip loads, to be mapped with Mapping...
            motion = read_motion(Path(path), unit_m=self.read.unit_m, up=self.read.up)
            body = check_plausible(motion, trust=self.read.trust_skeleton, mapping=self.mapping, name=str(path))
            self.reading = reading_record(motion, body)
        old_loops = self.loops
        self.motion = motion
        self.motion_path = None if isinstance(path, Motion) else Path(path)
        self.position_s = 0.0
        self.loops = 1
        self.motion_changed.emit()
        self._recompute()
        reset = f"; repeat reset from {old_loops} x to 1 x" if old_loops != 1 else ""
        self.status_changed.emit(f"clip: {self.motion_path or 'motion'}: {motion.n_frames} frames "
                                 f"at {motion.fps:g} Hz ({motion.n_frames / motion.fps:.1f} s){reset}",
                                 False)

    def set_reading(self, *, unit_m: float | None = None, up: str | None = None,
                    trust_skeleton: bool = False) -> None:
        """Read clips with this unit and up axis (None: from the file), and ``trust_skeleton`` past the
        plausibility gate; the loaded clip is read again with them.

        Raises
        ------
        UserError
            A bad unit or axis, or the clip refused with them (the old options and clip are kept).
        """
        old = self.read
        self.read = MotionReadOptions(unit_m=check_unit_m(unit_m, "unit"), up=check_up(up, "up axis"),
                                      trust_skeleton=bool(trust_skeleton))
        if self.motion_path is not None:
            try:
                self.load_motion(self.motion_path)
            except UserError:
                self.read = old
                raise

    def set_mapping(self, path: str | os.PathLike | None) -> None:
        """Use a joint-to-segment mapping file for the clips (None: the built-in conventions).

        Raises
        ------
        UserError
            A file that is not a mapping, or one that does not map the loaded clip's joints
            (the old mapping is kept).
        """
        from effortface.synth.segments import build_body, read_mapping

        file = None if path is None else Path(path)
        mapping = None if file is None else read_mapping(file)
        if file is not None and self.motion is not None:
            build_body(self.motion.joint_names, self.motion.parents, self.character.mass_kg, self.character.sex,
                       mapping=file, source=self.motion_path or self.motion.source)
        if self.motion is not None and self.motion_path is not None:  # the segments it maps, through the gate
            body = check_plausible(self.motion, trust=self.read.trust_skeleton, mapping=mapping,
                                   name=str(self.motion_path))
            self.reading = reading_record(self.motion, body)
        self.mapping, self.mapping_path = mapping, None if path is None else Path(path)
        self._work_cache = None
        self._recompute()
        self.status_changed.emit(f"mapping: {self.mapping_path or 'built-in conventions'}", False)

    def set_character(self, **changes: Any) -> None:
        """Change character fields (validated: a bad value raises UserError, nothing changes)."""
        self.character = dataclasses.replace(self.character, **changes)
        self.character_changed.emit()
        self._recompute()

    def set_expressiveness(self, index: int, value: float) -> None:
        """Change one blendshape's expressiveness (0 = none, 1 = as trained, > 1 exaggerated)."""
        e = list(self.character.expressiveness)
        e[index] = value
        self.set_character(expressiveness=tuple(e))

    def set_loops(self, loops: int) -> None:
        """Repeat the clip ``loops`` times end to end (1 to :data:`MAX_LOOPS`)."""
        if not isinstance(loops, (int, np.integer)) or not 1 <= loops <= MAX_LOOPS:
            raise UserError(f"loops: expected a whole number from 1 to {MAX_LOOPS}, found {loops!r}")
        self.loops = int(loops)
        self._recompute()

    # ---- curves
    def _work(self, model: FaceModel, motion: Motion, c: Character, mapping: dict | None = None) -> EnergyCurves:
        """Work and power of one pass of the clip, cached on what they depend on."""
        key = (c.mass_kg, c.sex, c.load_left_kg, c.load_right_kg, c.load_back_kg, id(mapping))
        cache = self._work_cache
        if cache is None or cache[0] is not motion or cache[1] != key:
            energy = work_and_power(motion, model.body(c, motion, mapping), zero_phase=True)
            cache = self._work_cache = (motion, key, energy)
        return cache[2]

    def _curves(self, model: FaceModel, motion: Motion, character: Character, loops: int,
                mapping: dict | None = None) -> dict[str, np.ndarray]:
        """Whole-clip curves (runs on the worker thread in background mode)."""
        e = looped(self._work(model, motion, character, mapping), loops, motion.fps)
        return model.curves_from_work(e.t_s, e.w_per_kg, e.p_per_kg, 1.0 / motion.fps, character)

    def _recompute(self) -> None:
        """Curves for the current model, character and loops (now, or on the worker); the play head stays."""
        if self.motion is None:
            return
        self._generation += 1
        args = (self.model, self.motion, self.character, self.loops, self.mapping)
        if self.jobs is None:
            self._apply(self._curves(*args))
        else:
            generation = self._generation
            self.jobs.submit("curves", self._curves, *args,
                             done=lambda result: self._curves_done(generation, result))

    def _curves_done(self, generation: int, result: JobResult) -> None:
        """Apply a background recompute if it is the newest (older ones are dropped); report an error."""
        if result.error is not None:
            self.status_changed.emit(f"curves not updated: {result.error}", True)
        elif generation == self._generation:
            self._apply(result.value)

    def _apply(self, curves: dict[str, np.ndarray]) -> None:
        self.curves = curves
        self.position_s = min(self.position_s, self.duration_s)
        self.curves_changed.emit()
        self.position_changed.emit(self.frame)

    @property
    def busy(self) -> bool:
        """True while curves are being recomputed in the background."""
        return self.jobs is not None and self.jobs.busy()

    def poll(self) -> None:
        """Apply the newest finished recompute (call on the GUI thread); older ones are dropped.

        An error raised by a background recompute is reported through ``status_changed``.
        """
        if self.jobs is not None:
            self.jobs.drain()

    def wait(self, timeout_s: float | None = None, *, apply: bool = True) -> None:
        """Block until background recomputes finish, then :meth:`poll` unless ``apply`` is False."""
        if self.jobs is not None:
            self.jobs.wait(timeout_s)
        if apply:
            self.poll()

    def shutdown(self) -> None:
        """Stop the background jobs (pending recomputes are dropped)."""
        if self.jobs is not None:
            self.jobs.shutdown()

    # ---- play head
    @property
    def n_frames(self) -> int:
        """Frames of the (looped) clip."""
        return len(self.curves.get("t_s", ()))

    @property
    def duration_s(self) -> float:
        """Time of the last frame, seconds."""
        return float(self.curves["t_s"][-1]) if self.n_frames else 0.0

    @property
    def frame(self) -> int:
        """Index of the frame at the play head."""
        if not self.n_frames or self.motion is None:
            return 0
        return int(min(round(self.position_s * self.motion.fps), self.n_frames - 1))

    def seek(self, t_s: float) -> None:
        """Move the play head to ``t_s`` (clamped to the clip)."""
        self.position_s = float(np.clip(t_s, 0.0, self.duration_s))
        self.position_changed.emit(self.frame)

    def play(self, playing: bool = True) -> None:
        """Start or pause playback (a clip must be loaded)."""
        if playing and self.motion is None:
            raise UserError("play: expected a motion clip, found none (load a .bvh or .npz first)")
        self.playing = bool(playing)
        self.playing_changed.emit(self.playing)

    def advance(self, dt_s: float) -> None:
        """Move the play head on by ``dt_s`` of wall time when playing (wraps at the end)."""
        if not self.playing or not self.n_frames or self.motion is None:
            return
        span = self.duration_s + 1.0 / self.motion.fps
        self.position_s = (self.position_s + dt_s) % span
        self.position_changed.emit(self.frame)

    def weights_at(self, frame: int | None = None) -> np.ndarray:
        """Blendshape weights (B,) at a frame (default: the play head)."""
        i = self.frame if frame is None else frame
        return np.array([self.curves[n][i] for n in self.model.blendshapes.names])

    def pose_at(self, frame: int | None = None) -> np.ndarray:
        """Joint positions (J, 3) in metres, Z up, at a frame of the looped clip."""
        assert self.motion is not None
        i = self.frame if frame is None else frame
        return self.motion.positions_m[i % self.motion.n_frames]

    # ---- export
    def default_export_path(self, fmt: str = "csv") -> Path:
        """A file name for :meth:`export`: ``<clip>_<model>_curves.csv`` (``_livelink.csv``).

        In the clip's folder (the working folder for a clip given in memory); the model part is the
        bundle folder's name or ``rule`` for the built-in model.
        """
        clip = self.motion_path.stem if self.motion_path is not None else "motion"
        model = Path(self.model.name).name if Path(self.model.name).is_dir() else "rule"
        folder = self.motion_path.parent if self.motion_path is not None else Path.cwd()
        suffix = "livelink" if fmt == "livelink" else "curves"
        return folder / f"{clip}_{model or 'model'}_{suffix}.csv"

    def export(self, path: str | os.PathLike, fmt: str = "csv", *, overwrite: bool = False) -> Path:
        """Write the curves as the per-frame CSV or a Live Link Face CSV (:func:`write_curves`, as synth).

        Raises
        ------
        FileExistsError
            If ``path`` exists and ``overwrite`` is False.
        UserError
            For an unknown format, no clip, or a missing folder.
        """
        if fmt not in EXPORT_FORMATS:
            raise UserError(f"format: expected one of {', '.join(EXPORT_FORMATS)}, found {fmt!r}")
        if not self.n_frames:
            raise UserError("export: expected curves, found none (load a motion clip first)")
        out = refuse_overwrite(path, overwrite=overwrite)
        write_curves(out, self.curves, self.model, fmt=fmt, force=True, reading=self.reading)
        self.status_changed.emit(f"exported {self.n_frames} frames to {out}", False)
        return out
