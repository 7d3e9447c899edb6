"""``effortface synth`` in pieces (effortface.synth.chunked): the whole clip's curves, memory that
does not grow with the clip, the BVH read block by block."""

from __future__ import annotations

import csv
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.core.errors import UserError
from effortface.synth import chunked, motion as mo
from effortface.synth.bundle import write_bundle
from effortface.synth.chunked import TrailingWindow, margin_frames, synthesize_chunks
from effortface.synth.curves_io import LivelinkResampler, curves_text, livelink_rows, write_curve_chunks
from effortface.synth.energy import _window_rate
from effortface.synth.face import WeightFilter, filter_weights
from effortface.synth.motion import read_bvh, read_motion, read_motion_blocks
from effortface.synth.physiology import PhysiologyParams, PhysiologyState, simulate
from effortface.synth.runtime import Character, load_model

JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"
CSV_POSITIONS = "positions.csv"


def tiled_bvh(src: Path, seconds: float, out: Path) -> Path:
    """A real BVH clip's frame lines tiled forwards then backwards to ``seconds`` (its frame rate)."""
    lines = src.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().upper() == "MOTION")
    frames = [line for line in lines[at + 3:] if line.strip()]
    frame_time_s = float(lines[at + 2].split(":")[1])
    order = frames + frames[::-1]
    n = int(round(seconds / frame_time_s))
    body = [order[k % len(order)] for k in range(n)]
    out.write_text("\n".join(lines[:at + 1]) + f"\nFrames: {n}\n{lines[at + 2]}\n" + "\n".join(body) + "\n")
    return out


def _joined(pieces: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([p[k] for p in pieces]) for k in pieces[0]}


def _assert_same_curves(whole: dict[str, np.ndarray], pieces: dict[str, np.ndarray]) -> None:
    """Equal within 1e-12 of each curve's scale (the whole clip's own running sum rounds at that level)."""
    assert list(pieces) == list(whole)
    for k, values in whole.items():
        assert pieces[k].shape == values.shape, k
        scale = max(1.0, float(np.max(np.abs(values))))
        assert np.max(np.abs(pieces[k] - values)) <= 1e-12 * scale, k


@pytest.fixture
def long_clip(shared_data: Path, tmp_path: Path) -> Path:
    """20 s of the real jumping jacks at 120 Hz (2,400 frames)."""
    return tiled_bvh(shared_data / JJ, 20.0, tmp_path / "jj_20s.bvh")


def test_pieces_give_the_whole_clip_curves(long_clip: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Pieces of 1.5 s (shorter than the BVH blocks, which are made small too) on a 20 s clip."""
    monkeypatch.setattr(mo, "BVH_CHUNK_FRAMES", 333)
    model, hero = load_model("default"), Character(training_level=3, mass_kg=80)
    whole = model.synthesize(read_motion(long_clip), hero)
    pieces = list(synthesize_chunks(model, read_motion_blocks(long_clip), hero, chunk_s=1.5))
    assert len(pieces) == 14 and margin_frames(120.0) > 180  # pieces of 180 frames: margins reach past the next
    _assert_same_curves(whole, _joined(pieces))
    assert np.max(whole["w_per_kg"]) > 5  # a real workout, not zeros


def test_pieces_with_an_svr_bundle_and_positions_only(shared_data: Path, tmp_path: Path, make_bundle) -> None:
    """A bundle's SVR face, its output filter, and a clip of joint positions without rotations."""
    model = load_model(write_bundle(make_bundle(), tmp_path / "model"))
    motion = read_motion(shared_data / JJ)
    positions = mo.Motion(motion.joint_names, motion.parents, motion.positions_m, None, motion.fps, "positions")
    whole = model.synthesize(positions, Character())
    blocks = mo._blocks_of(positions, 600)
    _assert_same_curves(whole, _joined(list(synthesize_chunks(model, blocks, Character(), chunk_s=0.5))))


def test_chunk_size_must_be_positive(long_clip: Path) -> None:
    with pytest.raises(UserError, match="chunk_s: expected seconds above 0, found 0"):
        next(synthesize_chunks(load_model("default"), read_motion_blocks(long_clip), Character(), chunk_s=0))


def test_the_command_writes_the_whole_clip_curves(long_clip: Path, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """``effortface synth`` writes piece by piece: the same CSV and Live Link rows as the whole clip."""
    monkeypatch.setattr(chunked, "CHUNK_S", 2.5)
    model = load_model("default")
    whole = model.synthesize(read_motion(long_clip), Character())
    out = tmp_path / "x.csv"
    assert main(["synth", "default", str(long_clip), "--out", str(out)]) == 0
    got = np.loadtxt(out, delimiter=",", skiprows=1)
    expected = np.loadtxt(curves_text(whole, model).splitlines()[1:], delimiter=",")
    assert got.shape == expected.shape == (2400, len(model.columns))
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    live = tmp_path / "x_live.csv"
    assert main(["synth", "default", str(long_clip), "--out", str(live), "--format", "livelink"]) == 0
    with live.open(newline="") as f:
        rows = list(csv.reader(f))
    want = list(csv.reader(curves_text(whole, model, "livelink").splitlines()))
    assert len(rows) == len(want) == 1 + 1200  # 20 s at the 60 fps timecode, one header
    assert rows[0] == want[0] and [r[0] for r in rows] == [r[0] for r in want]
    np.testing.assert_allclose(np.array([r[2:] for r in rows[1:]], float),
                               np.array([r[2:] for r in want[1:]], float), atol=2e-6)


def _peak_bytes(clip: Path, out: Path) -> int:
    """tracemalloc peak of reading, synthesizing and writing ``clip`` in 2 s pieces."""
    model = load_model("default")
    tracemalloc.start()
    try:
        chunks = synthesize_chunks(model, read_motion_blocks(clip), Character(), chunk_s=2.0)
        write_curve_chunks(out, chunks, model)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_clip(shared_data: Path, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Clips of 10 s and 40 s (x4): the peak stays within 1.5x (the whole-clip path: about x4)."""
    monkeypatch.setattr(mo, "BVH_CHUNK_FRAMES", 256)
    short = tiled_bvh(shared_data / JJ, 10.0, tmp_path / "short.bvh")
    long = tiled_bvh(shared_data / JJ, 40.0, tmp_path / "long.bvh")
    _peak_bytes(short, tmp_path / "warm.csv")  # imports and caches
    small, large = _peak_bytes(short, tmp_path / "short.csv"), _peak_bytes(long, tmp_path / "long.csv")
    assert large < 1.5 * small, (small, large)
    assert len((tmp_path / "long.csv").read_text().splitlines()) == 1 + 4800


def test_bvh_blocks_equal_the_whole_read(long_clip: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same values and dtype as read_bvh, float32 above FLOAT32_ABOVE_FRAMES too; reference
    frames every n // 600-th."""
    monkeypatch.setattr(mo, "BVH_CHUNK_FRAMES", 500)
    for limit in (10**6, 1000):  # float64, then float32 for this 2,400-frame clip
        monkeypatch.setattr(mo, "FLOAT32_ABOVE_FRAMES", limit)
        whole = read_bvh(long_clip)
        blocks = read_motion_blocks(long_clip)
        parts = list(blocks.blocks())
        assert len(parts) == 5 and blocks.n_frames == whole.n_frames
        pos, rot = np.concatenate([p for p, _ in parts]), np.concatenate([r for _, r in parts])
        assert pos.dtype == whole.positions_m.dtype and np.array_equal(pos, whole.positions_m)
        assert np.array_equal(rot, whole.rotations)
        assert np.array_equal(blocks.skeleton.positions_m, whole.positions_m[::4])
        assert blocks.skeleton.fps == whole.fps and blocks.skeleton.joint_names == whole.joint_names


def test_a_bvh_with_too_few_frames_fails_before_any_block(long_clip: Path) -> None:
    text = long_clip.read_text().replace("Frames: 2400", "Frames: 2401")
    long_clip.write_text(text)
    with pytest.raises(mo.MotionFormatError, match=r"expected 2401 frame lines \(Frames:\), found 2400"):
        read_motion_blocks(long_clip)


def test_a_bad_frame_line_is_named_by_the_blocks(long_clip: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(mo, "BVH_CHUNK_FRAMES", 500)
    lines = long_clip.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip() == "MOTION") + 3 + 1203  # frame 1203
    lines[at] = lines[at].replace(lines[at].split()[5], "oops", 1)
    long_clip.write_text("\n".join(lines) + "\n")
    with pytest.raises(mo.MotionFormatError) as whole:
        read_bvh(long_clip)
    with pytest.raises(mo.MotionFormatError) as streamed:
        list(read_motion_blocks(long_clip).blocks())
    assert str(streamed.value) == str(whole.value) and f"line {at + 1}:" in str(whole.value)


def test_running_pieces_equal_the_whole_clip_helpers() -> None:
    """Window sums and physiology: the same numbers; the output filter within 1e-14."""
    rng = np.random.default_rng(3)
    rate = rng.uniform(0, 0.3, 1000)
    cuts = [0, 7, 8, 300, 301, 650, 1000]
    for fps, window_s in ((120.0, 1.0), (120.0, 0.25), (30.0, 1.0 / 70), (7.0, 0.3)):
        window = TrailingWindow(fps, window_s)
        got = np.concatenate([window.push(rate[a:b]) for a, b in zip(cuts, cuts[1:])])
        assert np.array_equal(got, _window_rate(rate, fps, window_s)), (fps, window_s)
    params = PhysiologyParams.from_character(Character(training_level=2))
    w = rng.uniform(0, 20, 1000)
    state = PhysiologyState(params)
    pieces = [state.run(w[a:b], 1 / 120) for a, b in zip(cuts, cuts[1:])]
    whole = simulate(w, 1 / 120, params)
    for k, values in whole.items():
        assert np.array_equal(np.concatenate([p[k] for p in pieces]), values), k
    weights = rng.uniform(0, 1, (1000, 4))
    taus = [0.15, 0.0, 0.5, 0.15]
    smooth = WeightFilter(taus)
    got = np.concatenate([smooth.run(weights[a:b], 1 / 120) for a, b in zip(cuts, cuts[1:])])
    np.testing.assert_allclose(got, filter_weights(weights, 1 / 120, taus), rtol=0, atol=1e-14)


def test_livelink_rows_in_pieces() -> None:
    t = np.arange(500) / 200.0  # 200 Hz: 3.3 motion frames per timecode frame
    curves = {"t_s": t, "a": np.sin(t * 7), "b": t**2}
    resampler = LivelinkResampler(["a", "b"])
    cuts = [0, 1, 2, 99, 100, 333, 500]
    pieces = [resampler.push({k: v[a:b] for k, v in curves.items()}) for a, b in zip(cuts, cuts[1:])]
    whole = livelink_rows(curves, ["a", "b"])
    for k in ("t_s", "a", "b"):
        assert np.array_equal(np.concatenate([p[k] for p in pieces]), whole[k]), k


def test_a_bad_frame_late_in_the_clip_leaves_no_file(long_clip: Path, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Pieces were written when the bad line is found: exit 2, one line naming it, no output left."""
    monkeypatch.setattr(chunked, "CHUNK_S", 2.0)
    monkeypatch.setattr(mo, "BVH_CHUNK_FRAMES", 256)
    lines = long_clip.read_text().splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip() == "MOTION") + 3 + 2000
    lines[at] = lines[at] + " 1.0"
    long_clip.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out" / "x.csv"
    out.parent.mkdir()
    assert main(["synth", "default", str(long_clip), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"line {at + 1}: expected " in err[0] and "found 97" in err[0]
    assert list(out.parent.iterdir()) == []
