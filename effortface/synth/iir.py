"""Recursive (IIR) low-pass filters along the time axis, in numpy: design, causal and zero-phase.

What the energies (:mod:`effortface.synth.energy`) and the face's output filter
(:func:`effortface.synth.face.filter_weights`) run on whole clips. The same numbers as
``scipy.signal`` (``butter(..., output="sos")``, ``sosfilt`` from the ``sosfilt_zi`` steady state,
``sosfiltfilt`` / ``filtfilt`` with odd padding, along the last axis), within rounding (about 1e-15
of the signal's range), but numpy only: importing ``scipy.signal`` costs about 0.7 s of CPU (scipy
1.17 parses every docstring at import), more than synthesizing a 10-minute clip, and
``effortface synth`` starts a fresh interpreter each time.

How a filter runs (choice: speed without a compiled extension): the cascade of second-order
sections is one linear state-space system ``s' = A s + B x``, ``y = C s + D x``. Each channel's
frames are cut into blocks of :data:`BLOCK_FRAMES`; the outputs of every block from a zero state
are one matrix product of all (channel, block) rows with the (triangular Toeplitz) impulse-response
matrix, the state at each block's start follows from the previous block's by a prefix scan (log2
of the block count matrix products), and its contribution is added. Channels first (time last),
that is a single large product per pass, and the callers' channels-first kinematics need no
transposition.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Frames per block (measured: 32 fastest of 16-64 on a 10-minute clip's 126 rotation channels).
BLOCK_FRAMES = 32


def butterworth_lowpass_sos(order: int, cutoff_hz: float, fs_hz: float) -> np.ndarray:
    """Second-order sections of a digital low-pass Butterworth filter (bilinear transform).

    The design of ``scipy.signal.butter(order, cutoff_hz, fs=fs_hz, output="sos")``: the analog
    prototype's poles, pre-warped at the cut-off, mapped by the bilinear transform, zeros at
    z = -1, unit gain at 0 Hz; one section per pair of complex poles (a first-order one for an odd
    order), the poles nearest the unit circle last: scipy's sections (to rounding).

    Parameters
    ----------
    order : int
        Filter order, >= 1.
    cutoff_hz : float
        -3 dB frequency, strictly between 0 and ``fs_hz / 2`` (the caller checks it).
    fs_hz : float
        Sampling rate.

    Returns
    -------
    ndarray, shape (ceil(order / 2), 6)
        Rows ``[b0, b1, b2, 1, a1, a2]``.
    """
    warped = 4.0 * math.tan(math.pi * cutoff_hz / fs_hz)  # scipy's pre-warp at fs = 2
    m = np.arange(-order + 1, order, 2)
    analog = warped * -np.exp(1j * np.pi * m / (2 * order))
    poles = (4.0 + analog) / (4.0 - analog)
    gain = float(np.real(warped**order / np.prod(4.0 - analog)))
    denominators = [(abs(p), [1.0, -p.real, 0.0]) for p in poles if abs(p.imag) <= 1e-12]
    denominators += [(abs(p), [1.0, -2.0 * p.real, abs(p) ** 2]) for p in poles if p.imag > 1e-12]
    sos = np.array([[1.0, 2.0, 1.0, *den] for _, den in sorted(denominators, key=lambda s: s[0])])
    if order % 2:  # the lone zero goes to the last section, as scipy pairs them
        sos[-1, :3] = (1.0, 1.0, 0.0)
    sos[0, :3] *= gain
    return sos


def _state_space(sos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(A, B, C, D) of the cascade of sections, each in transposed direct form II."""
    a_mat, b_vec, c_vec, d = np.zeros((0, 0)), np.zeros(0), np.zeros(0), 1.0
    for b0, b1, b2, a0, a1, a2 in np.asarray(sos, dtype=float):
        b0, b1, b2, a1, a2 = b0 / a0, b1 / a0, b2 / a0, a1 / a0, a2 / a0
        a_i = np.array([[-a1, 1.0], [-a2, 0.0]])
        b_i = np.array([b1 - a1 * b0, b2 - a2 * b0])
        n = b_vec.size
        joined = np.zeros((n + 2, n + 2))
        joined[:n, :n], joined[n:, n:], joined[n:, :n] = a_mat, a_i, np.outer(b_i, c_vec)
        a_mat, b_vec = joined, np.concatenate([b_vec, b_i * d])
        c_vec, d = np.concatenate([b0 * c_vec, [1.0, 0.0]]), b0 * d
    return a_mat, b_vec, c_vec, d


def steady_state(sos: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """The filter's state (q, channels) for a constant input ``x0`` (channels,): scipy's ``sosfilt_zi``
    times ``x0``."""
    a_mat, b_vec, _, _ = _state_space(sos)
    unit: np.ndarray = np.linalg.solve(np.eye(b_vec.size) - a_mat, b_vec)
    state: np.ndarray = unit[:, None] * np.asarray(x0, dtype=float)[None, :]
    return state


def sosfilt(sos: np.ndarray, x: Any, state: np.ndarray | None = None) -> np.ndarray:
    """Causal filtering along the last axis from ``state`` (default: the steady state of the first
    frame, as scipy's ``sosfilt(..., zi=sosfilt_zi(sos) * x[..., 0])``).

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    x : ndarray, shape (..., T), or a sequence of (c_i, T) arrays
        Finite values (a block's product multiplies all of its frames). A sequence is stacked along
        the first axis straight into the filter's buffer (no stacked copy).
    state : ndarray, shape (2 n_sections, C), optional
        Initial state of the cascade for the C channels (see :func:`steady_state`).

    Returns
    -------
    ndarray, shape of ``x`` (of the stack for a sequence), float64
    """
    shape, n_frames = _shape(x)
    if n_frames == 0:
        return np.zeros(shape)
    run = _BlockRun(sos, n_frames)
    frames = np.empty((math.prod(shape[:-1]), run.n_blocks * run.length))
    _fill(frames[:, :n_frames], x)
    frames[:, n_frames:] = frames[:, n_frames - 1:n_frames]  # finite: a block's product multiplies every frame
    out = run.apply(frames, steady_state(sos, frames[:, 0]) if state is None else state)
    return out[:, :n_frames].reshape(shape)


def sosfiltfilt(sos: np.ndarray, x: Any, padlen: int) -> np.ndarray:
    """Zero-phase (forward-backward) filtering along the last axis, as scipy's ``sosfiltfilt``.

    ``x`` is extended by ``padlen`` frames at each end by odd reflection (``2 x[0] - x[k]``),
    filtered forwards from the first frame's steady state, then backwards from the last output's,
    and the extension is cut.

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    x : ndarray, shape (..., T), or a sequence of (c_i, T) arrays
        As for :func:`sosfilt`.
    padlen : int
        Frames of odd extension at each end (0 <= padlen < T).

    Returns
    -------
    ndarray, shape of ``x`` (of the stack for a sequence), float64
    """
    shape, n_frames = _shape(x)
    if n_frames == 0:
        return np.zeros(shape)
    n_ext = n_frames + 2 * padlen
    run = _BlockRun(sos, n_ext)
    ext = np.empty((math.prod(shape[:-1]), run.n_blocks * run.length))
    _fill(ext[:, padlen:padlen + n_frames], x)
    if padlen:
        np.subtract(2.0 * ext[:, padlen:padlen + 1], ext[:, 2 * padlen:padlen:-1], out=ext[:, :padlen])
        last = padlen + n_frames - 1
        np.subtract(2.0 * ext[:, last:last + 1], ext[:, last - 1:last - padlen - 1:-1],
                     out=ext[:, last + 1:n_ext])
    ext[:, n_ext:] = ext[:, n_ext - 1:n_ext]  # finite: a block's product multiplies every frame
    forward = run.apply(ext, steady_state(sos, ext[:, 0]))
    forward[:, n_ext:] = forward[:, n_ext - 1:n_ext]  # the backward pass starts there, steady
    run.apply(forward, steady_state(sos, forward[:, n_ext - 1]), backward=True, out=ext)
    return ext[:, padlen:padlen + n_frames].reshape(shape)


def _shape(x: Any) -> tuple[tuple[int, ...], int]:
    """The shape of ``x`` (an array, or the stack of a sequence of (c_i, T) arrays) and T."""
    if isinstance(x, np.ndarray):
        return x.shape, x.shape[-1]
    parts = [np.asarray(p) for p in x]
    return (sum(p.shape[0] for p in parts), parts[0].shape[-1]), parts[0].shape[-1]


def _fill(rows: np.ndarray, x: Any) -> None:
    """Copy ``x`` (an array, or a sequence of (c_i, T) arrays stacked) into ``rows`` (C, T)."""
    if isinstance(x, np.ndarray):
        rows[...] = x.reshape(len(rows), -1)
        return
    at = 0
    for part in x:
        rows[at:at + len(part)] = part
        at += len(part)


class _BlockRun:
    """The block matrices of one filter for a signal of ``n_frames`` (see the module docstring)."""

    def __init__(self, sos: np.ndarray, n_frames: int) -> None:
        a_mat, b_vec, c_vec, d = _state_space(sos)
        self.length = length = min(BLOCK_FRAMES, n_frames)
        self.n_blocks = -(-n_frames // length)
        powers = [np.eye(b_vec.size)]
        for _ in range(length):
            powers.append(a_mat @ powers[-1])
        h = np.array([d] + [float(c_vec @ powers[m - 1] @ b_vec) for m in range(1, length)])
        lag = np.arange(length)[:, None] - np.arange(length)[None, :]
        #: zero-state response inside a block: outputs = frames @ impulse (upper-triangular Toeplitz)
        self.impulse = np.where(lag >= 0, h[np.maximum(lag, 0)], 0.0).T.copy()
        #: a block's frames -> its zero-state end state: frames @ to_end, (length, q)
        self.to_end = np.stack([powers[length - 1 - j] @ b_vec for j in range(length)])
        #: a block's start state -> its outputs: state @ from_start, (q, length)
        self.from_start = np.stack([c_vec @ powers[i] for i in range(length)], axis=1)
        self.step = powers[length]

    def apply(self, frames: np.ndarray, state: np.ndarray, backward: bool = False,
              out: np.ndarray | None = None) -> np.ndarray:
        """Filter ``frames`` (C, n_blocks * length) from ``state`` (q, C), forwards or backwards in
        time; the output (C, n_blocks * length), in ``out`` if given (not ``frames``)."""
        n_channels = frames.shape[0]
        rows = frames.reshape(n_channels * self.n_blocks, self.length)  # (channel, block) rows
        flip = slice(None, None, -1) if backward else slice(None)
        y = np.matmul(rows, np.ascontiguousarray(self.impulse[flip, flip]),
                      out=None if out is None else out.reshape(rows.shape))
        # the blocks' zero-state end states, in the order the state travels (backwards: reversed)
        ends = (rows @ np.ascontiguousarray(self.to_end[flip])).reshape(n_channels, self.n_blocks, -1)
        starts = np.empty_like(ends)
        starts[:, 0] = np.asarray(state).T
        starts[:, 1:] = ends[:, :0:-1] if backward else ends[:, :-1]
        _prefix_scan(starts, self.step.T)
        if backward:
            starts = np.ascontiguousarray(starts[:, ::-1])
        from_start = np.ascontiguousarray(self.from_start[:, flip])
        flat_starts = starts.reshape(-1, starts.shape[2])
        for at in range(0, len(y), _CORRECTION_ROWS):  # in slices: no temporary as large as y
            y[at:at + _CORRECTION_ROWS] += flat_starts[at:at + _CORRECTION_ROWS] @ from_start
        return y.reshape(frames.shape)


#: rows of the start-state correction added at a time in :meth:`_BlockRun.apply` (about 2 MB)
_CORRECTION_ROWS = 4096


def _prefix_scan(starts: np.ndarray, step_t: np.ndarray) -> None:
    """In place along axis 1: ``starts[:, b] += starts[:, b - 1] @ step_t`` in sequence, as log2(n)
    whole-array products (Hillis-Steele scan with the powers step^1, step^2, step^4...).

    ``starts`` holds the initial state then each block's zero-state end state (rows: states); after,
    it holds the state at every block's start.
    """
    shift, power = 1, step_t
    while shift < starts.shape[1]:
        starts[:, shift:] += starts[:, :-shift] @ power
        shift, power = 2 * shift, power @ power
