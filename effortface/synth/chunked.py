"""A whole clip's curves in pieces of bounded memory: what ``effortface synth`` runs on one clip.

:meth:`effortface.synth.runtime.FaceModel.synthesize` holds the whole clip and every intermediate
array at once (about 63 MB per minute of 120 Hz motion). :func:`synthesize_chunks` gives the same
curves piece by piece (:data:`CHUNK_S` of motion at a time), so the memory does not grow with the
clip and the curves can be written as they come (:func:`effortface.synth.curves_io.write_curve_chunks`):

* motion: :func:`effortface.synth.motion.read_motion_blocks` (a BVH file is parsed and posed a
  block at a time; the bones' lengths come from the same reference frames as the whole clip's);
* energies: the zero-phase (forward-backward) filter is not causal, so each piece is computed on
  its motion plus :func:`margin_frames` on each side, and the margins are dropped. The filter's
  transients decay by its pole radius per frame (0.80 at 6 Hz and 120 Hz); the margin is where they
  fall below 1e-18 of the signal (189 frames at 120 Hz), so the kept frames equal the whole clip's
  within rounding. The clip's own two ends are filtered exactly as the whole clip's are;
* the work and power windows continue the whole clip's running sum (the same numbers);
* physiology (:meth:`~effortface.synth.physiology.PhysiologyState.run`) and the output filter
  (:meth:`~effortface.synth.face.WeightFilter.run`) carry their state from piece to piece.

Tested: equal to the whole-clip path within 1e-12 of each curve's size on a clip of several pieces,
and the peak memory does not grow with the clip (``tests/synth/test_synth_chunked.py``). On an hour
at 120 Hz the two differ by 2e-12 of the curves' sizes: the rounding of the whole clip's own running
sum of the work (its ulp at that length), which the pieces continue from slightly different rates.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.synth import iir
from effortface.synth.energy import (CUTOFF_HZ, POWER_WINDOW_S, WORK_WINDOW_S, butterworth_sos, frame_rates,
                                     segment_energies)
from effortface.synth.face import WeightFilter
from effortface.synth.motion import Motion, MotionBlocks
from effortface.synth.physiology import PhysiologyState
from effortface.synth.runtime import Character, FaceModel

#: Seconds of motion per piece (choice: 60 s at 120 Hz is about 50 MB of working arrays; shorter
#: pieces repeat the margins more often, longer ones hold more).
CHUNK_S = 60.0
#: What is left of the energy filter's transients at the edge of a piece's margin, relative to the signal.
MARGIN_DECAY = 1e-18


def margin_frames(fps: float, cutoff_hz: float = CUTOFF_HZ) -> int:
    """Frames of motion on each side of a piece: the energy filter's transients fall below
    :data:`MARGIN_DECAY` over them (pole radius r: log(decay) / log(r)), plus 2 for the differences."""
    a_mat = iir._state_space(butterworth_sos(cutoff_hz, fps))[0]
    radius = float(np.max(np.abs(np.linalg.eigvals(a_mat))))
    return int(math.ceil(math.log(MARGIN_DECAY) / math.log(radius))) + 2


class TrailingWindow:
    """:func:`effortface.synth.energy._window_rate` over a clip given piece by piece (the same numbers:
    the running sum continues, the last ``n`` sums and rates are kept)."""

    def __init__(self, fps: float, window_s: float) -> None:
        frames = window_s * fps
        self.n = int(np.floor(frames + 1e-9))
        self.frac = max(frames - self.n, 0.0)
        self.window_s = float(window_s)
        self._sums = np.zeros(0)   # the running sum at the last (up to n) frames
        self._rates = np.zeros(0)  # and their rates
        self._last = 0.0
        self._seen = 0

    def push(self, rate: np.ndarray) -> np.ndarray:
        """The windowed rate (sum over the last ``window_s`` / ``window_s``) of the next frames."""
        sums = np.cumsum(np.concatenate([[self._last], rate]))[1:]
        all_sums = np.concatenate([self._sums, sums])
        all_rates = np.concatenate([self._rates, rate])
        late = np.arange(self._seen, self._seen + len(rate)) >= self.n
        at = np.flatnonzero(late) + len(self._sums)
        if self.n < 1:
            out = np.zeros_like(rate)
        else:
            out = sums.copy()
            out[late] = all_sums[at] - all_sums[at - self.n]
        if self.frac > 1e-9:
            out[late] += self.frac * all_rates[at - self.n]
        keep = len(all_sums) - self.n  # the last n frames (none for n = 0)
        self._sums, self._rates = all_sums[max(keep, 0):], all_rates[max(keep, 0):]
        if len(rate):
            self._last = float(sums[-1])
        self._seen += len(rate)
        return out / self.window_s


def _windows(motion: MotionBlocks, chunk_frames: int, margin: int
             ) -> Iterator[tuple[int, int, int, np.ndarray, np.ndarray | None]]:
    """(lo, a, b, positions, rotations): the pieces [a, b) of the clip with their motion [lo, hi),
    ``margin`` frames on each side where the clip has them."""
    n = motion.n_frames
    blocks = motion.blocks()
    pos_parts: list[np.ndarray] = []
    rot_parts: list[np.ndarray | None] = []
    start = end = 0  # the held frames [start, end)
    for a in range(0, n, chunk_frames):
        b = min(n, a + chunk_frames)
        lo, hi = max(0, a - margin), min(n, b + margin)
        while end < hi:
            pos, rot = next(blocks)
            pos_parts.append(pos)
            rot_parts.append(rot)
            end += len(pos)
        held_pos = np.concatenate(pos_parts) if len(pos_parts) > 1 else pos_parts[0]
        held_rot = None if rot_parts[0] is None else (
            np.concatenate(rot_parts) if len(rot_parts) > 1 else rot_parts[0])  # type: ignore[arg-type]
        yield (lo, a, b, held_pos[lo - start:hi - start],
               None if held_rot is None else held_rot[lo - start:hi - start])
        keep = max(0, b - margin) - start  # the next piece's motion starts there
        pos_parts = [held_pos[keep:]]
        rot_parts = [None if held_rot is None else held_rot[keep:]]
        start += keep
    for _ in blocks:  # the reader's own checks on what is left (a wrong frame count)
        pass


def synthesize_chunks(model: FaceModel, motion: MotionBlocks, character: Character, *, mapping: Any = None,
                      filter_tau_s: Any = None, chunk_s: float | None = None) -> Iterator[dict[str, np.ndarray]]:
    """The curves of :meth:`FaceModel.synthesize` (zero-phase energies) piece by piece.

    Parameters
    ----------
    model : FaceModel
    motion : MotionBlocks
        From :func:`effortface.synth.motion.read_motion_blocks`.
    character : Character
    mapping : dict or path, optional
        A user joint-to-segment mapping.
    filter_tau_s : float or sequence of float, optional
        The output filter, as in :meth:`FaceModel.synthesize`.
    chunk_s : float, optional
        Seconds of motion per piece (default :data:`CHUNK_S`).

    Yields
    ------
    dict of ndarray
        Consecutive pieces of the curves (:attr:`FaceModel.columns`, frames in order).
    """
    chunk_s = CHUNK_S if chunk_s is None else chunk_s
    if not (math.isfinite(chunk_s) and chunk_s > 0):
        raise UserError(f"chunk_s: expected seconds above 0, found {chunk_s!r}")
    if motion.n_frames < 1:
        raise UserError(f"motion: expected at least one frame, got none ({motion.skeleton.source})")
    skeleton = motion.skeleton
    fps = skeleton.fps
    dt_s = 1.0 / fps
    e = model.expressiveness(character)
    taus = model.filter_taus(filter_tau_s)
    body = model.body(character, skeleton, mapping)
    physiology = PhysiologyState(model.physiology_params(character))
    smooth = WeightFilter(taus)
    work, power = TrailingWindow(fps, WORK_WINDOW_S), TrailingWindow(fps, POWER_WINDOW_S)
    chunk_frames = max(1, int(round(chunk_s * fps)))
    for lo, a, b, pos, rot in _windows(motion, chunk_frames, margin_frames(fps)):
        piece = Motion(skeleton.joint_names, skeleton.parents, pos, rot, fps, skeleton.source)
        energies = segment_energies(piece, body, cutoff_hz=CUTOFF_HZ, zero_phase=True)
        rate = frame_rates(energies.total_j, body.mass_kg)[a - lo:b - lo]
        w_per_kg, p_per_kg = work.push(rate), power.push(rate)
        phys = physiology.run(w_per_kg, dt_s)
        yield model.curves_from_physiology(np.arange(a, b) / fps, w_per_kg, p_per_kg, phys, e,
                                           lambda weights: smooth.run(weights, dt_s))


__all__ = ["CHUNK_S", "TrailingWindow", "margin_frames", "synthesize_chunks"]
