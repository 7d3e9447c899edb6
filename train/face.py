"""Face models: features [w, p, NHR, EPOC] -> normalised blendshape weights -> x expressiveness.

SCIENCE.md sections 5 and 6. Two models share one interface, ``predict(features) -> (n, B)``
normalised weights in the blendshape set's order:

- :class:`SvrModel`: RBF epsilon-SVR prediction in numpy from exported arrays (support vectors,
  dual coefficients, intercepts, gamma and the feature scaler), vectorised over rows, so one call
  serves one clip (rows = frames) or a crowd (rows = characters).
- :class:`RuleFaceModel`: the paper's empirical rules (section 4.1.1), deterministic, no training;
  the default model until a trained one exists and a baseline after.

numpy only (the runtime imports this module).
"""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core.errors import UserError
from effortface.train import iir

#: SVR input features, in order, and their units.
FEATURE_NAMES = ("w_per_kg", "p_per_kg", "nhr", "epoc_norm")
FEATURE_UNITS = ("W/kg", "W/kg", "1", "1")

#: Rows per chunk in :meth:`SvrModel.predict`: keeps each (rows x support vectors) kernel block in
#: the L2 cache (16 rows x 2,000 vectors x 8 bytes = 256 KB); measured fastest of 16/64/256/1000.
_CHUNK_ROWS = 16
#: Largest gamma |z|^2 for which the factored kernel (see :func:`_rbf_block`) cannot overflow,
#: in double and in single precision (exp overflows at about 709 and 88).
_MAX_FACTORED_EXPONENT = {np.dtype(np.float64): 600.0, np.dtype(np.float32): 60.0}


def apply_expressiveness(normalised: Any, expressiveness: Any) -> np.ndarray:
    """Scale normalised weights by the expressiveness vector and clip to [0, 1].

    Parameters
    ----------
    normalised : array_like, shape (..., B)
        Predicted normalised weights.
    expressiveness : array_like, shape (B,) or (N, B)
        Per-blendshape factor e_b (< 1 softens, > 1 exaggerates).

    Returns
    -------
    ndarray
        Blendshape weights in [0, 1].
    """
    return np.clip(np.asarray(normalised, dtype=float) * np.asarray(expressiveness, dtype=float),
                   0.0, 1.0)


# --------------------------------------------------------------------------- output filter

#: Default time constant (s) of the output filter on every blendshape weight (choice, see
#: :class:`WeightFilter`): 0.15 s passes the build-up of effort (seconds) and damps the 1-3 Hz
#: rhythm of jumps and strides (2 Hz to 0.2 of its amplitude) with a mean delay of 0.3 s.
DEFAULT_FILTER_TAU_S = 0.15


def check_filter_tau(tau_s: Any, n: int, name: str = "filter_tau_s") -> np.ndarray:
    """Time constants (s) as an (n,) array: one number for every blendshape or one per blendshape.

    Raises
    ------
    UserError
        Naming ``name`` unless the values are finite numbers >= 0 (0 turns the filter off).
    """
    try:
        values = np.broadcast_to(np.asarray(tau_s, dtype=float), (n,)).copy()
    except (TypeError, ValueError):
        raise UserError(f"{name}: expected a time constant in seconds (>= 0) or {n} of them, "
                        f"found {tau_s!r}") from None
    if not np.all(np.isfinite(values) & (values >= 0)):
        raise UserError(f"{name}: expected time constants of 0 s or more, found {tau_s!r}")
    return values


class WeightFilter:
    """Critically damped low-pass on blendshape weights, frame by frame (any frame time).

    Two identical first-order stages in series, ``H(s) = 1 / (1 + tau s)^2``: a double real pole,
    i.e. a critically damped second-order system. A step settles without overshoot (95 % after
    4.7 tau) and the mean delay is 2 tau. Each stage is exact for an input held over the frame,
    ``y <- y + (1 - exp(-dt / tau)) (x - y)``, so it works at any (varying) frame time, and a
    convex combination of weights in [0, 1] stays in [0, 1]. It starts at the first frame's value.
    ``tau = 0`` passes that blendshape through.

    Parameters
    ----------
    tau_s : array_like, shape (B,)
        Time constant per blendshape, seconds (see :func:`check_filter_tau`).

    Examples
    --------
    >>> f = WeightFilter([0.15] * 4)                      # doctest: +SKIP
    >>> smooth = f.step(weights, dt_s)                    # (B,) or (N, B)
    """

    def __init__(self, tau_s: Any) -> None:
        self.tau_s = np.asarray(tau_s, dtype=float)
        self._stages: list[np.ndarray] | None = None

    def step(self, weights: Any, dt_s: float) -> np.ndarray:
        """Filter one frame's weights (..., B) coming ``dt_s`` seconds after the previous frame."""
        x = np.asarray(weights, dtype=float)
        if self._stages is None:
            self._stages = [x.copy(), x.copy()]
            return x.copy()
        with np.errstate(divide="ignore"):
            gain = -np.expm1(-float(dt_s) / self.tau_s)  # 1 where tau = 0
        for k in range(2):
            self._stages[k] = self._stages[k] + gain * (x - self._stages[k])
            x = self._stages[k]
        return x.copy()


def filter_weights(weights: Any, dt_s: float, tau_s: Any) -> np.ndarray:
    """:class:`WeightFilter` over a whole clip at a constant frame time (identical numbers).

    Parameters
    ----------
    weights : array_like, shape (T, B)
    dt_s : float
        Frame interval, seconds.
    tau_s : float or array_like, shape (B,)

    Returns
    -------
    ndarray, shape (T, B)
    """
    y = np.array(weights, dtype=float)
    if y.shape[0] == 0:
        return y
    taus = np.broadcast_to(np.asarray(tau_s, dtype=float), y.shape[1:])
    for tau in np.unique(taus[taus > 0]):  # the blendshapes sharing a time constant together
        gain = -np.expm1(-dt_s / tau)
        stage = [gain, 0.0, 0.0, 1.0, gain - 1.0, 0.0]  # y[k] = (1 - gain) y[k-1] + gain x[k]
        y[:, taus == tau] = iir.sosfilt(np.array([stage, stage]), y[:, taus == tau])  # from the first value
    return y


def jitter(weights: Any) -> float:
    """Median over frames of the largest frame-to-frame step of any blendshape weight.

    Parameters
    ----------
    weights : array_like, shape (T, B)

    Returns
    -------
    float
        0 for fewer than two frames.
    """
    w = np.asarray(weights, dtype=float)
    if w.shape[0] < 2:
        return 0.0
    return float(np.median(np.max(np.abs(np.diff(w, axis=0)), axis=1)))


def _features(features: Any) -> np.ndarray:
    x = np.asarray(features, dtype=float)
    x = x[None, :] if x.ndim == 1 else x
    if x.ndim != 2 or x.shape[1] != len(FEATURE_NAMES):
        raise UserError(f"face features: expected shape (n, {len(FEATURE_NAMES)}) "
                        f"[{', '.join(FEATURE_NAMES)}], found {np.shape(features)}")
    return x


# --------------------------------------------------------------------------- SVR

def _rbf_block(z: np.ndarray, zz: np.ndarray, sv2g: np.ndarray, bias: np.ndarray, gamma: float,
               coef: np.ndarray, max_exponent: float) -> np.ndarray:
    """``sum_i coef_i exp(-gamma |z - s_i|^2)`` for a few rows (the kernel block stays in cache).

    ``exp(-gamma |z - s|^2) = exp(-gamma |z|^2) exp(2 gamma z.s - gamma |s|^2)``: the row factor
    comes out of the sum, saving a pass over the block. The second exponent is at most
    ``gamma |z|^2``, so the factored form is used only while that stays below ``max_exponent``
    (far from overflow); beyond it, the plain form.
    """
    k = z @ sv2g
    k += bias
    row = gamma * zz
    if row.max(initial=0.0) < max_exponent:
        np.exp(k, out=k)
        return np.exp(-row) * (k @ coef)
    k -= row[:, None]
    np.exp(k, out=k)
    return k @ coef


class SvrModel:
    """RBF epsilon-SVR prediction for B blendshapes from exported arrays.

    ``f_b(x) = sum_i alpha_bi exp(-gamma_b |z - s_bi|^2) + b_b`` with ``z = (x - mean) / scale``.

    Parameters
    ----------
    support_vectors : sequence of ndarray, each (S_b, F)
        Support vectors of each blendshape's SVR (in standardised feature space).
    dual_coef : sequence of ndarray, each (S_b,)
        Dual coefficients alpha of each SVR.
    intercept : array_like, shape (B,)
        Intercepts.
    gamma : array_like, shape (B,)
        RBF gamma of each SVR (numbers, never 'scale').
    scaler_mean, scaler_scale : array_like, shape (F,)
        Feature standardisation.
    """

    def __init__(self, support_vectors: Sequence[Any], dual_coef: Sequence[Any], intercept: Any,
                 gamma: Any, scaler_mean: Any, scaler_scale: Any) -> None:
        self.support_vectors = [np.asarray(s, dtype=float).reshape(-1, len(FEATURE_NAMES))
                                for s in support_vectors]
        self.dual_coef = [np.asarray(a, dtype=float).ravel() for a in dual_coef]
        self.intercept = np.asarray(intercept, dtype=float).ravel()
        self.gamma = np.asarray(gamma, dtype=float).ravel()
        self.scaler_mean = np.asarray(scaler_mean, dtype=float).ravel()
        self.scaler_scale = np.asarray(scaler_scale, dtype=float).ravel()
        self._check()
        self._pack()

    @property
    def n_outputs(self) -> int:
        """Number of blendshapes B."""
        return len(self.support_vectors)

    def _check(self) -> None:
        b = len(self.support_vectors)
        sizes = [len(self.dual_coef), self.intercept.size, self.gamma.size]
        if sizes != [b, b, b]:
            raise UserError(f"SVR arrays: expected {b} dual_coef/intercept/gamma entries, found {sizes}")
        for i, (s, a) in enumerate(zip(self.support_vectors, self.dual_coef)):
            if s.shape[0] != a.size:
                raise UserError(f"SVR {i}: expected one dual coefficient per support vector, "
                                f"found {a.size} for {s.shape[0]}")
        if np.any(self.gamma <= 0) or np.any(self.scaler_scale <= 0):
            raise UserError("SVR arrays: expected gamma > 0 and scaler scale > 0, found "
                            f"gamma {self.gamma.tolist()}, scale {self.scaler_scale.tolist()}")

    def _pack(self) -> None:
        """Precompute, per blendshape, what the kernel expansion needs.

        ``-gamma |z - s|^2 = z . (2 gamma s) - gamma |s|^2 - gamma |z|^2``: one small matrix product
        per block of rows, then two in-place additions and the exponential.
        """
        self._blocks: dict[np.dtype, list[tuple[Any, ...]]] = {np.dtype(np.float64): [
            ((2.0 * g * sv).T.copy(), -g * np.einsum("ij,ij->i", sv, sv), float(g), a)
            for sv, a, g in zip(self.support_vectors, self.dual_coef, self.gamma)]}
        self._blocks[np.dtype(np.float32)] = [tuple(np.asarray(v, np.float32) if isinstance(v, np.ndarray)
                                                    else v for v in block)
                                              for block in self._blocks[np.dtype(np.float64)]]

    def standardise(self, features: Any) -> np.ndarray:
        """``(x - mean) / scale`` for rows of [w, p, NHR, EPOC_norm]."""
        return (_features(features) - self.scaler_mean) / self.scaler_scale

    def predict(self, features: Any, *, single_precision: bool = False) -> np.ndarray:
        """Normalised weights for rows of features.

        Parameters
        ----------
        features : array_like, shape (n, 4) or (4,)
            Rows of [w_per_kg, p_per_kg, nhr, epoc_norm] (frames of a clip or characters).
        single_precision : bool
            Evaluate the kernels in float32: about 2x faster for crowds, but each kernel term is
            rounded to float32, so the error grows with the dual coefficients: about
            2e-8 x sum |alpha| (measured; 4e-3 of the weight range for a C = 100 model with
            2,000 support vectors, against 1e-12 in float64). Off by default.

        Returns
        -------
        ndarray, shape (n, B)
            The SVR outputs (not clipped; see :func:`apply_expressiveness`).
        """
        dtype: np.dtype = np.dtype(np.float32 if single_precision else np.float64)
        z = self.standardise(features).astype(dtype, copy=False)
        zz = np.einsum("ij,ij->i", z, z)
        out = np.empty((z.shape[0], self.n_outputs))
        for start in range(0, z.shape[0], _CHUNK_ROWS):
            rows = slice(start, start + _CHUNK_ROWS)
            for b, block in enumerate(self._blocks[dtype]):
                sv2g, bias, gamma, coef = block
                out[rows, b] = _rbf_block(z[rows], zz[rows], sv2g, bias, gamma, coef,
                                          _MAX_FACTORED_EXPONENT[dtype])
        return out + self.intercept

    @classmethod
    def from_estimators(cls, estimators: Sequence[Any], scaler_mean: Any,
                        scaler_scale: Any) -> SvrModel:
        """Export fitted scikit-learn ``SVR`` objects (duck-typed: no sklearn import here).

        Each estimator must be an RBF SVR fitted on standardised features; its gamma is read as a
        number (``_gamma`` holds the value actually used when gamma was 'scale' or 'auto').
        """
        gammas = []
        for est in estimators:
            if est.kernel != "rbf":
                raise UserError(f"SVR kernel: expected 'rbf', found {est.kernel!r}")
            g = est.gamma if isinstance(est.gamma, numbers.Real) else est._gamma
            gammas.append(float(g))
        return cls([e.support_vectors_ for e in estimators], [e.dual_coef_ for e in estimators],
                   [float(np.ravel(e.intercept_)[0]) for e in estimators], gammas,
                   scaler_mean, scaler_scale)


# --------------------------------------------------------------------------- rules

def _smoothstep(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """0 below ``lo``, 1 above ``hi``, a smooth cubic in between."""
    t = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclasses.dataclass(frozen=True)
class RuleParams:
    """Named constants of the rule model (choices; SCIENCE.md section 6 gives only the shapes).

    Attributes
    ----------
    p_onset_w_per_kg : float
        Power below which effort does not show (3 W/kg: calm walking stays near neutral).
    p_half_w_per_kg : float
        Power above the onset giving half the maximal instantaneous exertion (8 W/kg: jumping
        jacks reach about 0.5, running at 3.4 m/s about 0.7).
    fatigue_epoc_share : float
        Fatigue = (1 - share) NHR + share min(EPOC_norm, 1).
    mouth_open_from_nhr, mouth_open_full_nhr : float
        The mouth stays closed below the first NHR (respiration rate is linear in NHR), then opens.
    squint_relax_from, squint_relax_to, squint_residual : float
        Squint follows exertion until fatigue reaches ``from``, relaxes until ``to`` to a constant
        residual.
    """

    p_onset_w_per_kg: float = 3.0
    p_half_w_per_kg: float = 8.0
    fatigue_epoc_share: float = 0.3
    mouth_open_from_nhr: float = 0.4
    mouth_open_full_nhr: float = 0.95
    squint_relax_from: float = 0.5
    squint_relax_to: float = 0.9
    squint_residual: float = 0.25


class RuleFaceModel:
    """The paper's empirical rules as a face model (no training, deterministic).

    - instantaneous exertion follows mechanical power p: ``e / (e + p_half)`` with
      ``e = max(p - p_onset, 0)``; loads raise p, so expression grows with displaced mass;
    - fatigue grows with NHR and EPOC;
    - ``mouth_stretch``: exertion and fatigue;
    - ``mouth_open``: closed early, opens with respiration rate (linear in NHR) and fatigue;
    - ``eye_squint``: exertion up to a fatigue level, then relaxes to a constant residual;
    - ``brow_lower``: down with exertion, up (less lowered) with fatigue.

    Occasional expirations and gulps are not modelled (they would need randomness).

    Parameters
    ----------
    blendshapes : BlendshapeSet
        The set to output, in its order; every name must have a rule.
    params : RuleParams
        The rule constants.
    """

    RULES = ("mouth_stretch", "mouth_open", "eye_squint", "brow_lower")

    def __init__(self, blendshapes: BlendshapeSet = DEFAULT_SET,
                 params: RuleParams = RuleParams()) -> None:
        missing = [n for n in blendshapes.names if n not in self.RULES]
        if missing:
            raise UserError(f"rule face model: expected blendshapes among {', '.join(self.RULES)}, "
                            f"found {', '.join(missing)}")
        self.blendshapes = blendshapes
        self.params = params

    @property
    def n_outputs(self) -> int:
        """Number of blendshapes B."""
        return len(self.blendshapes)

    def predict(self, features: Any) -> np.ndarray:
        """Normalised weights in [0, 1], shape (n, B), for rows of [w, p, NHR, EPOC_norm]."""
        x = _features(features)
        q = self.params
        effort = np.maximum(x[:, 1] - q.p_onset_w_per_kg, 0.0)
        exertion = effort / (effort + q.p_half_w_per_kg)
        nhr = x[:, 2]
        fatigue = (1 - q.fatigue_epoc_share) * nhr + q.fatigue_epoc_share * np.minimum(x[:, 3], 1)
        relax = _smoothstep(fatigue, q.squint_relax_from, q.squint_relax_to)
        rules = {
            "mouth_stretch": 0.6 * exertion + 0.5 * fatigue,
            "mouth_open": 0.7 * _smoothstep(nhr, q.mouth_open_from_nhr, q.mouth_open_full_nhr)
                          + 0.3 * fatigue,
            "eye_squint": exertion * (1 - relax) + q.squint_residual * relax,
            "brow_lower": 0.8 * exertion - 0.5 * fatigue,
        }
        return np.clip(np.column_stack([rules[n] for n in self.blendshapes.names]), 0.0, 1.0)
