"""The numpy IIR filters (effortface.synth.iir) against scipy.signal, which they replace at run time."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from effortface.synth import iir
from effortface.synth.energy import butterworth_sos, filter_frames


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize(("cutoff_hz", "fs_hz"), [(6.0, 120.0), (6.0, 30.0), (2.0, 1000.0), (0.5, 3.0)])
def test_butterworth_design_is_scipys(order: int, cutoff_hz: float, fs_hz: float) -> None:
    ours = iir.butterworth_lowpass_sos(order, cutoff_hz, fs_hz)
    np.testing.assert_allclose(ours, signal.butter(order, cutoff_hz, fs=fs_hz, output="sos"),
                               rtol=1e-12, atol=1e-15)


def _random_walks(n_channels: int, n_frames: int, seed: int = 1) -> np.ndarray:
    return np.cumsum(np.random.default_rng(seed).normal(size=(n_channels, n_frames)), axis=1)


# around the block length (32): one frame, a partial block, exactly one, one and a bit, many
@pytest.mark.parametrize("n_frames", [1, 2, 3, 31, 32, 33, 97, 5000])
@pytest.mark.parametrize("order", [1, 2, 4])
def test_causal_and_zero_phase_filters_give_scipys_numbers(n_frames: int, order: int) -> None:
    x = _random_walks(5, n_frames)
    sos = signal.butter(order, 6.0, fs=120.0, output="sos")
    scale = np.abs(x).max()
    causal, _ = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos)[:, None, :] * x[:, :1])
    np.testing.assert_allclose(iir.sosfilt(sos, x), causal, rtol=0, atol=1e-13 * scale)
    padlen = max(min(3 * (2 * len(sos) + 1), n_frames - 1), 0)
    zero_phase = signal.sosfiltfilt(sos, x, padlen=padlen)
    np.testing.assert_allclose(iir.sosfiltfilt(sos, x, padlen), zero_phase, rtol=0, atol=1e-13 * scale)
    # a sequence of channel groups is filtered as their stack
    parts = [x[:1], x[1:3], x[3:]]
    np.testing.assert_allclose(iir.sosfiltfilt(sos, parts, padlen), zero_phase, rtol=0, atol=1e-13 * scale)


def test_filter_frames_filters_along_the_first_axis_as_scipy() -> None:
    """The frames-first helper the motion attachment uses; 1,000 frames of (4, 3) channels."""
    x = _random_walks(12, 1000).T.reshape(1000, 4, 3)
    sos = butterworth_sos(6.0, 120.0)
    expected = signal.sosfiltfilt(sos, x, axis=0, padlen=9)
    np.testing.assert_allclose(filter_frames(x, sos, zero_phase=True), expected, rtol=0, atol=1e-12)
    zi = signal.sosfilt_zi(sos)[:, None, None, :] * x[:1].transpose(1, 2, 0)[None]
    causal, _ = signal.sosfilt(sos, x.transpose(1, 2, 0), zi=zi)
    np.testing.assert_allclose(filter_frames(x, sos, zero_phase=False), causal.transpose(2, 0, 1),
                               rtol=0, atol=1e-12)


def test_filters_start_in_the_steady_state_of_a_constant() -> None:
    """A constant stays itself (scipy's zi semantics), to rounding, for any length."""
    sos = butterworth_sos(6.0, 120.0)
    for n_frames in (1, 40, 1000):
        x = np.full((3, n_frames), 7.25)
        np.testing.assert_allclose(iir.sosfilt(sos, x), x, rtol=1e-13)
        np.testing.assert_allclose(iir.sosfiltfilt(sos, x, min(9, n_frames - 1)), x, rtol=1e-13)
