"""The runtime API: Character validation, whole-clip synthesis, streams, crowds, bundles."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from effortface.core.errors import UserError
from effortface.synth.bundle import write_bundle
from effortface.synth.motion import motion_from_positions, read_motion
from effortface.synth.face import DEFAULT_FILTER_TAU_S, WeightFilter, filter_weights, jitter
from effortface.synth.runtime import CURVE_COLUMNS, Character, load_model

ROOT = Path(__file__).resolve().parents[2]
JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"


@pytest.fixture(scope="module")
def jumping_jacks(shared_data: Path):
    return read_motion(shared_data / JJ)


BAD_CHARACTERS = {
    r"mass_kg: expected a number from 15 to 300 kg, found -75": dict(mass_kg=-75),
    r"training_level: expected a number from 0 to 10, found 11": dict(training_level=11),
    r"training_level: expected a number from 0 to 10, found -1": dict(training_level=-1),
    r"sex: expected one of female, male, found 'robot'": dict(sex="robot"),
    r"age: expected a number from 10 to 100 years, found 300": dict(age=300),
    r"height_m: expected a number from 0.5 to 2.6 m, found 178": dict(height_m=178),
    r"expressiveness: expected numbers >= 0, found \(1, -1, 1, 1\)": dict(expressiveness=(1, -1, 1, 1)),
    r"expressiveness: expected a sequence of numbers, found 'big'": dict(expressiveness="big"),
    r"load_left_kg: expected a load of 0 kg or more, found -3": dict(load_left_kg=-3),
    r"hr_max_bpm: expected a number from 100 to 240 bpm, found 900": dict(hr_max_bpm=900),
}


@pytest.mark.parametrize(("message", "fields"), BAD_CHARACTERS.items(), ids=list(BAD_CHARACTERS))
def test_bad_characters(message: str, fields: dict) -> None:
    with pytest.raises(UserError, match=message) as info:
        Character(**fields)
    assert "\n" not in str(info.value)


def test_expressiveness_length_is_checked_against_the_model(jumping_jacks) -> None:
    model = load_model("default")
    with pytest.raises(UserError, match=r"expressiveness: expected 4 values \(mouth_stretch, "
                                        r"mouth_open, eye_squint, brow_lower\), found 3"):
        model.synthesize(jumping_jacks, Character(expressiveness=(1, 1, 1)))
    with pytest.raises(UserError, match="expected 4 values"):
        model.stream(Character(expressiveness=(1,) * 5), jumping_jacks)


def test_synthesize_a_real_clip(shared_data: Path) -> None:
    model = load_model("default")
    hero = Character()
    curves = model.synthesize(shared_data / JJ, hero)
    assert tuple(curves) == CURVE_COLUMNS + ("mouth_stretch", "mouth_open", "eye_squint",
                                             "brow_lower")
    assert {len(v) for v in curves.values()} == {439}
    params = model.physiology_params(hero)
    assert params.hr_rest_bpm <= curves["hr_bpm"].min() <= curves["hr_bpm"].max() <= params.hr_max_bpm
    weights = np.column_stack([curves[n] for n in model.blendshapes.names])
    assert weights.min() >= 0 and weights.max() <= 1
    assert curves["eye_squint"].max() > 0.3  # jumping jacks show exertion
    assert 6 < np.median(curves["w_per_kg"][120:]) < 12


def test_expressiveness_and_loads_change_the_face(jumping_jacks) -> None:
    model = load_model("default")
    base = model.synthesize(jumping_jacks, Character())
    soft = model.synthesize(jumping_jacks, Character(expressiveness=(0.5, 1, 1, 0)))
    np.testing.assert_allclose(soft["mouth_stretch"], 0.5 * base["mouth_stretch"])
    assert soft["brow_lower"].max() == 0
    loaded = model.synthesize(jumping_jacks, Character(load_left_kg=10, load_right_kg=10))
    assert loaded["w_per_kg"][120:].mean() > base["w_per_kg"][120:].mean()
    assert loaded["mouth_stretch"][120:].mean() > base["mouth_stretch"][120:].mean()


def test_training_level_slows_the_heart_rate(jumping_jacks) -> None:
    tiled = dataclasses.replace(jumping_jacks,
                                positions_m=np.tile(jumping_jacks.positions_m[1:], (30, 1, 1)),
                                rotations=None)  # about 110 s of jumping jacks
    model = load_model("default")
    unfit = model.synthesize(tiled, Character(training_level=0))["nhr"][-1]
    athlete = model.synthesize(tiled, Character(training_level=10))["nhr"][-1]
    assert unfit > 0.3 and athlete < unfit


def _stream_curves(model, character, motion, causal_rotations: bool) -> dict[str, np.ndarray]:
    live = model.stream(character, motion)
    rows = []
    for k, frame in enumerate(motion.positions_m):
        rot = motion.rotations[k] if causal_rotations else None
        live.step(frame, 1 / motion.fps, rot)
        rows.append(live.last)
    return {key: np.array([r[key] for r in rows]) for key in rows[0]}


@pytest.mark.parametrize("model_name", ["default", "bundle"])
def test_streaming_equals_whole_clip(jumping_jacks, tmp_path: Path, model_name: str, make_bundle) -> None:
    path = "default" if model_name == "default" else write_bundle(make_bundle(), tmp_path / "m")
    model = load_model(path)
    hero = Character(training_level=2, expressiveness=(1, 0.8, 1.2, 1))
    whole = model.synthesize(jumping_jacks, hero, causal=True)
    streamed = _stream_curves(model, hero, jumping_jacks, causal_rotations=True)
    assert list(streamed) == list(whole)
    for key in whole:
        np.testing.assert_allclose(streamed[key], whole[key], rtol=1e-9, atol=1e-9, err_msg=key)


def test_crowd_equals_single_streams(jumping_jacks, tmp_path: Path, make_bundle) -> None:
    model = load_model(write_bundle(make_bundle(), tmp_path / "m"))
    crowd_chars = [Character(training_level=tl, mass_kg=m, expressiveness=(1, 1, e, 1))
                   for tl, m, e in [(0, 60, 1), (5, 80, 0.5), (10, 100, 1.5)]]
    skeleton = motion_from_positions(jumping_jacks.positions_m[:2], jumping_jacks.joint_names,
                                     jumping_jacks.parents, jumping_jacks.fps)
    crowd = model.stream_batch(crowd_chars, skeleton)
    singles = [model.stream(c, skeleton) for c in crowd_chars]
    frames = jumping_jacks.positions_m[:200]
    for k, frame in enumerate(frames):
        # each character a few frames out of phase
        positions = np.stack([frames[(k + 7 * i) % len(frames)] for i in range(3)])
        together = crowd.step(positions, 1 / 120)
        apart = np.stack([s.step(p, 1 / 120) for s, p in zip(singles, positions)])
        np.testing.assert_allclose(together, apart, rtol=0, atol=1e-10)
    with pytest.raises(UserError, match=r"positions_m: expected shape \(3, J, 3\)"):
        crowd.step(frames[:2], 1 / 120)


def test_bundle_model_uses_its_svr(jumping_jacks, tmp_path: Path, make_bundle) -> None:
    bundle = make_bundle(3)
    model = load_model(write_bundle(bundle, tmp_path / "m"))
    curves = model.synthesize(jumping_jacks, Character(), filter_tau_s=0)
    x = np.column_stack([curves["w_per_kg"], curves["p_per_kg"], curves["nhr"],
                         curves["epoc"] / bundle.epoc_params().scale_ml_per_kg])
    expected = np.clip(bundle.face_model().predict(x), 0, 1)
    raw = np.column_stack([curves[n] for n in model.blendshapes.names])
    np.testing.assert_allclose(raw, expected, atol=1e-10)
    smooth = model.synthesize(jumping_jacks, Character())  # the bundle's output filter, on by default
    np.testing.assert_allclose(np.column_stack([smooth[n] for n in model.blendshapes.names]),
                               filter_weights(expected, 1 / jumping_jacks.fps, DEFAULT_FILTER_TAU_S),
                               atol=1e-10)


def test_output_filter_removes_the_jump_rhythm(jumping_jacks, tmp_path: Path, make_bundle) -> None:
    """Jumping jacks through an SVR bundle: the filter cuts the jitter (median largest frame-to-frame
    step of any weight) at least 3x and keeps the mean face within 0.03 once effort has built up."""
    model = load_model(write_bundle(make_bundle(), tmp_path / "m"))
    raw = model.synthesize(jumping_jacks, Character(), filter_tau_s=0)
    smooth = model.synthesize(jumping_jacks, Character())
    names = model.blendshapes.names
    raw_w, smooth_w = (np.column_stack([c[n] for n in names]) for c in (raw, smooth))
    print(f"jitter: raw {jitter(raw_w):.5f}, filtered {jitter(smooth_w):.5f}")
    assert jitter(smooth_w) < jitter(raw_w) / 3
    late = raw["t_s"] >= 1.0
    np.testing.assert_allclose(smooth_w[late].mean(axis=0), raw_w[late].mean(axis=0), atol=0.03)


@pytest.mark.parametrize("fps", [30.0, 120.0])
def test_weight_filter_is_critically_damped_at_any_frame_time(fps: float) -> None:
    """A unit step through the filter with +-30 % jittering frame times follows the critically
    damped response 1 - (1 + t/tau) exp(-t/tau): no overshoot, same curve at 30 and 120 fps."""
    tau = 0.15
    rng = np.random.default_rng(3)
    dt_s = (1.0 + rng.uniform(-0.3, 0.3, int(2 * fps))) / fps
    f = WeightFilter(np.full(2, tau))
    f.step(np.zeros(2), dt_s[0])
    t_s = np.cumsum(dt_s[1:])
    y = np.array([f.step(np.ones(2), dt)[0] for dt in dt_s[1:]])
    exact = 1 - (1 + t_s / tau) * np.exp(-t_s / tau)
    assert np.all(np.diff(y) >= 0) and y.max() <= 1.0
    np.testing.assert_allclose(y, exact, atol=0.05)  # first-order in dt / tau: 0.037 at 30 fps


def test_filter_tau_is_checked_and_zero_passes_through(jumping_jacks) -> None:
    model = load_model("default")
    with pytest.raises(UserError, match=r"filter_tau_s: expected time constants of 0 s or more, found -1"):
        model.synthesize(jumping_jacks, Character(), filter_tau_s=-1)
    with pytest.raises(UserError, match=r"filter_tau_s: expected a time constant in seconds \(>= 0\) or 4"):
        model.stream(Character(), jumping_jacks, filter_tau_s=(0.1, 0.2))
    f = WeightFilter(np.zeros(4))
    f.step(np.zeros(4), 0.01)
    np.testing.assert_array_equal(f.step(np.full(4, 0.7), 0.01), np.full(4, 0.7))


def test_load_model_errors(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="nowhere: expected a model folder"):
        load_model(tmp_path / "nowhere")


def test_rule_face_orders_the_real_clips(shared_data: Path) -> None:
    """Default model: squats and walking < jumping jacks < running (mean over the clip's last 3/4)."""
    model = load_model("default")
    clips = ["cmu_13_29_squats_120fps.bvh", "amp_humanoid_walk.npz",
             "cmu_13_29_jumping_jacks_120fps.bvh", "amp_humanoid_run.npz"]
    squint = []
    for name in clips:
        curves = model.synthesize(shared_data / "motion" / name, Character(training_level=0))
        squint.append(curves["eye_squint"][len(curves["t_s"]) // 4:].mean())
    assert max(squint[:2]) < 0.2 < squint[2] < squint[3]


def test_character_stream_work_does_not_depend_on_the_game_frame_rate(jumping_jacks) -> None:
    """The jumping-jacks skeleton is 120 fps; a game stepping it at 30 fps (every 4th frame) or with
    jittering frame times gets the same mean work (issue 18: 30 fps used to give 10.5 instead of 8.7 W/kg)."""
    model = load_model("default")
    hero = Character()

    def mean_w(idx: np.ndarray) -> float:
        live = model.stream(hero, jumping_jacks)
        t = jumping_jacks.t_s[idx]
        dt = np.diff(t, prepend=t[0] - 1 / 120)
        w = np.array([(live.step(jumping_jacks.positions_m[i], d), live.last["w_per_kg"])[1]
                      for i, d in zip(idx, dt)])
        keep = t >= 1.0
        return float(np.average(w[keep], weights=dt[keep]))

    n = jumping_jacks.n_frames
    every = mean_w(np.arange(n))
    rng = np.random.default_rng(0)
    jittered = np.unique(np.cumsum(rng.integers(1, 4, n)))  # frame gaps of 1-3 skeleton frames
    for idx in (np.arange(0, n, 4), jittered[jittered < n]):
        assert mean_w(idx) == pytest.approx(every, rel=0.05)


def test_synthesize_stage_curves_use_the_output_filter(jumping_jacks) -> None:
    """The Synthesize stage's session (what its plots, preview and Live Link export show) gets the
    model's filtered weights: the same as synthesize(), with less jitter than the raw weights."""
    from effortface.synth.synth_session import SynthSession

    session = SynthSession("default")
    session.load_motion(jumping_jacks)
    model = session.model
    names = model.blendshapes.names
    shown = np.column_stack([session.curves[n] for n in names])
    raw = model.synthesize(jumping_jacks, session.character, filter_tau_s=0)
    filtered = model.synthesize(jumping_jacks, session.character)
    np.testing.assert_allclose(shown, np.column_stack([filtered[n] for n in names]), atol=1e-9)
    assert jitter(shown) < jitter(np.column_stack([raw[n] for n in names])) / 2
