"""The machine guide (Qt-free): RDP within the tolerance, no-face spans, "Accept machine" as sparse machine keys
(one per 3 s at most, close to the 1 s median of the machine curve) in one undo step."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.annotate_session import AnnotateSession
from effortface.annotate.machine_guide import fit_keys, load_guide, rdp_keep, runs
from effortface.core.errors import UserError
from tests.annotate.machine_helpers import write_fake_machine

ROOT = Path(__file__).resolve().parents[2]
SESSION = ROOT / "sample_sessions" / "P01_20260112-093000_cardio"


@pytest.fixture
def session_dir(tmp_path: Path) -> Path:
    dst = tmp_path / SESSION.name
    shutil.copytree(SESSION, dst, ignore=shutil.ignore_patterns("serial", "*.avi"))
    write_fake_machine(dst)
    return dst


@pytest.mark.parametrize("tolerance", [0.0, 0.01, 0.03, 0.1])
def test_rdp_keeps_every_sample_within_the_tolerance(tolerance: float) -> None:
    rng = np.random.default_rng(1)
    y = np.clip(np.cumsum(rng.normal(0, 0.03, 400)) + 0.4, 0, 1)
    keep = rdp_keep(y, tolerance)
    assert keep[0] == 0 and keep[-1] == y.size - 1 and np.all(np.diff(keep) > 0)
    rebuilt = np.interp(np.arange(y.size), keep, y[keep])
    assert np.max(np.abs(rebuilt - y)) <= tolerance + 1e-12
    if tolerance >= 0.03:
        assert keep.size < y.size / 3  # it simplifies


def test_a_straight_line_needs_two_keys_and_runs_are_inclusive() -> None:
    assert rdp_keep(np.linspace(0.1, 0.9, 50)).tolist() == [0, 49]
    assert runs(np.array([0, 1, 1, 0, 0, 1], bool)) == [(1, 2), (5, 5)]


def one_second_median(curve: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """The reference: at each frame, the median of the machine's values within +-0.5 s (NaN where no face)."""
    out = np.full(curve.shape, np.nan)
    for i in np.flatnonzero(np.isfinite(curve)):
        near = np.abs(t_s - t_s[i]) <= 0.5
        out[i] = np.nanmedian(curve[near])
    return out


def test_accept_machine_sets_sparse_machine_keys_close_to_the_smoothed_curve(session_dir: Path) -> None:
    s = AnnotateSession(session_dir, "R1", autosave=False)
    guide = s.machine
    assert guide is not None and guide.no_face.any()
    s.set_blendshape("mouth_open")
    before = s.track.copy()
    outside = [k.frame for k in before.keys if k.frame < 100 or k.frame > 700]
    fit = s.accept_machine(100, 700)
    keys = [k for k in s.track.keys if 100 <= k.frame <= 700]
    assert len(keys) == len(fit.keys) > 2
    t = np.asarray(s.session.frame_times_s)
    assert len(keys) <= (t[700] - t[100]) / 3.0  # at most one key per 3 s
    assert all(k.origin == "machine" and k.accepted_by == "R1" for k in keys)
    assert not any(guide.no_face[k.frame] for k in keys)  # no key where no face
    assert [k.frame for k in s.track.keys if k.frame < 100 or k.frame > 700] == outside  # untouched
    reference = one_second_median(np.clip(guide.curve("mouth_open"), 0, 1), t)
    frames = np.arange(100, 701)
    face = np.isfinite(reference[frames])
    rms = float(np.sqrt(np.mean((s.track.evaluate(frames) - reference[frames])[face] ** 2)))
    assert rms <= 0.08, rms
    assert "accept machine mouth_open" in s.undo_text and f"RMS {fit.rms:.3f}" in s.undo_text
    s.undo()
    assert s.track == before


def test_the_budget_puts_keys_where_the_curve_moves() -> None:
    t = np.arange(0, 300, 0.5)  # 300 s at 2 frames/s: a flat first half, a ramp up and down after
    curve = np.where(t < 150, 0.2, 0.2 + 0.6 * np.abs(np.sin((t - 150) / 20)))
    fit = fit_keys(curve, t)
    frames = np.array([f for f, _ in fit.keys])
    assert len(frames) <= 300 / 3 and fit.budget == 99  # 299.5 s // 3 s
    assert (t[frames] < 149).sum() <= 2 < (t[frames] >= 150).sum()
    assert fit.max_error <= 0.03 + 1e-9  # within the tolerance before the budget ran out


def test_accept_refuses_without_a_track_or_a_face(session_dir: Path, tmp_path: Path) -> None:
    s = AnnotateSession(session_dir, "R9", autosave=False)
    first, last = s.machine.no_face_spans()[0]
    with pytest.raises(UserError, match="expected frames with a face"):
        s.accept_machine(first, last)
    with pytest.raises(UserError, match="tolerance"):
        s.accept_machine(0, 10, tolerance=2.0)
    bare = tmp_path / "bare"
    shutil.copytree(SESSION, bare, ignore=shutil.ignore_patterns("serial", "*.avi"))
    s2 = AnnotateSession(bare, "R9", autosave=False)
    assert s2.machine is None and load_guide(bare, s2.n_frames) is None
    with pytest.raises(UserError, match="expected a machine track"):
        s2.accept_machine(0, 10)
