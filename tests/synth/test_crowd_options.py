"""The crowd's speed options against the exact float64 face: float32 kernels within their stated
bound, the compact surrogate within its stated error on a held grid (and exact outside its range)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVR

from effortface.core.blendshapes import DEFAULT_SET
from effortface.synth.bundle import ModelBundle, write_bundle
from effortface.synth.face import (SINGLE_PRECISION_ERROR_PER_ALPHA, SURROGATE_MAX_ERROR, SvrModel,
                                   SvrSurrogate, _grid)
from effortface.synth.motion import Motion, read_motion
from effortface.synth.physiology import NhrParams, NhrRegression
from effortface.synth.runtime import Character, FaceModel, load_model
from tests.synth.test_face import _fit_random

JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"
#: the features' training range of the big model below (w, p in W/kg, NHR, EPOC_norm)
HIGH = np.array([25.0, 40.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def big_svr() -> SvrModel:
    """Four C = 100 SVRs fitted on noisy data: about 1,000 support vectors each (the crowd
    benchmark's kind of model, smaller), wide kernels (gamma 0.05) and large dual coefficients."""
    rng = np.random.default_rng(3)
    x = HIGH * rng.uniform(size=(1100, 4))
    scaler = StandardScaler().fit(x)
    z = scaler.transform(x)
    svrs = [SVR(C=100.0, gamma=0.05, epsilon=0.002).fit(
        z, np.tanh(z @ rng.normal(size=4)) * 0.4 + 0.5 + 0.05 * rng.normal(size=len(z))) for _ in range(4)]
    return SvrModel.from_estimators(svrs, scaler.mean_, scaler.scale_)


@pytest.fixture(scope="module")
def big_model(big_svr: SvrModel, tmp_path_factory: pytest.TempPathFactory) -> FaceModel:
    m = big_svr
    bundle = ModelBundle(
        blendshapes=DEFAULT_SET, scaler_mean=m.scaler_mean, scaler_scale=m.scaler_scale,
        nhr_coefficients=NhrParams(7.13, 0.0056, 0.0009), nhr_regression=NhrRegression(),
        svr_hyperparameters=[{"C": 100.0, "gamma": 0.05, "epsilon": 0.002}] * 4,
        support_vectors=m.support_vectors, dual_coef=m.dual_coef, intercept=m.intercept,
        provenance={"data": "random"})
    return load_model(write_bundle(bundle, tmp_path_factory.mktemp("big") / "m"))


def _alpha_sums(model: SvrModel) -> np.ndarray:
    return np.array([np.abs(a).sum() for a in model.dual_coef])


@pytest.mark.parametrize("seed", range(4))
def test_float32_kernels_stay_within_their_stated_bound(seed: int) -> None:
    svrs, scaler, x = _fit_random(seed)
    model = SvrModel.from_estimators(svrs, scaler.mean_, scaler.scale_)
    error = np.abs(model.predict(x, single_precision=True) - model.predict(x)).max(axis=0)
    assert np.all(error > 0)  # it really ran in float32
    assert np.all(error <= SINGLE_PRECISION_ERROR_PER_ALPHA * _alpha_sums(model)), error / _alpha_sums(model)


def _crowd_weights(model: FaceModel, motion: Motion, frames: int, **options: bool) -> np.ndarray:
    """Weights of a 40-character crowd (each a few frames out of phase), all steps stacked."""
    chars = [Character(training_level=float(tl), mass_kg=60.0 + tl) for tl in np.linspace(0, 10, 40)]
    crowd = model.stream_batch(chars, motion, **options)
    out = []
    for k in range(frames):
        positions = np.stack([motion.positions_m[(k + 11 * i) % motion.n_frames] for i in range(len(chars))])
        out.append(crowd.step(positions, 1 / 60))
    return np.array(out)


def test_crowd_float32_and_surrogate_stay_within_their_bounds(big_model: FaceModel, shared_data: Path) -> None:
    motion = read_motion(shared_data / JJ)
    exact = _crowd_weights(big_model, motion, 60)
    single = _crowd_weights(big_model, motion, 60, single_precision=True)
    surrogate = _crowd_weights(big_model, motion, 60, surrogate=True)
    assert isinstance(big_model.face, SvrModel)
    bound = SINGLE_PRECISION_ERROR_PER_ALPHA * _alpha_sums(big_model.face).max()
    assert 0 < np.abs(single - exact).max() <= bound
    assert 0 < np.abs(surrogate - exact).max() <= SURROGATE_MAX_ERROR


def test_surrogate_is_within_its_error_on_a_held_grid(big_svr: SvrModel) -> None:
    surrogate = big_svr.surrogate()
    assert isinstance(surrogate, SvrSurrogate) and big_svr.surrogate() is surrogate  # fitted once
    assert surrogate.n_centres * 4 < sum(len(s) for s in big_svr.support_vectors)  # compact
    assert np.all(surrogate.max_error <= SURROGATE_MAX_ERROR)
    # a grid it was not fitted nor checked on (9 points per axis, not 7) and random points
    box = (surrogate.box_lo, surrogate.box_hi)
    z = np.vstack([_grid(box, 9), box[0] + (box[1] - box[0]) * np.random.default_rng(9).uniform(size=(5000, 4))])
    x = z * big_svr.scaler_scale + big_svr.scaler_mean
    error = np.abs(surrogate.predict(x) - big_svr.predict(x)).max()
    assert 0 < error <= SURROGATE_MAX_ERROR, error


def test_surrogate_gives_the_exact_model_outside_its_range(big_svr: SvrModel) -> None:
    surrogate = big_svr.surrogate()
    assert surrogate is not None
    x = np.array([[12.0, 300.0, 0.5, 0.5], [-40.0, 10.0, 0.2, 0.1], [5.0, 5.0, 0.3, 0.2]])
    got = surrogate.predict(x)
    np.testing.assert_array_equal(got[:2], big_svr.predict(x[:2]))  # outside: the exact model
    assert abs(got[2] - big_svr.predict(x[2:])[0]).max() <= SURROGATE_MAX_ERROR  # inside: close


def test_small_models_keep_their_exact_face(tmp_path: Path, shared_data: Path, make_bundle) -> None:
    """200 support vectors per blendshape: no surrogate would be much cheaper, so none is made and
    the surrogate option changes nothing."""
    model = load_model(write_bundle(make_bundle(), tmp_path / "m"))
    assert isinstance(model.face, SvrModel) and model.face.surrogate() is None
    motion = read_motion(shared_data / JJ)
    np.testing.assert_array_equal(_crowd_weights(model, motion, 5, surrogate=True),
                                  _crowd_weights(model, motion, 5))


def test_float32_kernels_evaluate_each_shared_support_vector_once(big_svr: SvrModel) -> None:
    """The four SVRs share gamma and training rows: the float32 block holds the union of their
    support vectors (one kernel term each), not the sum, and still gives every blendshape's sum."""
    union = np.unique(np.vstack(big_svr.support_vectors), axis=0)
    assert big_svr._single.shape[1] == len(union) < sum(len(s) for s in big_svr.support_vectors)
    x = HIGH * np.random.default_rng(5).uniform(size=(300, 4))
    error = np.abs(big_svr.predict(x, single_precision=True) - big_svr.predict(x)).max(axis=0)
    assert np.all(error > 0)
    assert np.all(error <= SINGLE_PRECISION_ERROR_PER_ALPHA * _alpha_sums(big_svr))


def test_float32_crowd_from_positions_equals_separate_exact_streams(big_model: FaceModel,
                                                                     shared_data: Path) -> None:
    """Six different characters stepped together from joint positions (float32 face) against six
    separate exact float64 streams: within the stated float32 bound on every frame."""
    motion = read_motion(shared_data / JJ)
    chars = [Character(training_level=float(tl), mass_kg=55.0 + 9 * tl, sex="female" if tl % 2 else "male")
             for tl in range(6)]
    crowd = big_model.stream_batch(chars, motion, single_precision=True)
    streams = [big_model.stream(c, motion) for c in chars]
    assert isinstance(big_model.face, SvrModel)
    bound = SINGLE_PRECISION_ERROR_PER_ALPHA * _alpha_sums(big_model.face).max()
    worst = 0.0
    for k in range(40):
        positions = np.stack([motion.positions_m[(k + 17 * i) % motion.n_frames] for i in range(len(chars))])
        together = crowd.step(positions, 1 / 60)
        alone = np.array([s.step(p, 1 / 60) for s, p in zip(streams, positions)])
        worst = max(worst, float(np.abs(together - alone).max()))
    assert 0 < worst <= bound, (worst, bound)


def test_crowd_step_has_no_per_character_work(big_model: FaceModel, shared_data: Path) -> None:
    """The same character 50 times gives 50 identical rows (float32 and float64), and one character
    alone the same weights within the precision's bound (BLAS sums one row in another order):
    nothing in the step depends on how many characters share it."""
    motion = read_motion(shared_data / JJ)
    assert isinstance(big_model.face, SvrModel)
    float32_bound = SINGLE_PRECISION_ERROR_PER_ALPHA * _alpha_sums(big_model.face).max()
    for options, bound in (({}, 1e-9), ({"single_precision": True}, float32_bound)):
        one = big_model.stream_batch([Character()], motion, **options)
        many = big_model.stream_batch([Character()] * 50, motion, **options)
        for k in range(12):
            alone = one.step(motion.positions_m[k][None], 1 / 60)
            stacked = many.step(np.repeat(motion.positions_m[k][None], 50, axis=0), 1 / 60)
            if options:
                np.testing.assert_array_equal(stacked, np.repeat(stacked[:1], 50, axis=0))
            np.testing.assert_allclose(stacked, np.repeat(alone, 50, axis=0), rtol=0, atol=bound)
