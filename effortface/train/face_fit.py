"""Face models (SCIENCE.md section 5): expressiveness, four RBF epsilon-SVRs, evaluation like the paper.

Input is the per-second training table of :mod:`effortface.train.dataset` (one row per participant-second with
``participant, session, t_s, w_per_kg, p_per_kg, nhr, epoc_norm``, an optional ``exercise`` and one
column per blendshape, NaN where not annotated).

- **Expressiveness.** For each participant and blendshape, ``e_b`` = the maximal key-framed weight;
  the SVR learns ``y / e_b``. A participant who never showed a blendshape (``e_b`` below
  ``MIN_EXPRESSIVENESS``) keeps ``e_b = MIN_EXPRESSIVENESS`` so the division stays bounded (choice).
- **Features.** ``[w, p, NHR, EPOC_norm]`` standardised by a scaler fitted on the training rows;
  seconds without a measured heart rate (no NHR) are left out.
- **Hyper-parameters.** A grid over C, gamma and epsilon, scored by mean squared error averaged over
  the folds of leave-one-participant-out CV (the default; ``cv="kfold"`` random-frame folds exist only
  to show how autocorrelated frames inflate the score). gamma is always a number, never ``"scale"``.
- **Every annotated second (choice).** All rows are used by default (``max_rows_per_participant``
  = 3,600, one hour at 1 Hz; ``--max-rows`` raises it; ``max_total_rows`` is an optional total cap).
  Up to :data:`EXACT_MAX_ROWS` face rows the models are exact RBF epsilon-SVRs (libsvm, whose cost
  grows with the square of the rows); above it, every fit of the run (grid search, final fit,
  protocols) is a **Nystroem kernel approximation**: up to ``n_landmarks`` training rows picked by
  randomly pivoted Cholesky (seeded; no near-duplicates, :func:`select_landmarks`) and kernel ridge
  regression restricted to them, ``f(z) = K(z, landmarks) @ coef + b`` minimising
  ``sum (y - f)^2 + (n / 3000) (1 / C) f'K f`` (the squared-loss twin of the SVR's objective; the
  penalty grows with the rows n so that C keeps its meaning, the one it has for an exact SVR at the
  3,000-row switch, and the coefficients stay small enough for a float32 graph, issue 26; epsilon
  does not enter it). The ridge is solved in an orthonormal basis of the landmarks (``K_mm = L L'``,
  features ``K(z, landmarks) L^-T``). It is the same graph as an SVR (landmarks
  as support vectors, ``coef`` as dual coefficients), so ``svr.npz``, the runtime and face.onnx
  evaluate it unchanged. Its cost is linear in the rows (normal equations summed in chunks, memory
  independent of the rows). ``tests/train/test_face_scale.py`` checks it against exact SVR.
- **Speed (choices).** Leave-one-participant-out becomes participant-grouped ``max_folds``-fold CV for
  large labs. For exact SVRs each fold's scaler and, per gamma, its RBF Gram matrices are computed
  once and shared by every C, epsilon and blendshape (``SVR(kernel="precomputed")``). The folds and
  the final fits (one per blendshape) run through :func:`effortface.synth.parallel.map_ordered` (in
  this process, or on a Dask cluster with identical results: every fit single-threaded, so the
  model does not depend on the machine's core count either). Held-out scores reuse the
  hyper-parameters the same CV chose (not nested CV), which is slightly optimistic; the headline
  score "as a game uses it" (:mod:`effortface.train.game_score`) nests the search and measures that.
"""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import pandas as pd
from scipy.linalg import blas, solve_triangular
from sklearn.linear_model import LinearRegression
from sklearn.metrics.pairwise import rbf_kernel
from sklearn.model_selection import GroupKFold, KFold, LeaveOneGroupOut
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVR

from effortface.core.errors import UserError
from effortface.synth.face import FEATURE_NAMES
from effortface.synth.parallel import map_ordered

#: the SVR inputs, in order (units: W/kg, W/kg, 1, 1): the runtime's own list
FEATURES = FEATURE_NAMES
#: floor of an expressiveness value (choice, see module docstring)
MIN_EXPRESSIVENESS = 0.05
#: hyper-parameter grids on standardised features. "paper" is wider (32 points, about 15x the
#: time of "small"); it stops at C = 100 because one libsvm fit at C = 1000, gamma = 1 takes
#: about 4 s on the sample lab (0.04 s at C = 1). The paper's C 1e3-1e6 and gamma 1e-5-1e-2 were
#: on unstandardised features, so they do not transfer.
GRIDS: dict[str, dict[str, list[float]]] = {
    "small": {"C": [1.0, 10.0], "gamma": [0.1, 0.5], "epsilon": [0.05]},
    "paper": {"C": [0.1, 1.0, 10.0, 100.0], "gamma": [0.01, 0.05, 0.2, 1.0], "epsilon": [0.02, 0.1]},
}
CV_CHOICES = ("lopo", "kfold")


#: the fewest face-training rows per participant any fit accepts (train, demo and the Train stage check it)
MIN_ROWS_PER_PARTICIPANT = 20
#: The documented switch: exact RBF SVRs up to this many face rows, the Nystroem approximation above
#: (an exact fit on 3,000 rows takes about 0.3 s; libsvm's cost grows with the square of the rows).
EXACT_MAX_ROWS = 3000
#: Landmarks of the Nystroem approximation (measured: held-out RMSE within 1 % of exact SVR).
N_LANDMARKS = 300
#: the two kinds of face model of a fit (model.json provenance ``face_fit.method``)
METHODS = ("exact_svr", "nystroem")
#: rows per chunk when the approximation sums its normal equations (bounds the memory)
_CHUNK_ROWS = 16384
#: rows per chunk when the approximation predicts: its (rows x landmarks) kernel and the distance
#: temporaries behind it stay a few MB whatever the rows (issue 26: a prediction over all rows at
#: once cost about 3 KB of peak memory per row)
PREDICT_CHUNK_ROWS = 4096


@dataclasses.dataclass(frozen=True)
class FaceFitConfig:
    """Settings of a face fit (every choice a named parameter).

    Parameters
    ----------
    grid : dict
        Lists of ``C``, ``gamma`` and ``epsilon`` to search.
    cv : {"lopo", "kfold"}
        Leave-one-participant-out (default) or random-frame K-fold (inflated; for comparison only).
    n_splits : int
        Folds for ``cv="kfold"``.
    max_rows_per_participant : int
        Cap on training rows per participant (evenly spaced in time; 3,600 = one hour at 1 Hz).
    max_total_rows : int or None
        Optional cap on all training rows: the per-participant cap shrinks to ``max_total_rows / P``
        (None, the default: no total cap).
    max_folds : int
        With more participants than this, ``cv="lopo"`` becomes participant-grouped K-fold
        (``GroupKFold(max_folds)``), so the number of fits stops growing with the lab.
    seed : int
        Seed for the K-fold shuffle and the Nystroem landmarks.
    exact_max_rows : int
        Exact SVRs up to this many face rows, the Nystroem approximation above
        (:data:`EXACT_MAX_ROWS`).
    n_landmarks : int
        Landmarks of the approximation (:data:`N_LANDMARKS`).
    """

    grid: dict = dataclasses.field(default_factory=lambda: dict(GRIDS["small"]))
    cv: str = "lopo"
    n_splits: int = 5
    max_rows_per_participant: int = 3600
    max_total_rows: int | None = None
    max_folds: int = 8
    seed: int = 0
    exact_max_rows: int = EXACT_MAX_ROWS
    n_landmarks: int = N_LANDMARKS

    def rows_per_participant(self, n_participants: int) -> int:
        """The effective per-participant cap for a lab of ``n_participants``."""
        if self.max_total_rows is None:
            return max(MIN_ROWS_PER_PARTICIPANT, self.max_rows_per_participant)
        per_share = self.max_total_rows // max(n_participants, 1)
        return max(MIN_ROWS_PER_PARTICIPANT, min(self.max_rows_per_participant, per_share))

    def method(self, n_rows: int) -> str:
        """``"exact_svr"`` for at most :attr:`exact_max_rows` face rows, else ``"nystroem"``."""
        return METHODS[0] if n_rows <= self.exact_max_rows else METHODS[1]

    def n_folds(self, n_participants: int) -> int:
        """Cross-validation folds of a face fit on ``n_participants`` (the splits of :func:`cv_folds`)."""
        return min(n_participants, self.max_folds) if self.cv == "lopo" else self.n_splits

    def __post_init__(self) -> None:
        if self.cv not in CV_CHOICES:
            raise ValueError(f"cv: expected one of {CV_CHOICES}, found {self.cv!r}")
        for key in ("C", "gamma", "epsilon"):
            vals = self.grid.get(key)
            if not vals or not all(isinstance(v, (int, float)) and v > 0 for v in vals):
                raise ValueError(f"grid[{key!r}]: expected a list of positive numbers, found {vals!r}")


# --------------------------------------------------------------------------- data preparation


def expressiveness(table: pd.DataFrame, blendshapes: Sequence[str]) -> pd.DataFrame:
    """Expressiveness vectors: the maximal key-framed weight per participant and blendshape.

    Parameters
    ----------
    table : DataFrame
        Training table with ``participant`` and the blendshape columns.
    blendshapes : sequence of str
        Blendshape column names.

    Returns
    -------
    DataFrame
        Index: participant; columns: blendshapes; values floored at ``MIN_EXPRESSIVENESS``.
    """
    e = table.groupby("participant", sort=False, observed=True)[list(blendshapes)].max()
    return e.fillna(MIN_EXPRESSIVENESS).clip(lower=MIN_EXPRESSIVENESS)


def subsample(table: pd.DataFrame, max_rows_per_participant: int) -> pd.DataFrame:
    """At most ``max_rows_per_participant`` rows per participant, evenly spaced in time."""
    parts = []
    for _, rows in table.groupby("participant", sort=False, observed=True):
        rows = rows.sort_values(["session", "t_s"])
        if len(rows) > max_rows_per_participant:
            idx = np.linspace(0, len(rows) - 1, max_rows_per_participant).round().astype(int)
            rows = rows.iloc[np.unique(idx)]
        parts.append(rows)
    return pd.concat(parts).reset_index(drop=True)


@dataclasses.dataclass
class FaceData:
    """Arrays for fitting: features, normalised targets (NaN = not annotated), groups, expressiveness."""

    x: np.ndarray            # (n, 4) raw features
    y_norm: np.ndarray       # (n, B) weight / e_b
    e: np.ndarray            # (n, B) the row's participant expressiveness
    groups: np.ndarray       # (n,) participant codes (object arrays of shared strings: shared_labels)
    exercise: np.ndarray     # (n,) exercise labels
    t_s: np.ndarray
    session: np.ndarray
    blendshapes: tuple[str, ...]

    def __setstate__(self, state: dict) -> None:
        """Unpickle with every array aligned: a Dask worker may receive an array at any byte offset,
        where numpy takes slower loops and a sum may group its terms differently."""
        self.__dict__.update({key: value.copy(order="K")
                              if isinstance(value, np.ndarray) and not value.flags.aligned else value
                              for key, value in state.items()})


def face_data(table: pd.DataFrame, blendshapes: Sequence[str],
              e_table: pd.DataFrame | None = None) -> FaceData:
    """Arrays from a training table; ``e_table`` defaults to the table's own expressiveness."""
    blendshapes = tuple(blendshapes)
    e_table = expressiveness(table, blendshapes) if e_table is None else e_table
    e = e_table.loc[table["participant"], list(blendshapes)].to_numpy(float)
    y = table[list(blendshapes)].to_numpy(float)
    exercise = table["exercise"] if "exercise" in table else table["session"]
    return FaceData(table[list(FEATURES)].to_numpy(float), np.clip(y / e, 0.0, 1.0), e,
                    shared_labels(table["participant"]), shared_labels(exercise),
                    table["t_s"].to_numpy(float), shared_labels(table["session"]), blendshapes)


def shared_labels(values: pd.Series) -> np.ndarray:
    """Text labels as an object array whose rows share one string per distinct value.

    The values and their order are those of ``values.to_numpy(str)`` (a missing value reads
    ``"nan"``), in 8 bytes a row: a fixed-width numpy string array holds every character of every
    row (108 bytes a row for a 27-character session id).
    """
    codes, uniques = pd.factorize(values, sort=True)
    return np.array([str(u) for u in uniques] + ["nan"], dtype=object)[codes]


# --------------------------------------------------------------------------- folds and search


def cv_folds(data: FaceData, cv: str = "lopo", n_splits: int = 5, seed: int = 0, max_folds: int = 8
             ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Train/test index pairs: leave one participant out (participant-grouped ``max_folds``-fold
    beyond ``max_folds`` participants), or shuffled random-frame K-fold."""
    idx = np.arange(len(data.groups))
    if cv == "lopo":
        n_groups = len(np.unique(data.groups))
        if n_groups < 2:
            raise ValueError("cv: leave-one-participant-out needs >= 2 participants")
        splitter = LeaveOneGroupOut() if n_groups <= max_folds else GroupKFold(max_folds)
        return list(splitter.split(idx, groups=data.groups))
    return list(KFold(n_splits, shuffle=True, random_state=seed).split(idx))


def _fold_kernels(x: np.ndarray, train: np.ndarray, test: np.ndarray, gammas: Sequence[float]
                  ) -> Iterator[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per gamma: Gram matrices of the fold (scaler fitted on the training rows only)."""
    scaler = StandardScaler().fit(x[train])
    xs_tr, xs_te = scaler.transform(x[train]), scaler.transform(x[test])
    for gamma in gammas:
        yield gamma, rbf_kernel(xs_tr, xs_tr, gamma=gamma), rbf_kernel(xs_te, xs_tr, gamma=gamma), \
            xs_tr, xs_te


# --------------------------------------------------------------------------- the approximation


class LandmarkRegressor:
    """A fitted Nystroem kernel approximation: ``K(z, landmarks) @ coef + b`` (see the module docstring).

    It has the attributes of a fitted scikit-learn ``SVR`` that the export reads
    (``support_vectors_`` = the landmarks, ``dual_coef_`` (1, m), ``intercept_`` (1,), ``C``,
    ``gamma``, ``epsilon``), so the bundle, the runtime and face.onnx take it as they take an SVR.
    """

    def __init__(self, landmarks: np.ndarray, coef: np.ndarray, intercept: float, C: float,
                 gamma: float, epsilon: float) -> None:
        self.support_vectors_ = np.asarray(landmarks, dtype=float)
        self.dual_coef_ = np.asarray(coef, dtype=float).reshape(1, -1)
        self.intercept_ = np.array([float(intercept)])
        self.C, self.gamma, self.epsilon = float(C), float(gamma), float(epsilon)

    def predict(self, xs: np.ndarray) -> np.ndarray:
        """Predictions for standardised rows ``xs`` (n, F), in chunks of :data:`PREDICT_CHUNK_ROWS`."""
        return kernel_products(xs, self.support_vectors_, self.gamma, [self.dual_coef_[0]])[0] \
            + self.intercept_[0]


def _landmark_kernel(xs: np.ndarray, landmarks: np.ndarray, gamma: float) -> np.ndarray:
    """RBF kernel (n, m) of rows against landmarks."""
    return rbf_kernel(xs, landmarks, gamma=gamma)


def kernel_products(xs: np.ndarray, landmarks: np.ndarray, gamma: float,
                    weights: Sequence[np.ndarray]) -> list[np.ndarray]:
    """``K(xs, landmarks) @ w`` for every ``w`` of ``weights``, over chunks of
    :data:`PREDICT_CHUNK_ROWS` rows: the kernel is never held for all rows at once.

    Parameters
    ----------
    xs : ndarray, shape (n, F)
        Standardised rows.
    landmarks : ndarray, shape (m, F)
    gamma : float
        RBF gamma.
    weights : sequence of ndarray, each shape (m,) or (m, k)

    Returns
    -------
    list of ndarray
        One product per weight, shape (n,) or (n, k).
    """
    out = [np.empty((len(xs), *np.shape(w)[1:])) for w in weights]
    for start in range(0, len(xs), PREDICT_CHUNK_ROWS):
        rows = slice(start, start + PREDICT_CHUNK_ROWS)
        k = _landmark_kernel(xs[rows], landmarks, gamma)
        for product, w in zip(out, weights):
            product[rows] = k @ w
    return out


def landmark_rows(n_rows: int, n_landmarks: int, seed: int) -> np.ndarray:
    """Sorted indices of ``min(n_landmarks, n_rows)`` rows drawn without replacement (seeded)."""
    m = min(n_landmarks, n_rows)
    return np.sort(np.random.default_rng(seed).choice(n_rows, m, replace=False))


#: landmarks are picked from a seeded random pool of this many times ``n_landmarks`` rows
LANDMARK_POOL_FACTOR = 10
#: the landmark pick stops early when the kernel's unexplained variance per pool row falls below
#: this (more landmarks would be near-duplicates of the chosen ones)
LANDMARK_RESIDUAL_TOL = 1e-8
#: C's meaning is kept as the rows grow: the ridge penalty is ``(n / PENALTY_REFERENCE_ROWS) / C``,
#: i.e. the data term is the mean squared error per row times this many rows; at the exact/approximate
#: switch the approximation solves the objective it always solved (issue 26)
PENALTY_REFERENCE_ROWS = EXACT_MAX_ROWS


def select_landmarks(xs: np.ndarray, n_landmarks: int, gamma: float, seed: int) -> np.ndarray:
    """Indices of the landmark rows: randomly pivoted Cholesky on a seeded pool of rows.

    Each next landmark is drawn with probability proportional to the RBF kernel's variance that
    the chosen ones leave unexplained at a row (Chen, Epperly, Tropp & Webber 2023, "randomly
    pivoted Cholesky"), so a row close to a chosen landmark is rarely chosen again: no
    near-duplicates, a well-conditioned ``K_mm`` and small landmark coefficients. The pick stops
    before ``n_landmarks`` once :data:`LANDMARK_RESIDUAL_TOL` is reached.

    Parameters
    ----------
    xs : ndarray, shape (n, F)
        Standardised rows.
    n_landmarks : int
        Landmarks wanted.
    gamma : float
        RBF gamma.
    seed : int
        Seeds the pool and the draws.

    Returns
    -------
    ndarray of int
        Sorted row indices into ``xs``.
    """
    pool = landmark_rows(len(xs), LANDMARK_POOL_FACTOR * n_landmarks, seed)
    rows = xs[pool]
    rng = np.random.default_rng(seed + 1)
    chol = np.zeros((min(n_landmarks, len(pool)), len(pool)))      # the factor's columns as rows
    residual = np.ones(len(pool))
    picked: list[int] = []
    for j in range(len(chol)):
        cumulative = np.cumsum(residual)
        if cumulative[-1] <= LANDMARK_RESIDUAL_TOL * len(pool):
            break
        i = min(int(np.searchsorted(cumulative, rng.random() * cumulative[-1], side="right")), len(pool) - 1)
        column = np.exp(-gamma * ((rows - rows[i]) ** 2).sum(axis=1)) - chol[:j, i] @ chol[:j]
        chol[j] = column / np.sqrt(residual[i])
        residual = np.clip(residual - chol[j] ** 2, 0.0, None)
        residual[i] = 0.0
        picked.append(i)
    return np.sort(pool[picked])


def landmark_basis(landmarks: np.ndarray, gamma: float) -> np.ndarray:
    """``L^-T`` of the Cholesky factor ``K_mm = L L'``: ``K(x, landmarks) @ basis`` are the
    approximation's features in an orthonormal basis of the landmarks' span (the ridge penalty
    ``coef' K_mm coef`` becomes the plain squared norm of the coefficients in that basis)."""
    k_mm = _landmark_kernel(landmarks, landmarks, gamma)
    jitter = 1e-12
    while True:
        try:
            chol = np.linalg.cholesky(k_mm + jitter * np.eye(len(k_mm)))
            break
        except np.linalg.LinAlgError:
            jitter *= 10.0
    return solve_triangular(chol, np.eye(len(k_mm)), lower=True).T


def _normal_equations(xs: np.ndarray, y: np.ndarray, landmarks: np.ndarray, gamma: float,
                      basis: np.ndarray) -> dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per distinct pattern of annotated rows: ``A'A``, ``A'Y`` and the columns of Y using it.

    ``A = [K(xs, landmarks) @ basis, 1]``; summed over chunks of rows, so the memory does not grow
    with the rows. Blendshapes annotated on the same seconds share one ``A'A``. ``basis`` is upper
    triangular, so ``K @ basis`` is a triangular product (BLAS ``trmm``) and ``A'A`` a symmetric
    rank update (``syrk``): half the floating-point work of two general products, the same sums.
    """
    finite = np.isfinite(y)
    groups: dict[bytes, list[int]] = {}
    for b in range(y.shape[1]):
        groups.setdefault(np.packbits(finite[:, b]).tobytes(), []).append(b)
    m = len(landmarks)
    sums = {key: (np.zeros((m + 1, m + 1)), np.zeros((m + 1, len(cols)))) for key, cols in groups.items()}
    for start in range(0, len(xs), _CHUNK_ROWS):
        rows = slice(start, start + _CHUNK_ROWS)
        k = np.ascontiguousarray(_landmark_kernel(xs[rows], landmarks, gamma))
        a = blas.dtrmm(1.0, basis, k.T, side=0, lower=0, trans_a=1, overwrite_b=1).T  # K @ basis, in place
        for key, cols in groups.items():
            ok = finite[rows, cols[0]]
            a_ok = a if ok.all() else a[ok]  # no copy of the chunk when every row is annotated
            y_ok = y[rows][ok][:, cols]
            ata, aty = sums[key]
            ata[:m, :m] += blas.dsyrk(1.0, a_ok.T, trans=0, lower=0)  # upper triangle
            ata[:m, m] += a_ok.sum(axis=0)
            ata[m, m] += len(a_ok)
            aty[:m] += a_ok.T @ y_ok
            aty[m] += y_ok.sum(axis=0)
    lower = np.tril_indices(m, -1)
    for ata, _ in sums.values():
        ata[m, :m] = ata[:m, m]
        ata[lower] = ata[:m, :m].T[lower]
    return {key: (*sums[key], np.array(cols)) for key, cols in groups.items()}


def _solve_landmarks(ata: np.ndarray, aty: np.ndarray, c: float) -> np.ndarray:
    """Coefficients (m + 1, k) in the orthonormal basis (the last row: intercepts) of the ridge
    ``(A'A + (n / PENALTY_REFERENCE_ROWS) / C I) w = A'Y``, n the rows (``A'A``'s last entry)."""
    m = len(ata) - 1
    lhs = ata.copy()
    lhs[np.diag_indices(m)] += float(ata[-1, -1]) / PENALTY_REFERENCE_ROWS / c
    lhs[np.diag_indices(m)] += 1e-10 * max(float(np.trace(ata)) / (m + 1), 1.0)  # jitter
    try:
        return np.linalg.solve(lhs, aty)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(lhs, aty, rcond=None)[0]


def fit_landmark_models(xs: np.ndarray, y: np.ndarray, gamma: float, cs: Sequence[float],
                        n_landmarks: int, seed: int) -> tuple[np.ndarray, dict[float, np.ndarray]]:
    """Nystroem kernel ridge fits of every column of ``y`` (NaN = not annotated) for every C.

    Landmarks by :func:`select_landmarks`; the ridge is solved in the orthonormal basis of
    :func:`landmark_basis` with the penalty ``(n / PENALTY_REFERENCE_ROWS) / C`` (issue 26: a
    fixed ``1 / C`` weakened as the rows grew, and the landmark coefficients grew to sums near 1e4,
    beyond what a float32 graph can add within 1e-4).

    Parameters
    ----------
    xs : ndarray, shape (n, F)
        Standardised features.
    y : ndarray, shape (n, k)
        Targets; each column is fitted on its finite rows.
    gamma : float
        RBF gamma.
    cs : sequence of float
        Values of C (the ridge penalty is ``(n / PENALTY_REFERENCE_ROWS) / C``).
    n_landmarks : int
        Landmarks, at most (seeded by ``seed``).
    seed : int

    Returns
    -------
    landmarks : ndarray, shape (m, F)
    coefs : dict
        C -> (m + 1, k) array: landmark coefficients, then the intercept in the last row (NaN for
        a column with fewer than two annotated rows).
    """
    landmarks = xs[select_landmarks(xs, n_landmarks, gamma, seed)]
    basis = landmark_basis(landmarks, gamma)
    coefs = {c: np.full((len(landmarks) + 1, y.shape[1]), np.nan) for c in cs}
    for ata, aty, cols in _normal_equations(xs, y, landmarks, gamma, basis).values():
        if ata[-1, -1] < 2:
            continue
        for c in cs:
            w = _solve_landmarks(ata, aty, c)
            coefs[c][:-1, cols] = basis @ w[:-1]
            coefs[c][-1, cols] = w[-1]
    return landmarks, coefs


def fit_one(xs: np.ndarray, y: np.ndarray, params: dict[str, float], method: str, n_landmarks: int,
            seed: int) -> SVR | LandmarkRegressor:
    """One blendshape's model on standardised rows: an exact RBF SVR or its approximation."""
    c, gamma, eps = float(params["C"]), float(params["gamma"]), float(params["epsilon"])
    if method == METHODS[0]:
        return SVR(kernel="rbf", C=c, gamma=gamma, epsilon=eps).fit(xs, y)
    landmarks, coefs = fit_landmark_models(xs, y[:, None], gamma, [c], n_landmarks, seed)
    return LandmarkRegressor(landmarks, coefs[c][:-1, 0], coefs[c][-1, 0], c, gamma, eps)


def fit_predict(xs: np.ndarray, targets: np.ndarray, params: Sequence[dict[str, float]], method: str,
                n_landmarks: int, seed: int, tests: Sequence[np.ndarray], min_rows: int = 2
                ) -> list[np.ndarray]:
    """Fit every column of ``targets`` with its own hyper-parameters and predict ``tests``.

    The same models as :func:`fit_one` on each column's annotated rows, one by one; with the
    approximation the columns that share gamma and annotated rows share one landmark fit (the
    landmarks depend on the rows and gamma only) and one kernel pass per test array.

    Parameters
    ----------
    xs : ndarray, shape (n, F)
        Standardised training rows.
    targets : ndarray, shape (n, B)
        Targets, NaN where not annotated.
    params : sequence of dict
        Per column: ``C``, ``gamma``, ``epsilon``.
    method : str
        ``"exact_svr"`` or ``"nystroem"``.
    n_landmarks, seed : int
        The approximation's landmarks.
    tests : sequence of ndarray, each shape (n_i, F)
        Standardised rows to predict.
    min_rows : int
        A column with fewer annotated rows is not fitted (its predictions stay NaN).

    Returns
    -------
    list of ndarray
        Per test array, predictions (n_i, B).
    """
    outs = [np.full((len(t), targets.shape[1]), np.nan) for t in tests]
    finite = np.isfinite(targets)
    shared: dict[tuple, list[int]] = {}
    for b in range(targets.shape[1]):
        if finite[:, b].sum() >= min_rows:
            key = (b,) if method == METHODS[0] else (float(params[b]["gamma"]), finite[:, b].tobytes())
            shared.setdefault(key, []).append(b)
    for cols in shared.values():
        ok = finite[:, cols[0]]
        xs_ok = xs if ok.all() else xs[ok]
        if method == METHODS[0]:
            model = fit_one(xs_ok, targets[ok, cols[0]], params[cols[0]], method, n_landmarks, seed)
            for out, t in zip(outs, tests):
                out[:, cols[0]] = model.predict(t)
            continue
        gamma, cs = float(params[cols[0]]["gamma"]), [float(params[b]["C"]) for b in cols]
        landmarks, coefs = fit_landmark_models(xs_ok, targets[ok][:, cols], gamma, sorted(set(cs)),
                                               n_landmarks, seed)
        _predict_columns(outs, cols, tests, landmarks, gamma,
                         [(coefs[c][:-1, i], coefs[c][-1, i]) for i, c in enumerate(cs)])
    return outs


def _predict_columns(outs: Sequence[np.ndarray], cols: list[int], tests: Sequence[np.ndarray],
                     landmarks: np.ndarray, gamma: float, models: Sequence[tuple[np.ndarray, float]]) -> None:
    """Fill columns ``cols`` of each ``outs[i]`` with the landmark models' predictions for ``tests[i]``
    (one kernel pass per test array for all the models; ``models``: (coef (m,), intercept) per column)."""
    weights = np.column_stack([coef for coef, _ in models])
    intercepts = np.array([intercept for _, intercept in models])
    for out, t in zip(outs, tests):
        out[:, cols] = kernel_products(t, landmarks, gamma, [weights])[0] + intercepts


# --------------------------------------------------------------------------- the search


@dataclasses.dataclass
class SearchResult:
    """Grid-search outcome for one blendshape."""

    best: dict[str, float]
    cv_mse: float
    cv_r: float
    table: list[dict[str, float]]        # one row per grid point: C, gamma, epsilon, mse
    oof: np.ndarray                      # out-of-fold normalised predictions at the best point
    baselines: dict[str, np.ndarray]     # out-of-fold "mean" and "linear" predictions
    #: per fold, (C, gamma) -> that fold's approximation (landmarks, coef (m,), intercept) for this
    #: blendshape (landmarks shared by the blendshapes and Cs of a gamma); empty for exact SVRs
    fold_models: list[dict[tuple[float, float], tuple[np.ndarray, np.ndarray, float]]] = \
        dataclasses.field(default_factory=list)


def grid_search(data: FaceData, config: FaceFitConfig,
                progress: Callable[[int], object] | None = None) -> dict[str, SearchResult]:
    """Grid search of every blendshape's model (exact SVR or the approximation, by the rows).

    The folds run through :func:`effortface.synth.parallel.map_ordered` (this process or a Dask
    cluster, same results; ``data`` and each row's fold (:func:`fold_numbers`) go to the workers
    once, a task carries its fold's number).

    Parameters
    ----------
    data : FaceData
        Training arrays.
    config : FaceFitConfig
        Grid, CV scheme and the exact/approximate switch.
    progress : callable, optional
        Called with 1 after each fold (for a progress bar).

    Returns
    -------
    dict
        Blendshape name -> :class:`SearchResult`.
    """
    folds = cv_folds(data, config.cv, config.n_splits, config.seed, config.max_folds)
    points = list(itertools.product(config.grid["C"], config.grid["gamma"], config.grid["epsilon"]))
    n, nb = data.y_norm.shape
    oof = {p: np.full((n, nb), np.nan) for p in points}
    fold_mse = {p: np.zeros((len(folds), nb)) for p in points}
    base = {k: np.full((n, nb), np.nan) for k in ("mean", "linear")}
    models: list[dict] = []
    method = config.method(n)
    fold_of = fold_numbers(folds, n)
    calls = ((f, config, method) for f in range(len(folds)))  # small tasks: the rows follow from fold_of
    results = map_ordered(_search_numbered_fold, calls, shared=(data, fold_of))
    for f, (preds, mses, baselines, fold_models) in enumerate(results):
        test = np.flatnonzero(fold_of == f)
        for p in points:
            oof[p][test] = preds[p]
            fold_mse[p][f] = mses[p]
        for k, v in baselines.items():
            base[k][test] = v
        models.append(fold_models)
        if progress:
            progress(1)
    out = {name: _best(data, b, points, oof, fold_mse, base) for b, name in enumerate(data.blendshapes)}
    if method == METHODS[1]:
        for b, name in enumerate(data.blendshapes):
            out[name].fold_models = [{(c, gamma): (landmarks, coefs[c][:-1, b], float(coefs[c][-1, b]))
                                      for gamma, (landmarks, coefs) in fold.items() for c in coefs}
                                     for fold in models]
    return out


def fold_numbers(folds: Sequence[tuple[np.ndarray, np.ndarray]], n_rows: int) -> np.ndarray:
    """Each row's test fold (int16; -1 for a row in no test fold). The folds' test rows partition
    the rows and each fold trains on all the others, so a task needs only its fold's number."""
    fold_of = np.full(n_rows, -1, dtype=np.int16)
    for f, (_, test) in enumerate(folds):
        fold_of[test] = f
    return fold_of


def _search_numbered_fold(data: FaceData, fold_of: np.ndarray, fold: int, config: FaceFitConfig,
                          method: str) -> tuple[dict, dict, dict, dict]:
    """:func:`_search_fold` of fold number ``fold`` (test rows ascending; see :func:`fold_numbers`)."""
    return _search_fold(data, np.flatnonzero(fold_of != fold), np.flatnonzero(fold_of == fold), config, method)


def nested_choices(data: FaceData, config: FaceFitConfig, folds: Sequence[tuple[np.ndarray, np.ndarray]]
                   ) -> list[dict[str, dict[str, float]]]:
    """Per outer fold, the hyper-parameters a search on that fold's training rows alone chooses.

    The search of outer fold k scores every grid point on inner folds that are the other outer
    folds: inner fold j trains on every row outside folds j and k and is scored on fold j. That
    training set is the same for (k, j) and (j, k), so each pair of folds is fitted once and
    scored on both (half the fits of searching each outer fold on its own). With leave one
    participant out (at most ``max_folds`` participants) these are exactly the folds, fits and
    choice of :func:`grid_search` run on the outer training rows; with more participants the inner
    folds are the outer participant groups. Nothing of fold k's rows enters its choice.

    Parameters
    ----------
    data : FaceData
        Every row.
    config : FaceFitConfig
        Grid and the exact/approximate switch (by each outer fold's training rows).
    folds : sequence of (train, test)
        The outer folds (disjoint test folds covering the rows).

    Returns
    -------
    list of dict
        Per outer fold: blendshape name -> ``{"C", "gamma", "epsilon"}``.
    """
    points = list(itertools.product(config.grid["C"], config.grid["gamma"], config.grid["epsilon"]))
    if len(folds) < 3:
        raise ValueError("cv: a nested search needs >= 3 participant folds")
    fold_of = fold_numbers(folds, len(data.x))
    methods = [config.method(len(train)) for train, _ in folds]
    pairs = sorted({(min(j, k), max(j, k), methods[k]) for k in range(len(folds)) for j in range(len(folds))
                    if j != k})
    calls = ((j, k, config, method) for j, k, method in pairs)  # small tasks: the rows follow from fold_of
    scores = dict(zip(pairs, map_ordered(_pair_fold_mses, calls, shared=(data, fold_of))))
    choices = []
    for k in range(len(folds)):
        inner = [j for j in range(len(folds)) if j != k]
        fold_mse = {p: np.array([scores[(min(j, k), max(j, k), methods[k])][0 if j < k else 1][p]
                                 for j in inner]) for p in points}
        choices.append({name: {key: best[key] for key in ("C", "gamma", "epsilon")}
                        for b, name in enumerate(data.blendshapes)
                        for best in [_best_point(b, points, fold_mse)[0]]})
    return choices


def _pair_fold_mses(data: FaceData, fold_of: np.ndarray, j: int, k: int, config: FaceFitConfig,
                    method: str) -> list[dict[tuple, np.ndarray]]:
    """One fit per grid point on the rows outside folds ``j`` and ``k`` (``fold_of``: each row's
    fold; :func:`_search_fold`), scored on fold j and on fold k separately: per fold, grid point ->
    MSE per blendshape (B,) (NaN where nothing to score)."""
    scored = (fold_of == j) | (fold_of == k)
    both = np.flatnonzero(scored)
    preds = _search_fold(data, np.flatnonzero(~scored), both, config, method, baselines=False)[0]
    out = []
    for fold in (j, k):
        at = fold_of[both] == fold
        y = data.y_norm[both[at]]
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a blendshape with nothing to score: NaN
            out.append({p: np.nanmean((pred[at] - y) ** 2, axis=0) for p, pred in preds.items()})
    return out


def _search_fold(data: FaceData, train: np.ndarray, test: np.ndarray, config: FaceFitConfig,
                 method: str, baselines: bool = True) -> tuple[dict, dict, dict, dict]:
    """One fold of the search: per grid point the test predictions (n_test, B) and MSEs (B,), the
    baselines' test predictions (when ``baselines``), and for the approximation the fold's fits
    (gamma -> (landmarks, {C: coefs})). A pure function of its arguments (runs anywhere)."""
    points = list(itertools.product(config.grid["C"], config.grid["gamma"], config.grid["epsilon"]))
    nb = data.y_norm.shape[1]
    preds = {p: np.full((len(test), nb), np.nan) for p in points}
    mses = {p: np.full(nb, np.nan) for p in points}
    models: dict = {}
    if method == METHODS[0]:
        for gamma, k_tr, k_te, _, _ in _fold_kernels(data.x, train, test, config.grid["gamma"]):
            for b in range(nb):
                _fit_fold(data, b, train, test, k_tr, k_te, gamma, config, preds, mses)
    else:
        models = _search_fold_landmarks(data, train, test, config, preds, mses)
    base = {k: np.full((len(test), nb), np.nan) for k in ("mean", "linear")}
    if baselines:
        _baseline_fold(data, train, test, base)
    return preds, mses, base, models


def _fit_fold(data: FaceData, b: int, train: np.ndarray, test: np.ndarray, k_tr: np.ndarray,
              k_te: np.ndarray, gamma: float, config: FaceFitConfig, preds: dict, mses: dict) -> None:
    """Fit blendshape b on one fold for every (C, epsilon) at this gamma; store predictions."""
    y = data.y_norm[:, b]
    tr, te = np.isfinite(y[train]), np.isfinite(y[test])
    if tr.sum() < 2 or te.sum() == 0:
        return
    # slice the Gram matrices once for every (C, epsilon); skip the copy when nothing is missing
    k_fit = k_tr if tr.all() else k_tr[np.ix_(tr, tr)]
    k_pred = k_te if (tr.all() and te.all()) else k_te[np.ix_(te, tr)]
    for c, eps in itertools.product(config.grid["C"], config.grid["epsilon"]):
        svr = SVR(kernel="precomputed", C=c, epsilon=eps).fit(k_fit, y[train][tr])
        pred = svr.predict(k_pred)
        preds[(c, gamma, eps)][te, b] = pred
        mses[(c, gamma, eps)][b] = float(np.mean((pred - y[test][te]) ** 2))


def _search_fold_landmarks(data: FaceData, train: np.ndarray, test: np.ndarray, config: FaceFitConfig,
                           preds: dict, mses: dict) -> dict[float, tuple[np.ndarray, dict[float, np.ndarray]]]:
    """The approximation's fold: per gamma one set of landmarks and normal equations, every C
    solved from them (epsilon does not enter the approximation: its points share the result).
    Returns the fits: gamma -> (landmarks, {C: (m + 1, B) coefficients, intercepts last})."""
    scaler = StandardScaler().fit(data.x[train])
    xs_tr, xs_te = scaler.transform(data.x[train]), scaler.transform(data.x[test])
    y_tr, y_te = data.y_norm[train], data.y_norm[test]
    te_ok = np.isfinite(y_te)
    models = {}
    for gamma in config.grid["gamma"]:
        landmarks, coefs = fit_landmark_models(xs_tr, y_tr, gamma, config.grid["C"], config.n_landmarks,
                                               config.seed)
        models[gamma] = (landmarks, coefs)
        products = dict(zip(config.grid["C"], kernel_products(xs_te, landmarks, gamma,
                                                              [coefs[c][:-1] for c in config.grid["C"]])))
        for c, eps in itertools.product(config.grid["C"], config.grid["epsilon"]):
            pred = products[c] + coefs[c][-1]
            pred[~te_ok] = np.nan
            preds[(c, gamma, eps)][:] = pred
            err = np.where(te_ok, pred - y_te, np.nan)
            with np.errstate(invalid="ignore"):
                mse = np.nanmean(err ** 2, axis=0) if te_ok.any() else np.full(len(mses[(c, gamma, eps)]), np.nan)
            mses[(c, gamma, eps)][:] = np.where(te_ok.any(axis=0) & np.isfinite(coefs[c][-1]), mse, np.nan)
    return models


def _baseline_fold(data: FaceData, train: np.ndarray, test: np.ndarray, base: dict) -> None:
    """Mean and linear-regression baselines on one fold (standardised features); ``base`` holds
    (n_test, B) arrays."""
    scaler = StandardScaler().fit(data.x[train])
    for b in range(data.y_norm.shape[1]):
        y = data.y_norm[:, b]
        tr, te = train[np.isfinite(y[train])], np.isfinite(y[test])
        if len(tr) < 2 or not te.any():
            continue
        base["mean"][te, b] = y[tr].mean()
        lin = LinearRegression().fit(scaler.transform(data.x[tr]), y[tr])
        base["linear"][te, b] = lin.predict(scaler.transform(data.x[test[te]]))


def _best_point(b: int, points: list, fold_mse: dict) -> tuple[dict[str, float], list[dict[str, float]]]:
    """Blendshape b's grid point with the lowest fold-averaged MSE (its row: C, gamma, epsilon,
    mse), and every point's row."""
    rows = [{"C": c, "gamma": g, "epsilon": e, "mse": float(np.nanmean(fold_mse[(c, g, e)][:, b]))}
            for c, g, e in points]
    return min(rows, key=lambda r: r["mse"] if np.isfinite(r["mse"]) else np.inf), rows


def _best(data: FaceData, b: int, points: list, oof: dict, fold_mse: dict, base: dict) -> SearchResult:
    """The grid point with the lowest fold-averaged MSE for blendshape b."""
    best, rows = _best_point(b, points, fold_mse)
    key = (best["C"], best["gamma"], best["epsilon"])
    y, pred = data.y_norm[:, b], oof[key][:, b]
    ok = np.isfinite(y) & np.isfinite(pred)
    r = float(np.corrcoef(y[ok], pred[ok])[0, 1]) if ok.sum() > 2 else float("nan")
    return SearchResult({k: best[k] for k in ("C", "gamma", "epsilon")}, best["mse"], r, rows,
                        pred, {k: v[:, b] for k, v in base.items()})


# --------------------------------------------------------------------------- final fit


@dataclasses.dataclass
class FaceModelFit:
    """The fitted face models and everything the export and the report need."""

    blendshapes: tuple[str, ...]
    scaler: StandardScaler
    svrs: dict[str, SVR | LandmarkRegressor]
    search: dict[str, SearchResult]
    expressiveness: pd.DataFrame
    data: FaceData
    config: FaceFitConfig

    @property
    def method(self) -> str:
        """``"exact_svr"`` or ``"nystroem"`` (chosen from the face rows, see :meth:`FaceFitConfig.method`)."""
        return self.config.method(len(self.data.x))

    def describe(self) -> dict[str, object]:
        """The choice for model.json and the model card: method, face rows, landmarks, the switch."""
        landmarks = [len(m.support_vectors_) for m in self.svrs.values()] \
            if self.method == METHODS[1] else None
        return {"method": self.method, "n_face_rows": int(len(self.data.x)),
                "exact_max_rows": int(self.config.exact_max_rows), "n_landmarks": landmarks,
                "max_rows_per_participant": int(self.config.max_rows_per_participant)}

    def predict_norm(self, x: np.ndarray) -> np.ndarray:
        """Normalised predictions (n, B) from raw features (n, 4), by scikit-learn."""
        xs = self.scaler.transform(np.asarray(x, dtype=float))
        return np.column_stack([self.svrs[b].predict(xs) for b in self.blendshapes])


def check_face_table(table: pd.DataFrame, blendshapes: Sequence[str], source: str = "table",
                     config: FaceFitConfig | None = None) -> None:
    """Refuse a prepared table the face models cannot be fitted on, before any work starts.

    Every blendshape needs key-framed weights on at least two of the seconds the fit uses (those
    with work and heart rate, after the even subsampling of :func:`subsample`).

    Parameters
    ----------
    table : DataFrame
        Prepared training table (with ``nhr`` and ``epoc_norm``).
    blendshapes : sequence of str
        Blendshape columns to model.
    source : str
        The table or sessions, for the message.
    config : FaceFitConfig, optional
        The fit's settings (its subsampling).

    Raises
    ------
    UserError
        Naming ``source`` and the first blendshape without annotations.
    """
    config = config or FaceFitConfig()
    usable = table.dropna(subset=list(FEATURES))
    kept = subsample(usable, config.rows_per_participant(usable["participant"].nunique())) \
        if len(usable) else usable
    for name in blendshapes:
        n_all, n_used = int(table[name].notna().sum()), int(kept[name].notna().sum())
        if n_used < 2:
            found = "none (the column is empty)" if n_all == 0 else \
                f"{n_used} of its {n_all} annotated seconds"
            raise UserError(f"{source}: blendshape {name}: expected key-framed weights on at least 2 "
                            f"seconds with work and heart rate, found {found}")


def fit_face_models(table: pd.DataFrame, blendshapes: Sequence[str],
                    config: FaceFitConfig | None = None,
                    progress: Callable[[int], object] | None = None) -> FaceModelFit:
    """Search hyper-parameters by grouped CV, then fit one model per blendshape on all rows.

    Exact RBF SVRs up to ``config.exact_max_rows`` face rows, the Nystroem approximation above
    (module docstring).

    Parameters
    ----------
    table : DataFrame
        Training table (see the module docstring).
    blendshapes : sequence of str
        Blendshape columns to model.
    config : FaceFitConfig, optional
        Grid, CV scheme and subsampling.
    progress : callable, optional
        Called with 1 after each CV fold.

    Returns
    -------
    FaceModelFit
    """
    config = config or FaceFitConfig()
    table = table.dropna(subset=list(FEATURES))  # seconds without a heart rate carry no NHR
    e_table = expressiveness(table, blendshapes)
    per_participant = config.rows_per_participant(table["participant"].nunique())
    data = face_data(subsample(table, per_participant), blendshapes, e_table)
    search = grid_search(data, config, progress)
    scaler = StandardScaler().fit(data.x)
    method = config.method(len(data.x))
    calls = ((scaler, b, search[name].best, method, config) for b, name in enumerate(data.blendshapes))
    svrs = dict(zip(data.blendshapes, map_ordered(_final_fit, calls, shared=(data,))))
    return FaceModelFit(tuple(blendshapes), scaler, svrs, search, e_table, data, config)


def _final_fit(data: FaceData, scaler: StandardScaler, b: int, params: dict[str, float], method: str,
               config: FaceFitConfig) -> SVR | LandmarkRegressor:
    """Blendshape b's model on every annotated row (one task of :func:`fit_face_models`)."""
    ok = np.isfinite(data.y_norm[:, b])
    return fit_one(scaler.transform(data.x[ok]), data.y_norm[ok, b], params, method, config.n_landmarks,
                   config.seed)


# --------------------------------------------------------------------------- metrics


def weight_metrics(y: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """Pearson r and RMSE in % of the observed range and in % of [0, 1] (NaN rows skipped)."""
    ok = np.isfinite(y) & np.isfinite(pred)
    y, pred = y[ok], pred[ok]
    if len(y) < 3:
        return {"r": float("nan"), "rmse_pct_range": float("nan"), "rmse_pct_unit": float("nan"), "n": len(y)}
    rmse = float(np.sqrt(np.mean((y - pred) ** 2)))
    r = float(np.corrcoef(y, pred)[0, 1]) if np.std(y) > 0 and np.std(pred) > 0 else 0.0
    span = float(np.ptp(y)) or 1.0
    return {"r": r, "rmse_pct_range": 100 * rmse / span, "rmse_pct_unit": 100 * rmse, "n": int(len(y))}


def training_expressiveness(data: FaceData, train: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Expressiveness of ``rows`` estimated from the training rows only (no label of ``rows`` used).

    A participant with annotated training rows gets the maximal key-framed weight of those rows; a
    participant absent from the training rows (a held-out participant) gets the mean expressiveness
    of the training participants. Floored at ``MIN_EXPRESSIVENESS``.

    Parameters
    ----------
    data : FaceData
    train, rows : ndarray of int
        Indices of the training rows and of the rows to give an expressiveness to.

    Returns
    -------
    ndarray, shape (len(rows), B)
    """
    weights = pd.DataFrame(data.y_norm[train] * data.e[train], columns=data.blendshapes)
    own = weights.groupby(data.groups[train], sort=False).max()
    own = own.fillna(MIN_EXPRESSIVENESS).clip(lower=MIN_EXPRESSIVENESS)
    e = own.reindex(data.groups[rows]).to_numpy(float, copy=True)
    unseen = np.isnan(e)
    e[unseen] = np.broadcast_to(own.mean().to_numpy(float), e.shape)[unseen]
    return e


def held_out_predictions(fit: FaceModelFit, known_expressiveness: bool = False) -> np.ndarray:
    """Out-of-fold SVR weights (n, B): normalised predictions x expressiveness, clipped to [0, 1].

    By default each fold's expressiveness is estimated without the scored rows' labels
    (:func:`training_expressiveness`: for a held-out participant, the training participants'
    mean), so the prediction for a participant never depends on that participant's key-frames.
    ``known_expressiveness=True`` multiplies by the participant's own maximal key-framed weight
    instead (what a user who knows the actor's expressiveness gets; it borrows from the labels).
    """
    norm = np.column_stack([fit.search[b].oof for b in fit.blendshapes])
    return np.clip(norm * _fold_expressiveness(fit, known_expressiveness), 0.0, 1.0)


def _fold_expressiveness(fit: FaceModelFit, known: bool) -> np.ndarray:
    """Per row, the expressiveness its out-of-fold prediction is multiplied by."""
    d = fit.data
    if known:
        return d.e
    e = np.full(d.e.shape, np.nan)
    c = fit.config
    for train, test in cv_folds(d, c.cv, c.n_splits, c.seed, c.max_folds):
        e[test] = training_expressiveness(d, train, test)
    return e


#: Model labels of :func:`held_out_scores` (``svr`` is the headline; the last borrows from the labels).
HELD_OUT_MODELS = ("svr", "mean", "linear", "svr_known_expressiveness")


def held_out_scores(fit: FaceModelFit) -> pd.DataFrame:
    """Per blendshape and model: out-of-fold metrics on the weight scale (the key-framed weights).

    Models ``svr``, ``mean`` and ``linear`` multiply their normalised predictions by an
    expressiveness estimated without the scored participant's labels (the training participants'
    mean; at run time the user supplies it): the headline scores. ``svr_known_expressiveness``
    multiplies the same SVR predictions by the participant's own maximal key-framed weight: the
    score when the actor's expressiveness is known, which borrows from the test labels.
    """
    e_est, e_known = _fold_expressiveness(fit, False), _fold_expressiveness(fit, True)
    rows = []
    for b, name in enumerate(fit.blendshapes):
        y = fit.data.y_norm[:, b] * fit.data.e[:, b]
        s = fit.search[name]
        for model, pred, e in (("svr", s.oof, e_est), ("mean", s.baselines["mean"], e_est),
                               ("linear", s.baselines["linear"], e_est),
                               ("svr_known_expressiveness", s.oof, e_known)):
            rows.append({"blendshape": name, "model": model,
                         **weight_metrics(y, np.clip(pred * e[:, b], 0, 1))})
    return pd.DataFrame(rows)


#: The paper's face figure: training (in-sample) RMSE of 17-26 % per blendshape.
PAPER_FACE_TRAINING_RMSE_PCT = (17.0, 26.0)


def training_scores(fit: FaceModelFit) -> pd.DataFrame:
    """In-sample metrics of the final SVRs on their own training rows (the paper's "training RMSE").

    Weight scale: normalised predictions x each participant's own expressiveness (in-sample, the
    labels are the training labels), against the key-framed weights. Labelled ``svr_in_sample``.
    """
    pred = np.clip(fit.predict_norm(fit.data.x) * fit.data.e, 0.0, 1.0)
    y = fit.data.y_norm * fit.data.e
    return pd.DataFrame([{"blendshape": name, "model": "svr_in_sample", **weight_metrics(y[:, b], pred[:, b])}
                         for b, name in enumerate(fit.blendshapes)])


# --------------------------------------------------------------------------- the paper's Fig. 3 protocols

PROTOCOLS = ("same_participant_exercise", "unseen_participant", "unseen_exercise")


def _protocol_folds(data: FaceData, protocol: str, n_blocks: int = 5, max_folds: int = 8
                    ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Folds for one protocol (see :func:`protocol_scores`)."""
    idx = np.arange(len(data.groups))
    if protocol == "unseen_participant":
        return cv_folds(data, "lopo", max_folds=max_folds)
    if protocol == "unseen_exercise":
        if len(np.unique(data.exercise)) < 2:
            return []
        return list(LeaveOneGroupOut().split(idx, groups=data.exercise))
    folds = []
    for rows in _rows_by_participant_exercise(data):
        rows = rows[np.argsort(data.t_s[rows], kind="stable")]
        for block in np.array_split(rows, n_blocks):  # contiguous blocks of time
            if len(block) and len(rows) - len(block) > 10:
                folds.append((np.setdiff1d(rows, block), block))
    return folds


def _rows_by_participant_exercise(data: FaceData) -> list[np.ndarray]:
    """Row indices (ascending) of each participant-exercise pair, pairs in sorted order; one pass
    over the rows (issue 26: a string comparison over all rows per pair grew as rows x pairs)."""
    keys = np.char.add(np.char.add(data.groups.astype(str), "|"), data.exercise.astype(str))
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    order = np.argsort(inverse.ravel(), kind="stable")
    return np.split(order, np.cumsum(counts)[:-1])


def protocol_scores(fit: FaceModelFit, protocols: Sequence[str] = PROTOCOLS) -> tuple[pd.DataFrame, dict]:
    """The paper's Fig. 3 protocols with the chosen hyper-parameters.

    - ``same_participant_exercise``: one model per participant and exercise, each contiguous fifth of
      the time predicted from the other four fifths;
    - ``unseen_participant``: trained on everyone else (leave one participant out); with the
      approximation and the default participant folds, by the search's own fits of each fold at the
      chosen point (:func:`search_fit_predictions`: the same folds, rows and hyper-parameters,
      targets normalised by each training participant's expressiveness as in every fit), not
      fitted a second time;
    - ``unseen_exercise``: trained on every other exercise, everyone pooled (leave one exercise out).

    Returns
    -------
    scores : DataFrame
        ``protocol, blendshape, r, rmse_pct_range, rmse_pct_unit, n`` (weight scale).
    predictions : dict
        protocol -> (n, B) array of predicted weights (NaN where not predicted), for the plots.
    """
    rows, preds = [], {}
    for protocol in protocols:
        if protocol == "unseen_participant" and fit.config.cv == "lopo" and fit.method == METHODS[1]:
            pred = _unseen_participant_from_search(fit)
        else:
            pred = _predict_folds(fit, _protocol_folds(fit.data, protocol, max_folds=fit.config.max_folds))
        preds[protocol] = pred
        for b, name in enumerate(fit.blendshapes):
            y = fit.data.y_norm[:, b] * fit.data.e[:, b]
            rows.append({"protocol": protocol, "blendshape": name, **weight_metrics(y, pred[:, b])})
    return pd.DataFrame(rows), preds


def search_fit_predictions(fit: FaceModelFit, fold: int, params: Sequence[dict[str, float]],
                           tests: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Normalised predictions by the grid search's own approximation fits of one fold.

    Parameters
    ----------
    fit : FaceModelFit
        A Nystroem fit (its :attr:`SearchResult.fold_models`).
    fold : int
        The fold (in :func:`cv_folds` order of the search).
    params : sequence of dict
        Per blendshape the grid point (``C``, ``gamma``) whose fit to use.
    tests : sequence of ndarray, each shape (n_i, F)
        Rows standardised by the fold's scaler (fitted on its training rows).

    Returns
    -------
    list of ndarray
        Per test array, predictions (n_i, B); one kernel pass per gamma and test array.
    """
    by_gamma: dict[float, list[int]] = {}
    for b, p in enumerate(params):
        by_gamma.setdefault(float(p["gamma"]), []).append(b)
    outs = [np.full((len(t), len(params)), np.nan) for t in tests]
    for gamma, cols in by_gamma.items():
        models = [fit.search[fit.blendshapes[b]].fold_models[fold][(params[b]["C"], gamma)] for b in cols]
        _predict_columns(outs, cols, tests, models[0][0], gamma, [(coef, icpt) for _, coef, icpt in models])
    return outs


def _unseen_participant_from_search(fit: FaceModelFit) -> np.ndarray:
    """The unseen-participant protocol's weights (n, B) from the search's fits at the chosen point."""
    d, c = fit.data, fit.config
    out = np.full(d.y_norm.shape, np.nan)
    params = [fit.search[name].best for name in fit.blendshapes]
    for f, (train, test) in enumerate(cv_folds(d, c.cv, c.n_splits, c.seed, c.max_folds)):
        xs = StandardScaler().fit(d.x[train]).transform(d.x[test])
        norm = search_fit_predictions(fit, f, params, [xs])[0]
        out[test] = np.clip(norm * training_expressiveness(d, train, test), 0, 1)
    return out


def _predict_folds(fit: FaceModelFit, folds: list) -> np.ndarray:
    """Out-of-fold predicted weights with each blendshape's chosen hyper-parameters.

    No label of a fold's test rows is used: the training targets are normalised and the test
    predictions scaled by expressiveness estimated from the training rows
    (:func:`training_expressiveness`). Each fit is exact or approximate by the run's face rows
    (the method of ``fit``); the folds run through :func:`~effortface.synth.parallel.map_ordered`.
    """
    out = np.full(fit.data.y_norm.shape, np.nan)
    params = {name: fit.search[name].best for name in fit.blendshapes}
    calls = ((train, test, params, fit.method, fit.config) for train, test in folds)
    for (_, test), pred in zip(folds, map_ordered(_protocol_fold, calls, shared=(fit.data,))):
        out[test] = np.where(np.isnan(pred), out[test], pred)
    return out


def _protocol_fold(d: FaceData, train: np.ndarray, test: np.ndarray, params: dict[str, dict[str, float]],
                   method: str, config: FaceFitConfig) -> np.ndarray:
    """Predicted weights (n_test, B) of one protocol fold (NaN for a blendshape not fitted)."""
    scaler = StandardScaler().fit(d.x[train])
    e_train = training_expressiveness(d, train, train)
    e_test = training_expressiveness(d, train, test)
    targets = np.clip(d.y_norm[train] * d.e[train] / e_train, 0.0, 1.0)
    pred = fit_predict(scaler.transform(d.x[train]), targets, [params[name] for name in d.blendshapes], method,
                       config.n_landmarks, config.seed, [scaler.transform(d.x[test])], min_rows=5)[0]
    return np.clip(pred * e_test, 0, 1)
