"""A learned mapping where the lab has human keys: 52 scores and their short history -> the lab's keys.

The effort mapping (:mod:`effortface.annotate.machine.effort`) is a definition: it does not know how
*this* lab's raters key. Where several participants have machine-rated sessions with human
key-frames, a regressor can learn it: per blendshape, scikit-learn's ridge regression on
standardised features, its penalty chosen by leave-one-out cross-validation (``RidgeCV``,
:func:`make_regressor`), from :func:`features` (the 52 scores at the frame, and their mean over the
:data:`HISTORY_S` before it) to the human key weights, one row per (rater, keyed frame), fitted across
participants. (Gradient-boosted trees, ``HistGradientBoostingRegressor``, scored a little higher held
out on the sample lab but took about 100 s of fitting per session rated against ridge's 12 s: see
docs/guide/machine-rater-effort-mapping.md.)

It is scored **leave-one-participant-out** against the definition: for each participant with keys,
the regressor fitted on the others predicts that participant's keyed frames, and the Pearson r of
its prediction with the keys is set beside the r of the effort mapping at the same frames. A
blendshape uses the learned mapping only where its mean held-out r over the participants is higher
(:func:`choose`), with at least :data:`MIN_PARTICIPANTS` participants keyed. A session is then rated
by the regressor fitted on every *other* participant, so its own participant's keys never shaped
its rating; the per-participant isotonic calibration
(:mod:`effortface.annotate.machine.mapping`) is fitted afterwards, on the same humans' keys.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.annotate.machine.effort import EFFORT_MAPPING, NAMES, session_weights

#: the short history: the mean of each score over this many seconds before the frame
HISTORY_S = 1.0
#: the fewest participants with keys for a held-out comparison
MIN_PARTICIPANTS = 3
#: the fewest keys of a blendshape per participant for that participant's held-out r
MIN_KEYS_SCORED = 10
#: the ridge penalties tried
RIDGE_ALPHAS = (0.1, 1.0, 10.0, 100.0, 1000.0)
LEARNED_MAPPING = "learned (RidgeCV, leave-one-participant-out)"


def features(scores: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """(n, 104): the 52 scores and their mean over the :data:`HISTORY_S` before each frame (NaN rows: no face).

    The history is the mean over the frames with a face whose time is in ``[t - HISTORY_S, t)``;
    a frame with none before it repeats its own scores.
    """
    t_s = np.asarray(t_s, dtype=float)
    face = ~np.isnan(scores).any(axis=1)
    filled = np.where(face[:, None], scores, 0.0)
    csum = np.vstack([np.zeros((1, scores.shape[1])), np.cumsum(filled, axis=0)])
    ccount = np.concatenate([[0], np.cumsum(face)])
    start = np.searchsorted(t_s, t_s - HISTORY_S, side="left")
    stop = np.arange(len(t_s))
    count = (ccount[stop] - ccount[start]).astype(float)
    history = (csum[stop] - csum[start]) / np.maximum(count, 1.0)[:, None]
    history = np.where((count > 0)[:, None], history, scores)
    out = np.hstack([scores, history])
    out[~face] = np.nan
    return np.asarray(out, dtype=float)


def make_regressor() -> Any:
    """The regressor of one blendshape: standardised features, ridge regression with its penalty chosen by
    efficient leave-one-out cross-validation over :data:`RIDGE_ALPHAS` (scikit-learn ``RidgeCV``)."""
    from sklearn.linear_model import RidgeCV
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    return make_pipeline(StandardScaler(), RidgeCV(alphas=RIDGE_ALPHAS))


@dataclasses.dataclass
class KeyedSession:
    """One machine-rated session's keyed frames: features, effort-mapped weights and human keys there."""

    folder: Path
    participant: str
    x: np.ndarray  # (k, 104) features at the keyed rows
    definition: np.ndarray  # (k, 4) effort-mapped weights there
    human: np.ndarray  # (k, 4) human key weights (NaN: that blendshape not keyed at that row)


def keyed_session(folder: Path, participant: str, scores: np.ndarray, t_s: np.ndarray) -> KeyedSession | None:
    """The session's rows keyed by humans that have a face; None when it has none."""
    from effortface.annotate.machine.mapping import human_keys

    index, human = human_keys(folder, np.arange(len(t_s)), NAMES)
    if not len(index):
        return None
    x = features(scores, t_s)[index]
    definition, _ = session_weights(folder, scores, t_s)
    ok = ~np.isnan(x).any(axis=1)
    if not ok.any():
        return None
    return KeyedSession(Path(folder), participant, x[ok], definition[index][ok], human[ok])


def _r(a: np.ndarray, b: np.ndarray) -> float | None:
    if len(a) < MIN_KEYS_SCORED or np.ptp(a) == 0 or np.ptp(b) == 0:
        return None
    return float(np.corrcoef(a, b)[0, 1])


def _rows(sessions: Sequence[KeyedSession], j: int, keep: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    chosen = [s for s in sessions if keep(s.participant)]
    if not chosen:
        return np.empty((0, 104)), np.empty(0), np.empty(0)
    x = np.vstack([s.x for s in chosen])
    y = np.concatenate([s.human[:, j] for s in chosen])
    d = np.concatenate([s.definition[:, j] for s in chosen])
    ok = ~np.isnan(y) & ~np.isnan(d)
    return x[ok], y[ok], d[ok]


def heldout(sessions: Sequence[KeyedSession], j: int) -> dict[str, dict[str, float | None]]:
    """Per participant: held-out r of the learned mapping and of the definition for blendshape ``j``."""
    out: dict[str, dict[str, float | None]] = {}
    for p in sorted({s.participant for s in sessions}):
        x_fit, y_fit, _ = _rows(sessions, j, lambda q, p=p: q != p)
        x_test, y_test, d_test = _rows(sessions, j, lambda q, p=p: q == p)
        if len(y_fit) < MIN_KEYS_SCORED or len(y_test) < MIN_KEYS_SCORED:
            continue
        learned = np.clip(make_regressor().fit(x_fit, y_fit).predict(x_test), 0.0, 1.0)
        out[p] = {"learned_r": _r(learned, y_test), "definition_r": _r(d_test, y_test),
                  "learned_mae": round(float(np.mean(np.abs(learned - y_test))), 4), "keys": int(len(y_test))}
    return out


def _mean_r(scores: dict[str, dict[str, float | None]], key: str) -> float | None:
    """The mean of ``key`` over the participants with both held-out r's (None when there are none)."""
    values = [float(value) for v in scores.values()
              if (value := v[key]) is not None and v["learned_r"] is not None and v["definition_r"] is not None]
    return None if not values else float(np.mean(values))


@dataclasses.dataclass
class Choice:
    """Per blendshape: learned or definition, the held-out scores behind it, and the fitted regressors."""

    participant: str
    use_learned: dict[str, bool]
    report: dict[str, dict[str, Any]]
    models: dict[str, Any]

    def weights(self, scores: np.ndarray, t_s: np.ndarray, definition: np.ndarray) -> np.ndarray:
        """The session's (n, 4) weights: the learned prediction where chosen, else the definition's."""
        out = definition.astype(float).copy()
        if not self.models:
            return out
        x = features(scores, t_s)
        face = ~np.isnan(x).any(axis=1)
        for j, name in enumerate(NAMES):
            if name in self.models and face.any():
                out[face, j] = np.clip(self.models[name].predict(x[face]), 0.0, 1.0)
        return out

    def to_dict(self) -> dict[str, Any]:
        """The sidecar's ``learned`` object."""
        return {"method": f"{LEARNED_MAPPING}: sklearn StandardScaler + RidgeCV (alphas {list(RIDGE_ALPHAS)}) per "
                          f"blendshape from the 52 scores and their mean over the {HISTORY_S:g} s before the frame "
                          "to the human keys; held-out Pearson r per participant, the regressor fitted on the other "
                          "participants",
                "participant": self.participant,
                "calibration": "the per-participant isotonic calibration is fitted after this mapping, on the same "
                               "humans' keys (this participant's): its fit_mae is not a held-out figure",
                "blendshapes": {n: {"used": self.use_learned.get(n, False), **self.report.get(n, {})}
                                for n in NAMES}}


def choose(sessions: Sequence[KeyedSession], participant: str) -> Choice:
    """Score the learned mapping held out and fit, where it wins, the regressor rating ``participant``.

    Parameters
    ----------
    sessions : sequence of KeyedSession
        The lab's machine-rated sessions with human keys (this one included).
    participant : str
        Whose session is rated: the regressor used for it is fitted on every other participant.
    """
    participants = {s.participant for s in sessions}
    use: dict[str, bool] = {}
    report: dict[str, dict[str, Any]] = {}
    models: dict[str, Any] = {}
    for j, name in enumerate(NAMES):
        scores = heldout(sessions, j) if len(participants) >= MIN_PARTICIPANTS else {}
        learned_r, definition_r = _mean_r(scores, "learned_r"), _mean_r(scores, "definition_r")
        scored = sum(1 for v in scores.values() if v["learned_r"] is not None and v["definition_r"] is not None)
        wins = learned_r is not None and definition_r is not None and scored >= MIN_PARTICIPANTS \
            and learned_r > definition_r
        report[name] = {"participants_scored": scored,
                        "heldout_r_learned": None if learned_r is None else round(learned_r, 4),
                        "heldout_r_definition": None if definition_r is None else round(definition_r, 4),
                        "per_participant": {p: {k: (round(v, 4) if isinstance(v, float) else v)
                                                for k, v in s.items()} for p, s in scores.items()}}
        if not wins:
            report[name]["why_not"] = (
                f"held-out scores for {scored} participant(s), fewer than {MIN_PARTICIPANTS}"
                if scored < MIN_PARTICIPANTS else "the definition scores at least as well held out")
            use[name] = False
            continue
        x_fit, y_fit, _ = _rows(sessions, j, lambda q: q != participant)
        use[name] = True
        models[name] = make_regressor().fit(x_fit, y_fit)
        mine = scores.get(participant)
        report[name]["this_participant_heldout_r"] = None if mine is None or mine["learned_r"] is None \
            else round(float(mine["learned_r"]), 4)
    return Choice(participant, use, report, models)


#: maps a session's (folder, (n, 52) scores, (n,) t_s) to its (n, 4) weights
Mapper = Callable[[Path, np.ndarray, np.ndarray], np.ndarray]


def lab_tracks(session_dir: Path) -> list[tuple[Path, str, Any]]:
    """(folder, participant, MachineTrack) of the other machine-rated sessions beside ``session_dir``."""
    from effortface.annotate.machine.track import read_machine_track
    from effortface.core.errors import UserError
    from effortface.core.session.folder import list_sessions, read_session_info

    here = Path(session_dir).resolve()
    try:
        folders = list_sessions(here.parent)
    except UserError:
        return []
    out = []
    for other in folders:
        if other.resolve() == here:
            continue
        try:
            track = read_machine_track(other)
            if track is not None:
                out.append((other, read_session_info(other).participant.code, track))
        except UserError:
            continue
    return out


def lab_mapping(session_dir: Path, participant: str, scores: np.ndarray,
                t_s: np.ndarray) -> tuple[np.ndarray, dict[str, Any], Mapper]:
    """The session's raw weights, the sidecar's ``mapping`` object and the mapper used (for the calibration).

    The effort mapping, with the learned one for the blendshapes where it wins held out over the
    lab's machine-rated, human-keyed sessions (this one included; :func:`choose`).
    """
    t_s = np.asarray(t_s, dtype=float)
    definition, record = session_weights(session_dir, scores, t_s)
    sessions = [keyed_session(session_dir, participant, scores, t_s)]
    sessions += [keyed_session(f, p, tr.scores, tr.t_s) for f, p, tr in lab_tracks(session_dir)]
    choice = choose([s for s in sessions if s is not None], participant)
    used = [n for n in NAMES if choice.use_learned.get(n)]
    record["used"] = {n: ("learned" if n in used else EFFORT_MAPPING) for n in NAMES}
    record["kind"] = EFFORT_MAPPING + (f" + learned for {', '.join(used)}" if used else "")
    record["learned"] = choice.to_dict()

    def mapper(folder: Path, other_scores: np.ndarray, other_t_s: np.ndarray) -> np.ndarray:
        weights, _ = session_weights(folder, other_scores, other_t_s)
        return choice.weights(other_scores, other_t_s, weights)

    return choice.weights(scores, t_s, definition), record, mapper


__all__ = ["HISTORY_S", "LEARNED_MAPPING", "MIN_PARTICIPANTS", "Choice", "KeyedSession", "choose", "features",
           "heldout", "keyed_session", "lab_mapping", "lab_tracks", "make_regressor"]
