"""Face models: features [w, p, NHR, EPOC] -> normalised blendshape weights -> x expressiveness.

SCIENCE.md sections 5 and 6. Two models share one interface, ``predict(features) -> (n, B)``
normalised weights in the blendshape set's order:

- :class:`SvrModel`: RBF epsilon-SVR prediction in numpy from exported arrays (support vectors,
  dual coefficients, intercepts, gamma and the feature scaler), vectorised over rows, so one call
  serves one clip (rows = frames) or a crowd (rows = characters).
- :class:`RuleFaceModel`: the paper's empirical rules (section 4.1.1), deterministic, no training;
  the default model until a trained one exists and a baseline after.

For big crowds, :class:`SvrSurrogate` stands in for an :class:`SvrModel` with far fewer kernel terms
(within :data:`SURROGATE_MAX_ERROR` on the training range; the crowd's ``surrogate`` option).

numpy only (the runtime imports this module).
"""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from effortface.core import bounds
from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core.errors import UserError
from effortface.synth import iir

#: SVR input features, in order, and their units.
FEATURE_NAMES = ("w_per_kg", "p_per_kg", "nhr", "epoc_norm")
FEATURE_UNITS = ("W/kg", "W/kg", "1", "1")

#: Rows per chunk in :meth:`SvrModel.predict`: keeps each (rows x support vectors) kernel block in
#: the L2 cache (16 rows x 2,000 vectors x 8 bytes = 256 KB); measured fastest of 16/64/256/1000.
_CHUNK_ROWS = 16
#: Largest gamma |z|^2 for which the factored kernel (see :func:`_rbf_block`) cannot overflow
#: (exp overflows at about 709).
_MAX_FACTORED_EXPONENT = 600.0
#: Values per block of the single-precision kernel matrix (2 MB of float32: the L2 cache); measured
#: on 2,500 rows x 8,000 support vectors, 32-128 rows per block run at the speed of one ``exp``.
_SINGLE_BLOCK_VALUES = 512 * 1024
#: Bound on the float32 error of :meth:`SvrModel.predict` (``single_precision``) per unit of a
#: blendshape's sum |alpha|: float32's unit roundoff, 2^-24, on every kernel term (measured: 2-3e-8).
SINGLE_PRECISION_ERROR_PER_ALPHA = 6e-8
#: The largest error (weight units) a :class:`SvrSurrogate` may make against its exact SVR on the
#: held-out points of the training range it checks (choice: 0.1 % of the weight range, below what
#: float32 kernels cost a C = 100 model; the surrogates fitted so far stay under 1e-4).
SURROGATE_MAX_ERROR = 1e-3
#: The surrogate's box: the support vectors' extended by this share of its width on every side
#: (a crowd at rest sits on the training range's edge: NHR and EPOC 0).
SURROGATE_BOX_MARGIN = 0.1
#: Centres a surrogate starts with; doubled until it meets its error bound.
SURROGATE_FIRST_CENTRES = 256
#: ... and stops growing there (the least-squares fit of 1,024 centres takes a few seconds).
SURROGATE_MAX_CENTRES = 1024
#: A surrogate is kept only if it evaluates at most this share of the model's kernel terms.
SURROGATE_MAX_COST_SHARE = 0.25


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


# --------------------------------------------------------------------------- rest anchor

#: Features of a character at rest: no work, no power, resting heart rate, no EPOC.
REST_FEATURES = (0.0, 0.0, 0.0, 0.0)
#: Training seconds count as rest for the raters' rest level below this work (W/kg) ...
REST_MAX_W_PER_KG = 0.5
#: ... and at or below this NHR (a heart back at rest, not a pause between bouts).
REST_MAX_NHR = 0.02


@dataclasses.dataclass(frozen=True)
class RestAnchor:
    """An affine map of the normalised SVR outputs that puts the output at rest on a chosen level.

    ``y' = level + (y - at_rest) (1 - level) / (1 - at_rest)`` per blendshape: the SVR's output for
    :data:`REST_FEATURES` becomes ``level`` and 1 stays 1 (monotone; clipped to [0, 1] with the
    expressiveness). An epsilon-SVR fitted to noisy labels does not pass through the raters' rest
    keys: on the sample lab it gave 0.08 to a character that stood still. ``level`` is 0, a neutral
    face; ``raters_rest_level`` records what the raters keyed at rest (median normalised weight of
    the training seconds below :data:`REST_MAX_W_PER_KG` and :data:`REST_MAX_NHR`), the tolerance
    the level must stay under (SCIENCE_NOTES "A still face at rest").

    Parameters
    ----------
    at_rest : array_like, shape (B,)
        The SVR's normalised output for :data:`REST_FEATURES`.
    level : array_like, shape (B,)
        The normalised weight it maps to.
    raters_rest_level : array_like, shape (B,)
        The raters' median normalised key at rest (NaN without rest seconds); for the record.
    """

    at_rest: tuple[float, ...]
    level: tuple[float, ...]
    raters_rest_level: tuple[float, ...]

    def apply(self, normalised: Any) -> np.ndarray:
        """The anchored normalised outputs, same shape (..., B) as ``normalised``."""
        y = np.asarray(normalised, dtype=float)
        rest, level = np.asarray(self.at_rest, dtype=float), np.asarray(self.level, dtype=float)
        return level + (y - rest) * (1.0 - level) / (1.0 - rest)

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``model.json`` ``rest_anchor``)."""
        return {"features": list(REST_FEATURES), "at_rest": [float(v) for v in self.at_rest],
                "level": [float(v) for v in self.level],
                "raters_rest_level": [None if not np.isfinite(v) else float(v) for v in self.raters_rest_level]}

    @classmethod
    def from_dict(cls, doc: dict[str, Any], n: int, where: str) -> RestAnchor:
        """Read the JSON form; raise UserError naming ``where`` and the field for a malformed one.

        Every value is bounded (:data:`effortface.core.bounds.BOUNDS`): ``at_rest`` from -1 to 0.99 (:func:`rest_anchor`
        writes it from 0: a value far below 0 would map every output to 1), ``level``
        from 0 to 0.99, ``raters_rest_level`` a number or null.
        """
        lists: dict[str, Any] = {key: doc.get(key, [None] * n if key == "raters_rest_level" else None) for key in
                                 ("at_rest", "level", "raters_rest_level")} if isinstance(doc, dict) else {}
        if not lists or not all(isinstance(v, list) and len(v) == n for v in lists.values()):
            raise UserError(f"{where}.rest_anchor: expected {n} values each in the at_rest, level and "
                            f"raters_rest_level lists, found {doc!r:.80}")
        at_rest = tuple(bounds.check("rest_at_rest", v, f"{where}.rest_anchor.at_rest[{i}]")
                        for i, v in enumerate(lists["at_rest"]))
        level = tuple(bounds.check("rest_level", v, f"{where}.rest_anchor.level[{i}]")
                      for i, v in enumerate(lists["level"]))
        raters = tuple(float("nan") if v is None else bounds.check("svr_value", v, f"{where}.rest_anchor."
                                                                                  f"raters_rest_level[{i}]")
                       for i, v in enumerate(lists["raters_rest_level"]))
        return cls(at_rest, level, raters)


def rest_anchor(at_rest: Any, raters_rest_level: Any) -> RestAnchor:
    """The anchor of a fitted model: its output at rest mapped to a neutral face (level 0)."""
    at = np.clip(np.asarray(at_rest, dtype=float).ravel(), 0.0, 0.99)  # already neutral: unchanged
    return RestAnchor(tuple(float(v) for v in at), (0.0,) * at.size,
                      tuple(float(v) for v in np.asarray(raters_rest_level, dtype=float).ravel()))


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
        Naming ``name`` unless the values are numbers from 0 (0 turns the filter off) to the
        ``filter_tau_s`` bound of :data:`effortface.core.bounds.BOUNDS` (an integer of 400 digits too).
    """
    items = list(np.ravel(tau_s)) if isinstance(tau_s, np.ndarray) else \
        list(tau_s) if isinstance(tau_s, (list, tuple)) else [tau_s]
    if len(items) not in (1, n):
        raise UserError(f"{name}: expected a time constant in seconds (>= 0) or {n} of them, "
                        f"found {tau_s!r:.80}")
    values = [_tau_value(v, tau_s, f"{name}[{i}]" if len(items) > 1 else name) for i, v in enumerate(items)]
    return np.broadcast_to(np.asarray(values, dtype=float), (n,)).copy()


def _tau_value(value: Any, given: Any, label: str) -> float:
    """One time constant (s) within ``BOUNDS["filter_tau_s"]`` (an integer of 400 digits too); UserError
    naming ``label``, as ``check_filter_tau`` has always said for a negative or non-numeric one."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not value >= 0:
        raise UserError(f"{label.split('[')[0]}: expected time constants of 0 s or more, found {given!r:.80}")
    return bounds.check("filter_tau_s", value, label)


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

    def run(self, weights: Any, dt_s: float) -> np.ndarray:
        """Filter T frames (T, B) at a constant frame time, continuing from the previous call.

        A clip filtered in consecutive pieces gives :func:`filter_weights`'s numbers on the whole
        clip within rounding (each stage restarts from its last output: within 1e-14).
        """
        y = np.array(weights, dtype=float)
        if y.shape[0] == 0:
            return y
        if self._stages is None:
            self._stages = [y[0].copy(), y[0].copy()]
        taus = np.broadcast_to(self.tau_s, y.shape[1:])
        for tau in np.unique(taus[taus > 0]):
            gain = -np.expm1(-dt_s / tau)
            stage = np.array([[gain, 0.0, 0.0, 1.0, gain - 1.0, 0.0]])  # y[k] = (1 - gain) y[k-1] + gain x[k]
            cols = taus == tau
            for k in range(2):
                state = np.zeros((2, int(cols.sum())))
                state[0] = (1.0 - gain) * self._stages[k][cols]  # the section's state after its last output
                y[:, cols] = iir.sosfilt(stage, y[:, cols].T, state).T
                self._stages[k][cols] = y[-1, cols]
        for k in range(2):
            self._stages[k][taus == 0] = y[-1, taus == 0]
        return y


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
        y[:, taus == tau] = iir.sosfilt(np.array([stage, stage]), y[:, taus == tau].T).T  # from the first value
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
        self._blocks: list[tuple[Any, ...]] = [
            ((2.0 * g * sv).T.copy(), -g * np.einsum("ij,ij->i", sv, sv), float(g), a)
            for sv, a, g in zip(self.support_vectors, self.dual_coef, self.gamma)]
        # single precision: the support vectors in one block whose product with [z, 1, |z|^2] is the
        # exponent -gamma |z - s|^2 itself (no factored form, no overflow check). Blendshapes with the
        # same gamma fitted on the same rows share most support vectors: each distinct (vector, gamma)
        # gets one column (one kernel term, one exp) and a coefficient per blendshape (zero where a
        # blendshape does not use it), so the kernel costs the union, not the sum, of the vectors.
        columns, coefs, groups = [], [], []
        start = 0
        for g in np.unique(self.gamma):
            members = np.flatnonzero(self.gamma == g)
            stacked = np.vstack([self.support_vectors[b] for b in members])
            union, where = np.unique(stacked, axis=0, return_inverse=True)
            coef = np.zeros((len(union), len(members)))
            ends = np.cumsum([0] + [self.dual_coef[b].size for b in members])
            for k in range(len(members)):
                np.add.at(coef[:, k], where.ravel()[ends[k]:ends[k + 1]], self.dual_coef[members[k]])
            columns.append(np.vstack([2.0 * g * union.T, -g * np.einsum("ij,ij->i", union, union)[None, :],
                                      np.full((1, len(union)), -g)]))
            coefs.append(coef.astype(np.float32))
            groups.append((slice(start, start + len(union)), members))
            start += len(union)
        self._single = np.concatenate(columns, axis=1).astype(np.float32)
        #: per gamma: the block's columns, the (columns, members) coefficients and the blendshapes
        self._single_coef = [(cols, coef, members) for (cols, members), coef in zip(groups, coefs)]
        #: rows per block of the single-precision kernel matrix: about 2 MB, in the L2 cache
        self._single_rows = max(8, _SINGLE_BLOCK_VALUES // max(1, self._single.shape[1]))

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
            Evaluate the kernels in float32 (all blendshapes in one block of rows at a time: one
            product, one ``exp``, each distinct support vector of a gamma once, however many
            blendshapes use it): 6.5x faster than float64 for the benchmark's crowd (8,996 support
            vectors, 2,300 distinct), but each kernel term is rounded to
            float32, so the error grows with the dual coefficients: at most
            :data:`SINGLE_PRECISION_ERROR_PER_ALPHA` (6e-8) x sum |alpha| per blendshape (measured
            2-3e-8 x: 6.5e-3 of the weight range over the training range of the benchmark's C = 100
            model, 2,250 support vectors per blendshape and sum |alpha| = 2.2e5; 8e-4 on its crowd;
            1e-12 in float64). Off by default.

        Returns
        -------
        ndarray, shape (n, B)
            The SVR outputs (not clipped; see :func:`apply_expressiveness`).
        """
        z = self.standardise(features)
        if single_precision:
            return self._predict_single(z) + self.intercept
        zz = np.einsum("ij,ij->i", z, z)
        out = np.empty((z.shape[0], self.n_outputs))
        for start in range(0, z.shape[0], _CHUNK_ROWS):
            rows = slice(start, start + _CHUNK_ROWS)
            for b, block in enumerate(self._blocks):
                sv2g, bias, gamma, coef = block
                out[rows, b] = _rbf_block(z[rows], zz[rows], sv2g, bias, gamma, coef, _MAX_FACTORED_EXPONENT)
        return out + self.intercept

    def _predict_single(self, z: np.ndarray) -> np.ndarray:
        """The kernel sums (n, B) in float32 for standardised rows z: per block of rows, one product
        gives every exponent of every distinct (support vector, gamma), one ``exp`` in place, one
        product with the (vectors, blendshapes) coefficients per gamma."""
        n_rows, n_features = z.shape
        z_aug = np.empty((n_rows, n_features + 2), dtype=np.float32)
        z_aug[:, :n_features] = z
        z_aug[:, n_features] = 1.0
        z_aug[:, n_features + 1] = np.einsum("ij,ij->i", z, z)
        out = np.empty((n_rows, self.n_outputs), dtype=np.float32)
        kernel = np.empty((min(self._single_rows, n_rows), self._single.shape[1]), dtype=np.float32)
        one_group = len(self._single_coef) == 1
        for start in range(0, n_rows, self._single_rows):
            rows = slice(start, start + self._single_rows)
            block = kernel[:len(z_aug[rows])]
            np.matmul(z_aug[rows], self._single, out=block)
            np.exp(block, out=block)
            for columns, coef, members in self._single_coef:
                if one_group:
                    np.matmul(block, coef, out=out[rows])
                else:
                    out[rows, members] = block[:, columns] @ coef
        return out.astype(np.float64)

    def kernel_sums(self, z: np.ndarray) -> np.ndarray:
        """The outputs without the intercepts, (n, B), for standardised rows ``z`` (float64)."""
        return self.predict(z * self.scaler_scale + self.scaler_mean) - self.intercept

    def surrogate(self, max_error: float = SURROGATE_MAX_ERROR) -> SvrSurrogate | None:
        """The compact surrogate of this model (:class:`SvrSurrogate`), fitted once and kept; None
        when none within ``max_error`` is much cheaper than the model itself."""
        cache: dict[float, SvrSurrogate | None] = self.__dict__.setdefault("_surrogates", {})
        if max_error not in cache:
            cache[max_error] = SvrSurrogate.fit(self, max_error)
        return cache[max_error]

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


# --------------------------------------------------------------------------- compact surrogate

class SvrSurrogate:
    """A compact stand-in for an :class:`SvrModel` in crowds: far fewer Gaussian centres, fitted to
    the model's outputs, on the model's training range; the exact model outside it.

    ``f_b(x) ~ sum_g sum_k w_bgk exp(-gamma_g |z - c_k|^2) + w_b0``: the SVR's kernel widths gamma_g, on
    M centres spread uniformly (fixed seed) over the box of the support vectors (standardised
    features: the training range), weights by least squares on the exact outputs at the support
    vectors and at 8 M uniform points of the box. M starts at :data:`SURROGATE_FIRST_CENTRES` and
    doubles until the largest error on held-out points (8,192 uniform ones and a 7 x 7 x 7 x 7 grid
    of the box) is at most ``max_error`` (:data:`SURROGATE_MAX_ERROR`), as long as the surrogate
    stays cheaper than :data:`SURROGATE_MAX_COST_SHARE` of the model. Rows outside the box get the
    exact model. Fitting takes about 1-2 s for 8,000 support vectors (:meth:`SvrModel.surrogate`
    does it once per model). Use :meth:`SvrModel.surrogate`.

    Attributes
    ----------
    box_lo, box_hi : ndarray, shape (F,)
        The (widened) training range, standardised.
    n_centres : int
    max_error : ndarray, shape (B,)
        The largest |surrogate - exact| found on the held-out points, per blendshape.
    """

    def __init__(self, exact: SvrModel, centres: np.ndarray, weights: np.ndarray,
                 box: tuple[np.ndarray, np.ndarray], max_error: np.ndarray) -> None:
        self.exact = exact
        self.box_lo, self.box_hi = box
        self.n_centres = len(centres)
        self.max_error = max_error
        self._weights = weights  # (M + 1, B): centres, then the intercept
        self._centres = _exponent_block(centres, exact.gamma)

    @property
    def n_outputs(self) -> int:
        """Number of blendshapes B."""
        return self.exact.n_outputs

    @classmethod
    def fit(cls, exact: SvrModel, max_error: float = SURROGATE_MAX_ERROR, seed: int = 0) -> SvrSurrogate | None:
        """Fit the smallest surrogate within ``max_error`` (see the class); None if it would not be
        much cheaper than ``exact``."""
        support = np.vstack(exact.support_vectors)
        lo, hi = support.min(axis=0), support.max(axis=0)
        box = (lo - SURROGATE_BOX_MARGIN * (hi - lo), hi + SURROGATE_BOX_MARGIN * (hi - lo))
        rng = np.random.default_rng(seed)
        held = np.vstack([_uniform(rng, box, 8192), _grid(box, 7)])
        held_y = exact.kernel_sums(held)
        n_kernels = len(np.unique(exact.gamma))
        n_centres = SURROGATE_FIRST_CENTRES
        while n_centres <= SURROGATE_MAX_CENTRES \
                and n_centres * n_kernels <= SURROGATE_MAX_COST_SHARE * len(support):
            centres = _uniform(rng, box, n_centres)
            points = np.vstack([support, _uniform(rng, box, 8 * n_centres)])
            design = _design(points, _exponent_block(centres, exact.gamma))
            weights = np.linalg.lstsq(design, exact.kernel_sums(points) + exact.intercept, rcond=1e-12)[0]
            error = np.max(np.abs(_design(held, _exponent_block(centres, exact.gamma)) @ weights
                                  - exact.intercept - held_y), axis=0)
            if error.max() <= max_error:
                return cls(exact, centres, weights, box, error)
            n_centres *= 2
        return None

    def predict(self, features: Any, *, single_precision: bool = False) -> np.ndarray:
        """Normalised weights (n, B) for rows of [w, p, NHR, EPOC_norm]: the surrogate inside the
        training range (float64), the exact model (in ``single_precision`` if asked) outside."""
        x = _features(features)
        z = self.exact.standardise(x)
        inside = np.all((z >= self.box_lo) & (z <= self.box_hi), axis=1)
        if inside.all():
            return self._inside(z)
        out = np.empty((len(z), self.n_outputs))
        out[inside] = self._inside(z[inside])
        out[~inside] = self.exact.predict(x[~inside], single_precision=single_precision)
        return out


    def _inside(self, z: np.ndarray) -> np.ndarray:
        """The surrogate's outputs (n, B) for standardised rows inside the box."""
        out = _kernels(z, self._centres) @ self._weights[:-1]
        out += self._weights[-1]
        return out


def _uniform(rng: np.random.Generator, box: tuple[np.ndarray, np.ndarray], n: int) -> np.ndarray:
    """``n`` points drawn uniformly in the box (lo, hi)."""
    lo, hi = box
    return lo + (hi - lo) * rng.uniform(size=(n, lo.size))


def _grid(box: tuple[np.ndarray, np.ndarray], n: int) -> np.ndarray:
    """The regular grid of ``n`` points per axis spanning the box (lo, hi), as rows."""
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(*box)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))


def _exponent_block(centres: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """The (F + 2, G M) block whose product with [z, 1, |z|^2] is -gamma |z - c|^2 for every centre
    c and each of the G distinct gammas."""
    return np.hstack([np.vstack([2.0 * g * centres.T, -g * np.einsum("ij,ij->i", centres, centres)[None, :],
                                 np.full((1, len(centres)), -g)]) for g in np.unique(gamma)])


def _kernels(z: np.ndarray, block: np.ndarray) -> np.ndarray:
    """Kernel values (n, G M) of every centre and width for standardised rows z (every blendshape
    may use every width's kernels)."""
    z_aug = np.empty((len(z), z.shape[1] + 2))
    z_aug[:, :-2], z_aug[:, -2], z_aug[:, -1] = z, 1.0, np.einsum("ij,ij->i", z, z)
    kernels = z_aug @ block
    return np.exp(np.minimum(kernels, 0.0, out=kernels), out=kernels)


def _design(z: np.ndarray, block: np.ndarray) -> np.ndarray:
    """The least-squares design: :func:`_kernels` and a column of ones (the intercept)."""
    return np.hstack([_kernels(z, block), np.ones((len(z), 1))])


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
    exertion_from_work : bool
        Exertion follows the work rate w (1 s window, the sustained effort the Compendium's METs
        describe; default) rather than the power p (0.25 s window), which rises and falls inside
        every repetition: on jumping jacks the squint swung 0.17 peak to peak inside a repetition
        (0.48 of its mean) with p, 0.04 (0.10) with w (SCIENCE_NOTES "The built-in face follows
        sustained effort"). ``False`` gives the earlier behaviour. The onset and half-saturation
        keep their values: in steady rhythmic work w and p have the same mean.
    """

    p_onset_w_per_kg: float = 3.0
    p_half_w_per_kg: float = 8.0
    fatigue_epoc_share: float = 0.3
    mouth_open_from_nhr: float = 0.4
    mouth_open_full_nhr: float = 0.95
    squint_relax_from: float = 0.5
    squint_relax_to: float = 0.9
    squint_residual: float = 0.25
    exertion_from_work: bool = True


class RuleFaceModel:
    """The paper's empirical rules as a face model (no training, deterministic).

    - exertion follows the work rate w (``RuleParams.exertion_from_work``; the power p before):
      ``e / (e + p_half)`` with ``e = max(w - p_onset, 0)``; loads raise w, so expression grows with
      displaced mass;
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
        effort = np.maximum(x[:, 0 if q.exertion_from_work else 1] - q.p_onset_w_per_kg, 0.0)
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
