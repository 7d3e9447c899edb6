"""Recursive (IIR) low-pass filters along the frame axis, in numpy: design, causal and zero-phase.

What the energies (:mod:`effortface.train.energy`) and the face's output filter
(:func:`effortface.train.face.filter_weights`) run on whole clips. The same numbers as
``scipy.signal`` (``butter(..., output="sos")``, ``sosfilt`` from the ``sosfilt_zi`` steady state,
``sosfiltfilt`` / ``filtfilt`` with odd padding), within rounding (about 1e-15 of the signal's
range), but numpy only: importing ``scipy.signal`` costs about 0.7 s of CPU (scipy 1.17 parses
every docstring at import), more than synthesizing a 10-minute clip, and ``effortface synth``
starts a fresh interpreter each time.

How a filter runs (choice: speed without a compiled extension): the cascade of second-order
sections is one linear state-space system ``s' = A s + B x``, ``y = C s + D x``. The frames are
cut into blocks of :data:`BLOCK_FRAMES`; inside a block the output from a zero state is one matrix
product with the (lower-triangular Toeplitz) impulse-response matrix, the state at each block's
start follows from the previous block's by a prefix scan (log2 of the block count matrix products),
and its contribution is added. Every frame and channel is processed by BLAS, frames first, so a
clip's (T, channels) array needs no transposition.
"""

from __future__ import annotations

import math

import numpy as np

#: Frames per block of :func:`sosfilt` (measured: 32-64 fastest on (72,000 x 180) clips).
BLOCK_FRAMES = 48


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
    """The filter's state (q, channels) for a constant input ``x0`` (channels,): scipy's ``sosfilt_zi``."""
    a_mat, b_vec, _, _ = _state_space(sos)
    unit = np.linalg.solve(np.eye(b_vec.size) - a_mat, b_vec)
    return unit[:, None] * np.asarray(x0, dtype=float)[None, :]


def sosfilt(sos: np.ndarray, x: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
    """Causal filtering along axis 0 of ``x`` (T, channels) from ``state`` (default: the steady
    state of the first frame, as scipy's ``sosfilt(..., zi=sosfilt_zi(sos) * x[0])``).

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    x : ndarray, shape (T, C)
    state : ndarray, shape (2 n_sections, C), optional
        Initial state of the cascade (see :func:`steady_state`).

    Returns
    -------
    ndarray, shape (T, C), float64
    """
    x = np.asarray(x)
    n_frames, n_channels = x.shape
    if n_frames == 0:
        return np.zeros(x.shape)
    run = _BlockRun(sos, n_frames)
    blocks = np.zeros((run.n_blocks * run.length, n_channels))
    blocks[:n_frames] = x
    out = run.apply(blocks, steady_state(sos, x[0]) if state is None else state)
    return out.reshape(-1, n_channels)[:n_frames]


def sosfiltfilt(sos: np.ndarray, x: np.ndarray, padlen: int) -> np.ndarray:
    """Zero-phase (forward-backward) filtering along axis 0, as scipy's ``sosfiltfilt``.

    ``x`` is extended by ``padlen`` frames at each end by odd reflection (``2 x[0] - x[k]``),
    filtered forwards from the first frame's steady state, then backwards from the last output's,
    and the extension is cut.

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    x : ndarray, shape (T, C)
    padlen : int
        Frames of odd extension at each end (0 <= padlen < T).

    Returns
    -------
    ndarray, shape (T, C), float64
    """
    x = np.asarray(x)
    n_frames, n_channels = x.shape
    if n_frames == 0:
        return np.zeros(x.shape)
    n_ext = n_frames + 2 * padlen
    run = _BlockRun(sos, n_ext)
    ext = np.empty((run.n_blocks * run.length, n_channels))
    ext[padlen:padlen + n_frames] = x
    if padlen:
        np.subtract(2.0 * x[0], x[padlen:0:-1], out=ext[:padlen])
        np.subtract(2.0 * x[-1], x[-2:-padlen - 2:-1], out=ext[padlen + n_frames:n_ext])
    ext[n_ext:] = ext[n_ext - 1]  # finite: a block's product multiplies every row, even by 0
    forward = run.apply(ext, steady_state(sos, ext[0])).reshape(ext.shape)
    forward[n_ext:] = forward[n_ext - 1]  # the backward pass starts there in its steady state
    run.apply(forward, steady_state(sos, forward[n_ext - 1]), backward=True, out=ext)
    return ext[padlen:padlen + n_frames]


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
        #: zero-state response inside a block (lower-triangular Toeplitz)
        self.impulse = np.where(lag >= 0, h[np.maximum(lag, 0)], 0.0)
        #: a block's frames -> its zero-state end state (q, length)
        self.to_end = np.stack([powers[length - 1 - j] @ b_vec for j in range(length)], axis=1)
        #: a block's start state -> its outputs (length, q)
        self.from_start = np.stack([c_vec @ powers[i] for i in range(length)])
        self.step = powers[length]

    def apply(self, frames: np.ndarray, state: np.ndarray, backward: bool = False,
              out: np.ndarray | None = None) -> np.ndarray:
        """Filter ``frames`` (n_blocks * length, C) from ``state``, forwards or backwards in time;
        the output as (n_blocks, length, C), in ``out`` if given (not ``frames``)."""
        blocks = frames.reshape(self.n_blocks, self.length, -1)
        flip = slice(None, None, -1) if backward else slice(None)
        impulse, to_end = self.impulse[flip, flip], self.to_end[:, flip]
        y = np.matmul(np.ascontiguousarray(impulse), blocks,
                      out=None if out is None else out.reshape(blocks.shape))
        starts = np.empty((self.n_blocks, self.step.shape[0], blocks.shape[2]))
        ordered, data = (starts[::-1], blocks[::-1]) if backward else (starts, blocks)
        ordered[0] = state
        if self.n_blocks > 1:  # zero-state end states of the blocks, then the scan over blocks
            ordered[1:] = np.matmul(np.ascontiguousarray(to_end), data[:-1])
            _prefix_scan(ordered, self.step)
        y += np.matmul(np.ascontiguousarray(self.from_start[flip]), starts)
        return y


def _prefix_scan(starts: np.ndarray, step: np.ndarray) -> None:
    """In place: ``starts[b] += step @ starts[b - 1]`` sequentially, as log2(n) whole-array products.

    ``starts`` holds the initial state then each block's zero-state end state; afterwards it holds
    the state at every block's start (Hillis-Steele scan with the powers step^1, step^2, step^4...).
    """
    shift, power = 1, step
    while shift < len(starts):
        starts[shift:] += np.matmul(power, starts[:-shift])
        shift, power = 2 * shift, power @ power
