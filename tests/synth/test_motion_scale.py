"""Long clips (issue 15): the BVH reader parses and poses frames in chunks (same values as one
chunk), holds long clips in float32, and its memory does not grow with a whole-file parse."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from effortface.synth import motion as motion_module
from effortface.synth.motion import MotionFormatError, read_bvh
from effortface.synth.runtime import Character, load_model

JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"


def _tiled(shared_data: Path, tmp_path: Path, n_frames: int) -> Path:
    """The real clip's frame lines repeated to ``n_frames``."""
    lines = (shared_data / JJ).read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().upper() == "MOTION")
    frames = [line for line in lines[at + 3:] if line.strip()]
    body = [frames[k % len(frames)] for k in range(n_frames)]
    path = tmp_path / "long.bvh"
    path.write_text("\n".join(lines[:at + 1] + [f"Frames: {n_frames}", lines[at + 2]] + body) + "\n\n")
    return path


def test_chunks_give_the_values_of_one_chunk(shared_data: Path, monkeypatch) -> None:
    whole = read_bvh(shared_data / JJ)
    monkeypatch.setattr(motion_module, "BVH_CHUNK_FRAMES", 37)  # 439 frames: 12 chunks, a partial one
    chunked = read_bvh(shared_data / JJ)
    assert chunked.positions_m.dtype == np.float64
    np.testing.assert_array_equal(chunked.positions_m, whole.positions_m)
    np.testing.assert_array_equal(chunked.rotations, whole.rotations)


def test_frame_count_and_bad_lines_are_still_named(shared_data: Path, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(motion_module, "BVH_CHUNK_FRAMES", 50)
    path = _tiled(shared_data, tmp_path, 120)
    text = path.read_text().replace("Frames: 120", "Frames: 130")
    path.write_text(text)
    with pytest.raises(MotionFormatError, match=r"expected 130 frame lines \(Frames:\), found 120"):
        read_bvh(path)
    lines = text.replace("Frames: 130", "Frames: 120").splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    lines[first + 75] = lines[first + 75].replace(" ", " x ", 1)  # frame 75, in the second chunk
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MotionFormatError, match=rf"line {first + 76}: expected \d+ numbers, found 'x'"):
        read_bvh(path)


def test_long_clips_are_float32_and_synthesize_like_float64(shared_data: Path, tmp_path: Path,
                                                              monkeypatch) -> None:
    path = _tiled(shared_data, tmp_path, 1200)
    exact = read_bvh(path)
    monkeypatch.setattr(motion_module, "FLOAT32_ABOVE_FRAMES", 1000)
    small = read_bvh(path)
    assert small.positions_m.dtype == small.rotations.dtype == np.float32
    np.testing.assert_allclose(small.positions_m, exact.positions_m, rtol=0, atol=1e-5)  # metres
    model, hero = load_model("default"), Character()
    a, b = model.synthesize(exact, hero), model.synthesize(small, hero)
    # float32 positions: the work differs by rounding only (the error, shown: < 0.5 % of w)
    np.testing.assert_allclose(b["w_per_kg"], a["w_per_kg"], rtol=5e-3, atol=1e-3)
    for name in model.blendshapes.names:
        np.testing.assert_allclose(b[name], a[name], atol=5e-3)


def _peak_bytes(path: Path) -> tuple[int, int]:
    """Peak traced memory of reading ``path``, and the bytes of the motion read."""
    tracemalloc.start()
    try:
        m = read_bvh(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, m.positions_m.nbytes + m.rotations.nbytes


def test_reading_memory_stays_near_the_motion_itself(shared_data: Path, tmp_path: Path,
                                                     monkeypatch) -> None:
    """6,000 frames in chunks of 500 stay within 1.5x the motion; parsed as one chunk (as the
    reader did before), the same clip takes over 3x."""
    path = _tiled(shared_data, tmp_path, 6000)
    monkeypatch.setattr(motion_module, "BVH_CHUNK_FRAMES", 500)
    peak, data = _peak_bytes(path)
    assert peak < 1.5 * data, (peak / 2**20, data / 2**20)
    monkeypatch.setattr(motion_module, "BVH_CHUNK_FRAMES", 10**9)
    peak_whole, _ = _peak_bytes(path)
    assert peak_whole > 3 * data, (peak_whole / 2**20, data / 2**20)


def test_blank_lines_at_chunk_ends(shared_data: Path, tmp_path: Path, monkeypatch) -> None:
    """Trailing blank lines, even more than a chunk of them, end the clip; a blank line that ends a
    chunk but has frames after it is a bad frame line, named."""
    monkeypatch.setattr(motion_module, "BVH_CHUNK_FRAMES", 50)
    path = _tiled(shared_data, tmp_path, 120)
    reference = read_bvh(path)
    path.write_text(path.read_text() + " \n" * 70)
    trailing = read_bvh(path)
    assert trailing.n_frames == 120
    np.testing.assert_array_equal(trailing.rotations, reference.rotations)
    lines = path.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    lines[first + 49] = "   "  # the last line of the first chunk
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MotionFormatError, match=rf"line {first + 50}: expected \d+ numbers, found 0"):
        read_bvh(path)
