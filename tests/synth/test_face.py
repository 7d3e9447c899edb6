"""Face models: numpy SVR = scikit-learn, expressiveness, and the paper's rules."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVR

from effortface.core.blendshapes import DEFAULT_SET, Blendshape, BlendshapeSet
from effortface.core.errors import UserError
from effortface.synth.face import FEATURE_NAMES, RuleFaceModel, RuleParams, SvrModel, apply_expressiveness


def _random_features(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(0, 25, n), rng.uniform(0, 40, n), rng.uniform(0, 1, n),
                            rng.uniform(0, 1.2, n)])


def _fit_random(seed: int, n: int = 300) -> tuple[list[SVR], StandardScaler, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = _random_features(rng, n)
    scaler = StandardScaler().fit(x)
    z = scaler.transform(x)
    svrs = []
    for b in range(4):
        y = np.sin(z @ rng.normal(size=4)) + 0.1 * rng.normal(size=n)
        gamma = "scale" if b == 0 else float(10 ** rng.uniform(-3, 0.5))
        svrs.append(SVR(C=float(10 ** rng.uniform(-1, 3)), gamma=gamma,
                        epsilon=float(rng.uniform(0.01, 0.2))).fit(z, y))
    return svrs, scaler, _random_features(rng, 500)


@pytest.mark.parametrize("seed", range(5))
def test_numpy_svr_equals_sklearn(seed: int) -> None:
    svrs, scaler, x_test = _fit_random(seed)
    model = SvrModel.from_estimators(svrs, scaler.mean_, scaler.scale_)
    expected = np.column_stack([s.predict(scaler.transform(x_test)) for s in svrs])
    got = model.predict(x_test)
    assert got.shape == (500, 4)
    # far-away rows take the unfactored path (gamma |z|^2 > 600) and still match
    far = x_test[:3] * 200
    np.testing.assert_allclose(model.predict(far),
                               np.column_stack([s.predict(scaler.transform(far)) for s in svrs]),
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    # one row at a time (the streaming case) gives the same numbers as the batch
    np.testing.assert_allclose(model.predict(x_test[7]), got[7:8], rtol=0, atol=1e-10)


def test_svr_arrays_are_validated() -> None:
    sv = np.zeros((3, 4))
    with pytest.raises(UserError, match="expected one dual coefficient per support vector"):
        SvrModel([sv], [np.ones(2)], [0.0], [0.1], np.zeros(4), np.ones(4))
    with pytest.raises(UserError, match="expected gamma > 0"):
        SvrModel([sv], [np.ones(3)], [0.0], [0.0], np.zeros(4), np.ones(4))
    model = SvrModel([sv], [np.ones(3)], [0.0], [0.1], np.zeros(4), np.ones(4))
    with pytest.raises(UserError, match=r"expected shape \(n, 4\)"):
        model.predict(np.zeros((2, 3)))


def test_expressiveness_scales_and_clips() -> None:
    pred = np.array([[0.5, 0.2, 0.8, 0.0]])
    np.testing.assert_allclose(apply_expressiveness(pred, [1, 1, 1, 1]), pred)
    np.testing.assert_allclose(apply_expressiveness(pred, [0.5, 2, 2, 1]), [[0.25, 0.4, 1.0, 0.0]])
    crowd = apply_expressiveness(np.repeat(pred, 2, axis=0), [[1, 1, 1, 1], [0, 0, 0, 0]])
    np.testing.assert_allclose(crowd[1], 0.0)


def _rule(w=0.0, p=0.0, nhr=0.0, epoc=0.0) -> dict[str, float]:
    out = RuleFaceModel().predict([w, p, nhr, epoc])[0]
    return dict(zip(DEFAULT_SET.names, out))


def test_rules_follow_the_paper() -> None:
    rest = _rule()
    assert all(v == 0.0 for v in rest.values())  # neutral face at rest
    effort = _rule(w=8, p=15, nhr=0.2)
    tired = _rule(w=8, p=15, nhr=0.95, epoc=0.8)
    assert effort["mouth_stretch"] > rest["mouth_stretch"]
    assert tired["mouth_stretch"] > effort["mouth_stretch"]          # exertion and fatigue
    assert effort["mouth_open"] < 0.1 < tired["mouth_open"]           # closed early, opens later
    assert effort["eye_squint"] > tired["eye_squint"] > 0.2           # relaxes to a residual
    assert effort["brow_lower"] > tired["brow_lower"]                 # up with fatigue
    # the sustained work rate drives exertion (SCIENCE_NOTES "The built-in face follows sustained
    # effort"; it was the power p, which pulses inside every repetition); p alone no longer moves it
    assert _rule(w=30)["eye_squint"] > _rule(w=5)["eye_squint"]
    assert _rule(w=5, p=30)["eye_squint"] == _rule(w=5, p=5)["eye_squint"]
    old = RuleFaceModel(params=RuleParams(exertion_from_work=False))
    assert old.predict([0, 30, 0, 0])[0, 2] > old.predict([0, 5, 0, 0])[0, 2]  # the earlier rule, on request


def test_rules_are_deterministic_and_bounded() -> None:
    rng = np.random.default_rng(3)
    x = _random_features(rng, 1000) * 3
    a = RuleFaceModel().predict(x)
    np.testing.assert_array_equal(a, RuleFaceModel().predict(x))
    assert a.min() >= 0 and a.max() <= 1


def test_rules_follow_the_blendshape_set_order() -> None:
    reordered = BlendshapeSet(tuple(reversed(DEFAULT_SET.shapes)))
    x = [5.0, 12.0, 0.7, 0.3]
    np.testing.assert_array_equal(RuleFaceModel(reordered).predict(x)[0],
                                  RuleFaceModel().predict(x)[0][::-1])
    odd = BlendshapeSet((Blendshape("cheek_puff", "", ()),))
    with pytest.raises(UserError, match="found cheek_puff"):
        RuleFaceModel(odd)


def test_feature_names() -> None:
    assert FEATURE_NAMES == ("w_per_kg", "p_per_kg", "nhr", "epoc_norm")


def test_single_precision_is_close_to_double() -> None:
    svrs, scaler, x_test = _fit_random(7)
    model = SvrModel.from_estimators(svrs, scaler.mean_, scaler.scale_)
    double = model.predict(x_test)
    single = model.predict(x_test, single_precision=True)
    assert not np.array_equal(single, double)  # it really ran in float32
    # float32 rounding of each kernel term: the error scales with sum |alpha| (about 2e-8 of it)
    total_alpha = np.array([np.abs(a).sum() for a in model.dual_coef])
    assert np.all(np.abs(single - double).max(axis=0) <= 1e-7 * total_alpha)
