"""The Annotate stage's model: one rater keying one session (Qt-free).

It holds what the Annotate stage's widgets show and edit: the current frame, the current blendshape
(the paper's protocol: one blendshape at a time, always in the set's order, the next one offered
after a pass over the video), the rater's own key-frame tracks (never another rater's: a rater keys
blind), the clipboard and an undo/redo history of whole-annotation snapshots, each named ("set
mouth_open key at frame 120 to 0.40") with the blendshape and frame it changed: undo and redo go
to that blendshape and frame and say what they did. Every edit is saved at
once with an atomic write (:meth:`RaterAnnotations.save`: temp file + rename), so a crash or a
``kill -9`` loses no key that was set.

:class:`AnnotateSession` follows the stage-model convention of :mod:`effortface.core`: one
:class:`~effortface.core.events.Emitter` per thing that changes (``frame_changed``,
``blendshape_changed``, ``keys_changed``, ``file_changed`` when the file is saved, ``passes_changed``
when a pass over the video is done, ``history_changed`` when the undo or redo list changes (a menu
binds its Undo/Redo items to :attr:`can_undo`, :attr:`undo_text`... there), ``status_changed(text,
is_error)`` for what an edit, undo or redo did); widgets connect to them in ``__init__`` and write back only
through the methods (the rule: a view writes back only through model methods and keeps widget state only).
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.annotate.completeness import TrackStatus, rater_status
from effortface.annotate.machine_guide import ACCEPT_TOLERANCE, KeyFit, MachineGuide, load_guide
from effortface.annotate.keyframes import INTERPOLATIONS, Keyframe, KeyframeTrack, RaterAnnotations, read_annotations
from effortface.annotate.video_index import FrameTimes
from effortface.core.errors import UserError
from effortface.core.events import Emitter
from effortface.core.fileio import atomic_write_together
from effortface.core.locks import FileLock, LockedError, acquire_lock, describe_owner, lock_owner
from effortface.core.session.folder import Session, check_not_recording, read_session

if TYPE_CHECKING:
    from effortface.annotate.reliability import Correction, Rating

ANNOTATIONS_DIR = "annotations"
_RATER_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,31}")
#: snapshots kept for undo
UNDO_LIMIT = 500


@dataclasses.dataclass(frozen=True)
class UndoStep:
    """One entry of the undo (or redo) list: the annotations before the edit and what the edit did."""

    before: RaterAnnotations
    label: str
    blendshape: str
    frame: int


def check_rater(rater: str) -> str:
    """Return ``rater`` if it is a valid rater code (it names a file), else raise UserError."""
    if not isinstance(rater, str) or not _RATER_RE.fullmatch(rater):
        raise UserError(f"rater: expected a code of 1-32 letters, digits, '_' or '-' (e.g. R1), found {rater!r}")
    return rater


def annotation_path(session_folder: str | os.PathLike, rater: str) -> Path:
    """``<session>/annotations/<rater>.json``."""
    return Path(session_folder) / ANNOTATIONS_DIR / f"{check_rater(rater)}.json"


class RaterBusyError(UserError):
    """The rater file is open in another Annotate (window or program); the message names its owner."""


def lock_rater_file(path: Path) -> FileLock:
    """Take ``.<rater>.lock`` beside the rater file ``path``: one writer of a rater's keys at a time.

    Parameters
    ----------
    path : Path
        ``<session>/annotations/<rater>.json`` (its folder is created if needed).

    Returns
    -------
    FileLock
        Hold it while keys may be saved; :meth:`FileLock.release` frees it.

    Raises
    ------
    RaterBusyError
        Another Annotate holds it: two writers would overwrite each other's keys.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return acquire_lock(path.parent / f".{path.stem}.lock", "annotate")
    except LockedError:
        owner = lock_owner(path.parent / f".{path.stem}.lock") or {}
        raise RaterBusyError(f"{path}: expected rater {path.stem} free on this session, found it open in another "
                             f"Annotate ({describe_owner(owner)}); close that one first") from None
    except OSError as exc:
        raise UserError(f"{path.parent}: expected a writable annotations folder, found {exc.strerror or exc}") from None


class AnnotateSession:
    """One rater's key-framing of one session (the Annotate stage's model).

    Parameters
    ----------
    session_folder : path-like
        A session with video (``video_frames.csv``).
    rater : str
        Rater code; the file is ``annotations/<rater>.json`` (loaded if it exists).
    blendshapes : BlendshapeSet
        Used for a new file; an existing file keeps its own set.
    autosave : bool
        Save after every edit (the default; False for tests of the pure logic).

    Raises
    ------
    UserError
        If the session has no video frames, the rater code is invalid, or the file is malformed
        or belongs to another session or rater; a LockedError if a capture is recording the session now.
    RaterBusyError
        If another window or program has the same session open for the same rater (the message
        names it: pid, host, since when). Its lock is held until :meth:`close`; the kernel frees it
        if the holder dies, so a killed Annotate blocks nothing.

    Notes
    -----
    Emitters: ``frame_changed(frame)``, ``blendshape_changed(name)``, ``keys_changed(name)``,
    ``file_changed(path)`` (saved), ``passes_changed(name)`` (a pass over the video is done),
    ``history_changed()`` (undo/redo lists), ``status_changed(text, is_error)``.
    """

    def __init__(self, session_folder: str | os.PathLike, rater: str, *,
                 blendshapes: BlendshapeSet = DEFAULT_SET, autosave: bool = True) -> None:
        check_not_recording(session_folder, "annotate")
        self.session: Session = read_session(session_folder)
        if not self.session.frame_times_s:
            raise UserError(f"{self.session.path}: expected a session with video_frames.csv, found no video frames")
        self.times = FrameTimes(self.session.frame_times_s)
        self.path = annotation_path(self.session.path, rater)
        self._lock: FileLock | None = lock_rater_file(self.path)
        try:
            self._file_is_ours = self.path.exists()  # a new file is created once, never over another's
            self.annotations = (read_annotations(self.path, session_id=self.session.info.session_id, rater=rater)
                                if self._file_is_ours
                                else RaterAnnotations(rater, self.session.info.session_id, blendshapes))
        except BaseException:
            self.close()
            raise
        self.autosave = autosave
        self.frame = 0
        self.blendshape = self.annotations.blendshapes.names[0]
        self.interp = "linear"
        if self.annotations.passes_done is None:  # a file from before passes were recorded:
            self.annotations.passes_done = {  # a track its rule judged complete keeps counting
                n for n, st in rater_status(self.annotations, self.session.frame_times_s).items() if st.complete}
        self._undo: list[UndoStep] = []
        self._redo: list[UndoStep] = []
        self._clipboard: list[tuple[int, Keyframe]] = []  # (frame offset, key): a pasted key keeps its origin
        self.frame_changed, self.blendshape_changed = Emitter(), Emitter()
        self.keys_changed, self.file_changed, self.passes_changed = Emitter(), Emitter(), Emitter()
        self.history_changed, self.status_changed = Emitter(), Emitter()

    def disconnect_all(self) -> None:
        """Forget every connected function (a view that goes away)."""
        for emitter in (self.frame_changed, self.blendshape_changed, self.keys_changed,
                        self.file_changed, self.passes_changed, self.history_changed, self.status_changed):
            emitter.disconnect_all()

    @property
    def passes_done(self) -> set[str]:
        """Blendshapes whose pass over the video is finished (saved in the file)."""
        assert self.annotations.passes_done is not None  # set in __init__, kept by undo/redo
        return self.annotations.passes_done

    # ------------------------------------------------------------------------------ navigation
    @property
    def rater(self) -> str:
        """The rater code."""
        return self.annotations.rater

    @property
    def n_frames(self) -> int:
        """Frames in the session video."""
        return len(self.times)

    @property
    def t_s(self) -> float:
        """Session time of the current frame."""
        return self.times.t_at(self.frame)

    def set_frame(self, frame: int) -> None:
        """Go to ``frame`` (clamped to the video); a pass is done on reaching the last frame."""
        frame = self.times.clamp(frame)
        if frame == self.frame:
            return
        self.frame = frame
        self.frame_changed.emit(frame)
        if frame == self.n_frames - 1 and len(self.track) and self.blendshape not in self.passes_done:
            self.passes_done.add(self.blendshape)
            if self.autosave and self._file_is_ours:
                self.save()  # the pass is part of the file (completeness); a new file waits for a key
            self.passes_changed.emit(self.blendshape)

    def step(self, n_frames: int) -> None:
        """Move by ``n_frames`` (negative: back)."""
        self.set_frame(self.frame + int(n_frames))

    def go_to_time(self, t_s: float) -> None:
        """Go to the frame on screen at session time ``t_s``."""
        self.set_frame(self.times.frame_at(t_s))

    # -------------------------------------------------------------------------- the protocol
    @property
    def blendshape_names(self) -> tuple[str, ...]:
        """Blendshapes in the fixed annotation order."""
        return self.annotations.blendshapes.names

    @property
    def track(self) -> KeyframeTrack:
        """The current blendshape's track."""
        return self.annotations.tracks[self.blendshape]

    def set_blendshape(self, name: str) -> None:
        """Make ``name`` the blendshape being keyed (UserError if not in the set)."""
        self.annotations.blendshapes.index(name)
        if name != self.blendshape:
            self.blendshape = name
            self.blendshape_changed.emit(name)

    @property
    def next_blendshape(self) -> str | None:
        """The blendshape after the current one in the fixed order, None after the last."""
        names = self.blendshape_names
        i = names.index(self.blendshape)
        return names[i + 1] if i + 1 < len(names) else None

    def start_next_pass(self) -> str | None:
        """Move to the next blendshape and back to frame 0; return it (None if this was the last)."""
        nxt = self.next_blendshape
        if nxt is not None:
            self.set_blendshape(nxt)
            self.set_frame(0)
        return nxt

    def weight(self, frame: int | None = None, name: str | None = None) -> float:
        """Curve value of ``name`` (default current) at ``frame`` (default current); NaN if not keyed."""
        track = self.annotations.tracks[name or self.blendshape]
        return float(track.evaluate(self.frame if frame is None else frame))

    def weights(self, frame: int | None = None) -> dict[str, float]:
        """All blendshape weights at ``frame`` (NaN where a track has no key)."""
        return {n: self.weight(frame, n) for n in self.blendshape_names}

    def key_at(self, frame: int | None = None) -> Keyframe | None:
        """The current track's key on ``frame`` (default current), or None."""
        return self.track.get(self.frame if frame is None else frame)

    # ------------------------------------------------------------------------------- editing
    def _edit(self, change: Callable[[], Any], label: str, frame: int | None = None) -> Any:
        """Snapshot for undo, apply ``change``, save, notify; restore the snapshot if either raises.

        So the keys shown are always the keys on disk: an edit that cannot be saved is undone.
        ``label`` says what the edit does (the undo list shows it); ``frame`` is where it happened.
        """
        before = self.annotations.copy()
        try:
            result = change()
            if self.autosave:
                self.save()
        except BaseException:
            self.annotations = before
            raise
        self._undo.append(UndoStep(before, label, self.blendshape, self.frame if frame is None else int(frame)))
        del self._undo[:-UNDO_LIMIT]
        self._redo.clear()
        self.keys_changed.emit(self.blendshape)
        self.history_changed.emit()
        self.status_changed.emit(label, False)
        return result

    def _swap(self, source: list[UndoStep], target: list[UndoStep], verb: str) -> str | None:
        """Undo / redo: restore the top of ``source``, push the current state on ``target``.

        Goes to the step's blendshape and frame first (so the change is on screen) and says what it
        did through ``status_changed``; returns that text, None if ``source`` was empty.
        """
        if not source:
            self.status_changed.emit(f"nothing to {verb}", True)
            return None
        step = source[-1]
        current, self.annotations = self.annotations, step.before
        self.annotations.passes_done = current.passes_done  # passes are not edits: undo keeps them
        try:
            if self.autosave:
                self.save()
        except BaseException:
            self.annotations = current
            raise
        source.pop()
        target.append(UndoStep(current, step.label, step.blendshape, step.frame))
        self.set_blendshape(step.blendshape)
        self.set_frame(step.frame)
        text = f"{verb}: {step.label}"
        self.keys_changed.emit(self.blendshape)
        self.history_changed.emit()
        self.status_changed.emit(text, False)
        return text

    def set_key(self, weight: float, frame: int | None = None, interp: str | None = None) -> Keyframe:
        """Key the current blendshape at ``frame`` (default current) with ``weight`` in [0, 1].

        ``interp`` defaults to the key already there, else :attr:`interp`. Raises UserError for a
        weight outside [0, 1] or an unknown interpolation.
        """
        frame = self.times.check(self.frame if frame is None else frame)
        old = self.track.get(frame)
        interp = interp or (old.interp if old else self.interp)
        w = round(float(weight), 4)
        label = (f"set {self.blendshape} key at frame {frame} to {w:.2f}" if old is None
                 else f"change {self.blendshape} key at frame {frame} from {old.weight:.2f} to {w:.2f}")
        key = old.edited(weight=w, interp=interp) if old is not None else Keyframe(frame, w, interp)
        return self._edit(lambda: self.track.put(key), label, frame)

    def delete_key(self, frame: int | None = None) -> Keyframe | None:
        """Remove the current track's key on ``frame`` (default current); None if there was none."""
        frame = self.frame if frame is None else int(frame)
        old = self.track.get(frame)
        if old is None:
            return None
        return self._edit(lambda: self.track.delete(frame),
                          f"delete {self.blendshape} key at frame {frame} ({old.weight:.2f})", frame)

    def move_key(self, frame: int, new_frame: int, weight: float | None = None) -> Keyframe:
        """Move the current track's key on ``frame`` to ``new_frame`` (clamped), optionally re-weighted.

        Raises KeyError if there is no key on ``frame``, ValueError if ``new_frame`` is keyed.
        """
        new_frame = self.times.clamp(new_frame)
        if weight is not None:
            weight = round(min(max(float(weight), 0.0), 1.0), 4)
        return self._edit(lambda: self.track.move(frame, new_frame, weight),
                          f"move {self.blendshape} key from frame {frame} to {new_frame}", new_frame)

    def set_interp(self, interp: str, frame: int | None = None) -> None:
        """Set the default interpolation, and that of the key on ``frame`` (default current) if any."""
        if interp not in INTERPOLATIONS:
            raise UserError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, found {interp!r}")
        self.interp = interp
        key = self.key_at(frame)
        if key is not None and key.interp != interp:
            self._edit(lambda: self.track.put(key.edited(interp=interp)),
                       f"set {self.blendshape} key at frame {key.frame} to {interp}", key.frame)

    # ----------------------------------------------------------------------- copy and paste
    def copy(self, first: int | None = None, last: int | None = None) -> int:
        """Copy the current track's keys in ``first .. last`` (default: the current frame); return how many."""
        first = self.frame if first is None else int(first)
        last = first if last is None else int(last)
        keys = [k for k in self.track.keys if first <= k.frame <= last]
        self._clipboard = [(k.frame - first, k) for k in keys]
        return len(keys)

    def paste(self, frame: int | None = None) -> int:
        """Paste the copied keys into the current track from ``frame`` (default current); one undo step."""
        at = self.frame if frame is None else int(frame)
        keys = [dataclasses.replace(k, frame=at + off) for off, k in self._clipboard if 0 <= at + off < self.n_frames]
        if keys:
            self._edit(lambda: [self.track.put(k) for k in keys],
                       f"paste {len(keys)} {self.blendshape} key{'s' * (len(keys) != 1)} at frame {at}", at)
        return len(keys)

    # ---------------------------------------------------------------------------------- undo
    @property
    def can_undo(self) -> bool:
        """Whether there is an edit to undo."""
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        """Whether there is an undone edit to redo."""
        return bool(self._redo)

    @property
    def undo_text(self) -> str:
        """What Undo would undo (``""`` when nothing)."""
        return self._undo[-1].label if self._undo else ""

    @property
    def redo_text(self) -> str:
        """What Redo would redo (``""`` when nothing)."""
        return self._redo[-1].label if self._redo else ""

    @property
    def history(self) -> tuple[list[str], list[str]]:
        """The undo list (oldest first) and the redo list (next redo first), as labels."""
        return [s.label for s in self._undo], [s.label for s in reversed(self._redo)]

    def undo(self) -> str | None:
        """Undo the last edit (and save), going to its blendshape and frame; return what was undone.

        None (and a ``status_changed`` error) when there was nothing to undo.
        """
        return self._swap(self._undo, self._redo, "undid")

    def redo(self) -> str | None:
        """Redo the last undone edit (and save), going to its blendshape and frame; None if none."""
        return self._swap(self._redo, self._undo, "redid")

    def undo_to(self, n_steps: int) -> int:
        """Undo (``n_steps`` > 0) or redo (< 0) that many steps (the history view's click); return how many."""
        step, count = (self.undo, n_steps) if n_steps > 0 else (self.redo, -n_steps)
        return sum(step() is not None for _ in range(count))

    # ------------------------------------------------------------------------------- selections
    def shift_keys(self, frames: list[int], d_frames: int = 0, d_weight: float = 0.0,
                   scale: float = 1.0) -> list[int]:
        """Move several keys of the current track at once (one undo step); return their new frames.

        Each key goes ``d_frames`` frames on, and its weight becomes
        ``pivot + scale * (weight - pivot) + d_weight`` clipped to [0, 1], where ``pivot`` is the
        keys' mean weight (so ``scale`` stretches or flattens the selection about its middle).

        Raises
        ------
        KeyError
            If a frame has no key.
        UserError
            If a key would land on a keyed frame outside the selection, or two on one frame, or a key
            would leave the video (a move that cannot move every key moves none, and says why).
        """
        keys = [self.track.get(f) for f in frames]
        if any(k is None for k in keys):
            raise KeyError(f"no {self.blendshape} key on frame {frames[[k is None for k in keys].index(True)]}")
        chosen = [k for k in keys if k is not None]
        if not chosen:
            return []
        last = self.n_frames - 1
        stuck = [k.frame for k in chosen if not 0 <= k.frame + int(d_frames) <= last]
        if stuck:  # moving the others alone would change the selection's shape: refuse, nothing moves
            edge = "first frame (0)" if int(d_frames) < 0 else f"last frame ({last})"
            raise UserError(f"move keys: expected every selected key to move by {int(d_frames):+d} frames, found "
                            f"key{'s' * (len(stuck) != 1)} {', '.join(map(str, stuck))} within "
                            f"{abs(int(d_frames))} frame{'s' * (abs(int(d_frames)) != 1)} of the {edge}: "
                            f"nothing moved")
        pivot = sum(k.weight for k in chosen) / len(chosen)
        moved = [k.edited(frame=self.times.clamp(k.frame + int(d_frames)),
                          weight=round(min(max(pivot + scale * (k.weight - pivot) + d_weight, 0.0), 1.0), 4))
                 for k in chosen]
        targets = [k.frame for k in moved]
        others = {k.frame for k in self.track.keys} - {k.frame for k in chosen}
        if len(set(targets)) < len(targets) or others & set(targets):
            raise UserError(f"move keys: expected free frames, found a {self.blendshape} key in the way")

        def change() -> None:
            for k in chosen:
                self.track.delete(k.frame)
            for k in moved:
                self.track.put(k)
        self._edit(change, f"move {len(chosen)} {self.blendshape} key{'s' * (len(chosen) != 1)}"
                   + (f" by {d_frames:+d} frames" if d_frames else "")
                   + (f" by {d_weight:+.2f}" if d_weight else "")
                   + (f", weights x{scale:g}" if scale != 1.0 else ""), targets[0])
        return targets

    # ------------------------------------------------------------------------- the machine
    @property
    def machine(self) -> MachineGuide | None:
        """The session's machine track on its frames (``machine/face_landmarker.csv``), None without one;
        read on first use and again after :meth:`reload_machine`."""
        if not hasattr(self, "_machine"):
            self._machine = load_guide(self.session.path, self.n_frames)
        return self._machine

    def reload_machine(self) -> MachineGuide | None:
        """Read the machine track again (after a Pre-annotate run)."""
        self.__dict__.pop("_machine", None)
        return self.machine

    def accept_machine(self, first: int, last: int, tolerance: float = ACCEPT_TOLERANCE) -> KeyFit:
        """Replace the current track's keys on ``first..last`` by sparse keys following the machine curve.

        The keys (:func:`~effortface.annotate.machine_guide.fit_keys`: running median, then at most one
        key per 3 s, more where the curve moves, until within ``tolerance``) are marked as the machine's,
        accepted by this rater, until the rater edits one; frames without a face get none. One undo step.

        Returns
        -------
        KeyFit
            The keys set, the budget and the error to the smoothed curve.

        Raises
        ------
        UserError
            If the session has no machine track, the blendshape is not one the machine rates, the
            tolerance is outside [0, 1], or the range holds no frame with a face.
        """
        guide = self.machine
        if guide is None:
            raise UserError(f"{self.session.path / 'machine'}: expected a machine track (Pre-annotate), found none")
        if not 0.0 <= tolerance <= 1.0:
            raise UserError(f"accept tolerance: expected a weight from 0 to 1, found {tolerance}")
        first, last = sorted((self.times.clamp(first), self.times.clamp(last)))
        fit = guide.keys(self.blendshape, first, last, self.session.frame_times_s, tolerance)
        if fit is None:
            raise UserError(f"accept machine: expected a blendshape the machine rates, found {self.blendshape!r}")
        if not fit.keys:
            raise UserError(f"accept machine: expected frames with a face in {first}..{last}, found none")
        old = [k.frame for k in self.track.keys if first <= k.frame <= last]

        def change() -> None:
            for f in old:
                self.track.delete(f)
            for f, w in fit.keys:
                self.track.add(f, w, "linear", "machine", self.rater)
        n = len(fit.keys)
        self._edit(change, f"accept machine {self.blendshape} on frames {first}-{last}: {n} key{'s' * (n != 1)} "
                   f"(at most {fit.budget}), RMS {fit.rms:.3f} to the smoothed curve", fit.keys[0][0])
        return fit

    def completeness(self) -> dict[str, TrackStatus]:
        """This rater's completeness per blendshape (:mod:`effortface.annotate.completeness`)."""
        return rater_status(self.annotations, self.session.frame_times_s)

    # ---------------------------------------------------------------------------------- files
    def close(self) -> None:
        """Release the rater file's lock (idempotent); the keys are already on disk."""
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def __del__(self) -> None:
        """A model dropped without :meth:`close` releases its lock too."""
        lock = getattr(self, "_lock", None)
        if lock is not None:
            lock.release()

    def save(self) -> Path:
        """Write ``annotations/<rater>.json`` atomically.

        Raises
        ------
        FileExistsError
            If this session started without a file and one has appeared since (another program or
            window): it is never silently overwritten.
        UserError
            If the disk refuses the write (full, read-only...): the message names the file and the
            cause, and the edit being saved is undone by :meth:`_edit` (the file keeps the last keys).
        """
        try:
            path = self.annotations.save(self.path, overwrite=self._file_is_ours)
        except OSError as exc:
            if isinstance(exc, FileExistsError):
                raise
            raise UserError(f"{self.path}: expected to save the keys, found the write refused "
                            f"({exc.strerror or exc}); the last edit was undone, the file keeps the "
                            "keys before it") from None
        self._file_is_ours = True
        self.file_changed.emit(path)
        return path


class BlindRound:
    """One rater's blind ratings of the reliability pose set of a lab folder (Qt-free).

    The rater sees only their own ratings; they are saved atomically to
    ``reliability/ratings_<rater>.csv`` after every change. Ratings the lab already holds for this
    rater in ``reliability/ratings.csv`` count as done and cannot be changed here, and once the rater
    has rated every pose (the agreement report is then shown to them) all their ratings are locked:
    nobody revises a rating after seeing the others'.

    Parameters
    ----------
    lab_dir : path-like
        Folder of sessions with ``reliability/poses.csv``.
    rater : str
        Rater code.
    blendshapes : BlendshapeSet
        What is rated, in order.

    Raises
    ------
    UserError
        If the folder has no ``reliability/poses.csv`` or a file is malformed.
    """

    def __init__(self, lab_dir: str | os.PathLike, rater: str, blendshapes: BlendshapeSet = DEFAULT_SET) -> None:
        from effortface.annotate.agreement import frames_by_session
        from effortface.core.session.folder import list_sessions
        from effortface.annotate.reliability import read_poses, read_ratings

        self.lab_dir = Path(lab_dir)
        self.rater = check_rater(rater)
        self.blendshapes = blendshapes
        rel = self.lab_dir / "reliability"
        if not (rel / "poses.csv").is_file():
            raise UserError(f"{rel / 'poses.csv'}: expected the reliability pose set, found nothing "
                            "(propose one from HR and phase extremes first)")
        self.poses = read_poses(rel / "poses.csv", frames_by_session(list_sessions(self.lab_dir)))
        self.path = rel / f"ratings_{rater}.csv"
        lab_file = rel / "ratings.csv"
        self.locked = {(r.pose_id, r.blendshape): r.weight for r in
                       (read_ratings(lab_file, blendshapes) if lab_file.is_file() else []) if r.rater == rater}
        mine = read_ratings(self.path, blendshapes) if self.path.is_file() else []
        self.ratings = dict(self.locked) | {(r.pose_id, r.blendshape): r.weight for r in mine}

    def rating(self, pose_id: str, name: str) -> float | None:
        """This rater's weight for a pose and blendshape, None if not rated yet."""
        return self.ratings.get((pose_id, name))

    def is_done(self, pose_id: str) -> bool:
        """Whether every blendshape of the pose is rated."""
        return all((pose_id, n) in self.ratings for n in self.blendshapes.names)

    @property
    def complete(self) -> bool:
        """Whether the rater has rated every pose (the report is shown only then: blind round)."""
        return all(self.is_done(p.pose_id) for p in self.poses)

    def set_rating(self, pose_id: str, name: str, weight: float | None) -> None:
        """Rate one blendshape of one pose and save.

        Raises
        ------
        UserError
            For an unknown pose or blendshape, a weight outside [0, 1], a rating the lab file
            already holds, or a finished round (the rater has seen the report).
        """
        if pose_id not in {p.pose_id for p in self.poses}:
            raise UserError(f"pose: expected one of the pose set, found {pose_id!r}")
        self.blendshapes.index(name)
        if weight is None or isinstance(weight, bool):
            raise UserError(f"{pose_id} {name}: unrated is not a rating: type a weight in [0, 1]")
        if not 0.0 <= float(weight) <= 1.0:
            raise UserError(f"weight: expected a number in [0, 1], found {weight!r}")
        if (pose_id, name) in self.locked:
            raise UserError(f"{pose_id} {name}: already rated by {self.rater} in reliability/ratings.csv")
        if self.complete:
            raise UserError(f"{pose_id} {name}: {self.rater} has finished the blind round and seen the "
                            "agreement report, so the ratings are locked")
        self.ratings[(pose_id, name)] = round(float(weight), 4)
        self._save()

    def _save(self) -> None:
        """Write this rater's own ratings atomically (temporary file, then replace)."""
        from effortface.annotate.reliability import write_ratings

        tmp = self.path.with_name(f".{self.path.name}.tmp")
        write_ratings(tmp, self._mine(self.ratings), overwrite=True)
        os.replace(tmp, self.path)

    def _mine(self, ratings: dict[tuple[str, str], float]) -> list[Rating]:
        """This rater's own ratings (not those the lab's file holds) as Rating rows."""
        from effortface.annotate.reliability import Rating

        return [Rating(p, self.rater, n, w) for (p, n), w in ratings.items() if (p, n) not in self.locked]

    @property
    def corrections_path(self) -> Path:
        """``reliability/corrections_<rater>.csv``: the log of corrections after the round."""
        return self.path.with_name(f"corrections_{self.rater}.csv")

    def correct_rating(self, pose_id: str, name: str, weight: float, reason: str,
                       when_utc: datetime.datetime | None = None) -> Correction:
        """Correct one rating of a finished round (a typo), logged with its reason.

        The change is appended to :attr:`corrections_path` (``time_utc,pose_id,blendshape,old,new,reason``)
        and the ratings file is then rewritten atomically; both files are replaced whole, never left
        half-written.

        Parameters
        ----------
        pose_id, name : str
            The pose and blendshape corrected.
        weight : float
            The corrected weight in [0, 1].
        reason : str
            Why (required; one line).
        when_utc : datetime, optional
            Time of the correction (default: now, UTC).

        Returns
        -------
        Correction
            The logged change.

        Raises
        ------
        UserError
            Before the round is finished (rate normally instead), for a rating the lab's ``ratings.csv``
            holds, an unknown pose or blendshape, a weight outside [0, 1], the same value, or no reason.
        """
        from effortface.annotate.reliability import Correction, corrections_text, read_corrections, ratings_text

        if pose_id not in {p.pose_id for p in self.poses}:
            raise UserError(f"pose: expected one of the pose set, found {pose_id!r}")
        self.blendshapes.index(name)
        if not self.complete:
            raise UserError(f"{pose_id} {name}: the blind round is not finished: change the rating directly "
                            "(corrections are for a finished round)")
        if (pose_id, name) in self.locked:
            raise UserError(f"{pose_id} {name}: rated by {self.rater} in reliability/ratings.csv, the lab's "
                            "file: ask the lab to correct it there")
        if weight is None or isinstance(weight, bool) or not 0.0 <= float(weight) <= 1.0:
            raise UserError(f"weight: expected a number in [0, 1], found {weight!r}")
        reason = " ".join(str(reason).split())
        if not reason:
            raise UserError(f"{pose_id} {name}: expected a reason for the correction (e.g. 'typo: 0.7 not 0.07'), "
                            "found none")
        old, new = self.ratings[(pose_id, name)], round(float(weight), 4)
        if abs(old - new) < 5e-5:
            raise UserError(f"{pose_id} {name}: expected a new value, found the same ({old:.2f})")
        when = when_utc or datetime.datetime.now(datetime.timezone.utc)
        change = Correction(when.astimezone(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                            pose_id, name, old, new, reason)
        ratings = dict(self.ratings) | {(pose_id, name): new}
        # the log and the ratings together, or neither: a correction is never logged but not applied
        atomic_write_together({self.corrections_path: corrections_text([*read_corrections(self.corrections_path),
                                                                         change]),
                               self.path: ratings_text(self._mine(ratings))})
        self.ratings = ratings
        return change
