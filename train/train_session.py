"""The Train stage's model (Qt-free): pick data, train in a worker thread, show, export, compare.

The widgets of :mod:`effortface.train.gui.train_stage` call :class:`TrainSession` methods and listen to its
plain callbacks (:class:`Emitter`); a QTimer calls :meth:`TrainSession.poll`, which drains the
worker's queue on the GUI thread (STYLE.md L3, L5). The training itself is the headless lab's
(:mod:`effortface.train.dataset`, :mod:`effortface.train.hr_fit`, :mod:`effortface.train.face_fit`, :mod:`effortface.train.export`,
:mod:`effortface.train.report`), run step by step so that it reports progress and can be cancelled between
cross-validation folds.
"""

from __future__ import annotations

import dataclasses
import os
import queue
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core.events import Emitter
from effortface.core.errors import UserError
from effortface.core.fileio import refuse_overwrite
from effortface.capture_tool.session import list_sessions, parse_session_id, read_session_info
from effortface.train.dataset import ANNOTATIONS_DIR, prepare, read_table, sessions_table
from effortface.train.face_fit import (GRIDS, MIN_ROWS_PER_PARTICIPANT, FaceFitConfig, FaceModelFit,
                            held_out_scores, protocol_scores)
from effortface.train.hr_fit import PAPER_HR, HrEvaluation, HrSeries, evaluate_hr_models
from effortface.train.pipeline import check_training_data

#: fraction of the progress bar reached after each step (the CV folds fill the middle)
_STEP_FRACTION = {"prepare": 0.05, "hr": 0.2, "folds": 0.8, "held_out": 0.85, "protocols": 1.0}
ANY = "any"
#: the background jobs that :meth:`TrainSession.cancel` can stop (an export always finishes)
CANCELLABLE_JOBS = ("train", "compare")


class Cancelled(Exception):
    """The user cancelled a running training."""


# --------------------------------------------------------------------------- the data to pick


@dataclasses.dataclass(frozen=True)
class SessionEntry:
    """What the session picker shows of one session folder."""

    path: Path
    session_id: str
    participant: str
    exercise: str
    training_level: float
    raters: tuple[str, ...]
    complete: bool

    @property
    def annotated(self) -> bool:
        """True when at least one rater's key-frames exist."""
        return bool(self.raters)


def scan_sessions(folder: str | os.PathLike) -> list[SessionEntry]:
    """The sessions of ``folder`` (unreadable ones are skipped: Capture reports them)."""
    out = []
    for path in list_sessions(folder) if Path(folder).is_dir() else []:
        try:
            info = read_session_info(path)
        except UserError:
            continue
        label = parse_session_id(info.session_id)[2] or "session"
        raters = tuple(sorted(p.stem for p in (path / ANNOTATIONS_DIR).glob("*.json")))
        tl = info.participant.training_level
        out.append(SessionEntry(path, info.session_id, info.participant.code, label,
                                float("nan") if tl is None else float(tl), raters, info.complete))
    return out


def _people(entries: Sequence[SessionEntry]) -> str:
    """Participants of some entries, for a one-line description."""
    return ", ".join(sorted({e.participant for e in entries}))


def _count(items: Sequence[Any], noun: str) -> str:
    """``"1 session"``, ``"2 sessions"``."""
    return f"{len(items)} {noun}{'' if len(items) == 1 else 's'}"


def filter_entries(entries: Sequence[SessionEntry], participant: str = ANY, exercise: str = ANY,
                   annotated: bool | None = None) -> list[SessionEntry]:
    """Entries matching a participant code, an exercise label and an annotation status (ANY/None: all)."""
    return [e for e in entries
            if participant in (ANY, e.participant) and exercise in (ANY, e.exercise)
            and (annotated is None or e.annotated == annotated)]


@dataclasses.dataclass(frozen=True)
class TrainSettings:
    """The trainer's choices.

    Parameters
    ----------
    rater_policy : str
        ``"mean"`` of the raters or one rater's name.
    grid : str
        A key of :data:`effortface.train.face_fit.GRIDS`.
    cv : {"lopo", "kfold"}
        Leave-one-participant-out (the paper's honest protocol) or random-frame K-fold.
    max_rows_per_participant : int
        Face training rows per participant (1 Hz, evenly spaced).
    """

    rater_policy: str = "mean"
    grid: str = "small"
    cv: str = "lopo"
    max_rows_per_participant: int = 300

    def __post_init__(self) -> None:
        if self.grid not in GRIDS:
            raise UserError(f"grid: expected one of {', '.join(GRIDS)}, found {self.grid!r}")
        if self.max_rows_per_participant < MIN_ROWS_PER_PARTICIPANT:
            raise UserError(f"max rows per participant: expected at least {MIN_ROWS_PER_PARTICIPANT}, "
                            f"found {self.max_rows_per_participant}")
        if not self.rater_policy.strip():
            raise UserError("rater policy: expected 'mean' or a rater's name, found nothing")

    def config(self) -> FaceFitConfig:
        """The face-fit configuration of these settings."""
        return FaceFitConfig(grid=dict(GRIDS[self.grid]), cv=self.cv,
                             max_rows_per_participant=self.max_rows_per_participant)


# --------------------------------------------------------------------------- training


@dataclasses.dataclass
class TrainingOutcome:
    """Everything a training run produced, for the plots, the tables and the export."""

    prepared: pd.DataFrame
    series: list[HrSeries]
    hr_eval: HrEvaluation
    face: FaceModelFit
    held_out: pd.DataFrame
    protocols: pd.DataFrame
    protocol_predictions: dict[str, np.ndarray]
    blendshapes: BlendshapeSet
    sources: list[str]
    settings: TrainSettings

    @property
    def sessions(self) -> list[str]:
        """Session ids scored by the heart-rate evaluation, in order."""
        return [s.session for s in self.series]

    def fig2(self, session: str) -> dict[str, Any]:
        """Fig. 2 curves of one session: ``t_min``, ``measured``, ``own`` and ``tl`` NHR, and a title."""
        s = next(x for x in self.series if x.session == session)
        p = self.hr_eval.predictions
        return {"t_min": np.asarray(s.t_s) / 60.0, "measured": np.asarray(s.nhr, float),
                "own": p[("per_participant", session)], "tl": p[("tl_regression", session)],
                "title": f"{s.participant} (TL {s.training_level:g}): {session}"}

    def fig3(self, session: str, protocol: str) -> dict[str, Any]:
        """Fig. 3 curves: ``t_min``, ``keyed`` (n, B) and ``predicted`` (n, B) of one session."""
        d = self.face.data
        rows = np.flatnonzero(d.session == session)
        rows = rows[np.argsort(d.t_s[rows])]
        return {"t_min": d.t_s[rows] / 60.0, "keyed": d.y_norm[rows] * d.e[rows],
                "predicted": self.protocol_predictions[protocol][rows]}

    def face_sessions(self) -> list[str]:
        """Sessions with face rows (Fig. 3 choices)."""
        return sorted(np.unique(self.face.data.session).tolist())

    def hr_table(self) -> pd.DataFrame:
        """Heart-rate models (held out) beside the paper's figures."""
        rows = [{"model": k, "r": v["r"], "RMSE %": v["rmse_pct"], "HR RMSE bpm": v["hr_rmse_bpm"],
                 "paper r": PAPER_HR.get(k, {}).get("r", np.nan),
                 "paper RMSE %": PAPER_HR.get(k, {}).get("rmse_pct", np.nan)}
                for k, v in self.hr_eval.summary().items()]
        return pd.DataFrame(rows)

    def face_table(self) -> pd.DataFrame:
        """Face held-out scores: SVR beside the mean and linear baselines, per blendshape and mean."""
        wide = self.held_out.pivot_table(index="blendshape", columns="model", values="r", sort=False)
        rmse = self.held_out.pivot_table(index="blendshape", columns="model", values="rmse_pct_range",
                                         sort=False)
        out = pd.DataFrame({"blendshape": wide.index})
        for model in ("svr", "mean", "linear"):
            out[f"{model} r"] = wide[model].to_numpy()
            out[f"{model} RMSE %"] = rmse[model].to_numpy()
        mean = out.drop(columns="blendshape").mean()
        return pd.concat([out, pd.DataFrame([{"blendshape": "mean", **mean}])], ignore_index=True)


ProgressFn = Callable[[float, str], None]


def train_models(table: pd.DataFrame, blendshapes: BlendshapeSet, settings: TrainSettings,
                 sources: Sequence[str], progress: ProgressFn,
                 cancelled: Callable[[], bool] = lambda: False) -> TrainingOutcome:
    """Fit and evaluate both models like ``effortface train`` (without writing anything).

    Parameters
    ----------
    table : DataFrame
        Long training table.
    blendshapes : BlendshapeSet
        The blendshape set.
    settings : TrainSettings
        Rater policy (provenance only here), grid, CV, subsampling.
    sources : sequence of str
        Where the data came from (provenance).
    progress : callable
        ``progress(fraction, text)`` after each step and each CV fold (called from this thread).
    cancelled : callable
        Polled between steps and folds; when it returns True, :class:`Cancelled` is raised.

    Returns
    -------
    TrainingOutcome
    """
    config = settings.config()

    def step(name: str, text: str) -> None:
        if cancelled():
            raise Cancelled(text)
        progress(_STEP_FRACTION[name], text)

    prepared, series = check_training_data(table, blendshapes, ", ".join(sources) or "table", config)
    step("prepare", "heart-rate models")
    hr_eval = evaluate_hr_models(series)
    step("hr", "face SVR grid search")
    face = _fit_face(prepared, blendshapes, config, step, cancelled, progress)
    held = held_out_scores(face)
    step("held_out", "the paper's Fig. 3 protocols")
    protos, proto_preds = protocol_scores(face)
    step("protocols", "done")
    return TrainingOutcome(prepared, series, hr_eval, face, held, protos, proto_preds, blendshapes,
                           list(sources), settings)


def _fit_face(prepared: pd.DataFrame, blendshapes: BlendshapeSet, config: FaceFitConfig,
              step: Callable[[str, str], None], cancelled: Callable[[], bool],
              progress: ProgressFn) -> FaceModelFit:
    """The face grid search with a progress report (and a cancel check) after each fold."""
    from effortface.train.face_fit import fit_face_models

    n_people = prepared["participant"].nunique()
    n_folds = min(n_people, config.max_folds) if config.cv == "lopo" else config.n_splits
    done = [0]
    lo, hi = _STEP_FRACTION["hr"], _STEP_FRACTION["folds"]

    def fold(n: int) -> None:
        done[0] += n
        if cancelled():
            raise Cancelled("face CV")
        progress(lo + (hi - lo) * done[0] / max(n_folds, 1), f"face CV fold {done[0]} of {n_folds}")

    face = fit_face_models(prepared, blendshapes.names, config, progress=fold)
    step("folds", "held-out scores")
    return face


def export_outcome(outcome: TrainingOutcome, out_dir: str | os.PathLike, *,
                   overwrite: bool = False) -> Path:
    """Export the bundle with its model card (train/export.py) and the report (train/report.py).

    Raises
    ------
    FileExistsError
        If ``out_dir`` exists and ``overwrite`` is False.
    """
    from effortface.train.pipeline import export_training

    o = outcome
    model_dir, _, _ = export_training(
        prepared=o.prepared, series=o.series, hr_eval=o.hr_eval, face=o.face,
        held_out=o.held_out, protocols=o.protocols, protocol_predictions=o.protocol_predictions,
        blendshapes=o.blendshapes, sources=o.sources, rater_policy=o.settings.rater_policy,
        config=o.settings.config(), out=Path(out_dir), force=overwrite)
    return model_dir


# --------------------------------------------------------------------------- comparing bundles


@dataclasses.dataclass
class BundleSummary:
    """One model bundle as the comparison shows it."""

    path: Path
    hr: pd.DataFrame          # model, r, RMSE %, HR RMSE bpm (from model.json)
    face: pd.DataFrame        # blendshape, model, r, RMSE % (held out, from model.json)
    curves: dict[str, np.ndarray]   # predicted nhr and weights on the comparison session


def compare_bundle(path: str | os.PathLike, session_rows: pd.DataFrame) -> BundleSummary:
    """Metrics of a bundle and its predictions over one session's measured work (per second).

    The character is the session's participant, with the expressiveness of their key-frames
    (the maximal key-framed weight of each blendshape, as in training).
    """
    from effortface.train.bundle import read_bundle
    from effortface.train.face_fit import expressiveness
    from effortface.train.runtime import Character, load_model

    model = load_model(path)
    met = read_bundle(Path(path)).metrics
    first = session_rows.iloc[0]
    names = list(model.blendshapes.names)
    e = expressiveness(session_rows, names).iloc[0].to_numpy(float) \
        if set(names) <= set(session_rows.columns) else np.ones(len(names))
    who = Character(age=float(first["age"]), sex=str(first["sex"]), height_m=float(first["height_m"]),
                    mass_kg=float(first["mass_kg"]), training_level=float(first["training_level"]),
                    expressiveness=tuple(e))
    curves = model.curves_from_work(session_rows["t_s"], session_rows["w_per_kg"].to_numpy(float),
                                    session_rows["p_per_kg"].to_numpy(float), 1.0, who)
    hr = pd.DataFrame([{"model": k, "r": v["r"], "RMSE %": v["rmse_pct"], "HR RMSE bpm": v["hr_rmse_bpm"]}
                       for k, v in met.get("hr", {}).items()])
    face = pd.DataFrame(met.get("face_held_out", []))
    return BundleSummary(Path(path), hr, face, curves)


def measured_curves(prepared_rows: pd.DataFrame, names: Sequence[str]) -> dict[str, np.ndarray]:
    """Measured NHR and key-framed weights of one prepared session (the comparison's reference)."""
    out = {"t_s": prepared_rows["t_s"].to_numpy(float), "nhr": prepared_rows["nhr"].to_numpy(float)}
    out.update({n: prepared_rows[n].to_numpy(float) for n in names if n in prepared_rows})
    return out


# --------------------------------------------------------------------------- the worker


@dataclasses.dataclass(frozen=True)
class _Message:
    kind: str          # "progress", "done", "error"
    job: str
    value: Any = None


class _Worker:
    """One background job at a time; it reports into a queue that :meth:`drain` empties."""

    def __init__(self) -> None:
        self.queue: queue.Queue[_Message] = queue.Queue()
        self.cancel_event = threading.Event()
        self._thread: threading.Thread | None = None
        self.job = ""

    @property
    def busy(self) -> bool:
        """True while a job runs."""
        return self._thread is not None and self._thread.is_alive()

    def start(self, job: str, fn: Callable[[], Any]) -> None:
        """Run ``fn()`` in a thread named after ``job``."""
        if self.busy:
            raise UserError(f"{job}: expected no other job running, found {self.job!r} still running")
        self.cancel_event.clear()
        self.job = job

        def run() -> None:
            try:
                self.queue.put(_Message("done", job, fn()))
            except (UserError, ValueError, OSError, Cancelled) as exc:  # expected: shown in-window
                self.queue.put(_Message("error", job, exc))
            except BaseException as exc:  # unexpected: shown too, then to threading.excepthook
                self.queue.put(_Message("error", job, exc))
                raise

        self._thread = threading.Thread(target=run, name=f"train-gui-{job}", daemon=True)
        self._thread.start()

    def report(self, fraction: float, text: str) -> None:
        """Queue a progress message (called from the worker)."""
        self.queue.put(_Message("progress", self.job, (fraction, text)))

    def drain(self) -> list[_Message]:
        """Messages queued since the last call (never blocks)."""
        out = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out

    def join(self, timeout_s: float | None = None) -> None:
        """Wait for the running job (tests, shutdown)."""
        if self._thread is not None:
            self._thread.join(timeout_s)


# --------------------------------------------------------------------------- the session model


class TrainSession:
    """The Train stage's state: data choice, settings, the running job and its results.

    Parameters
    ----------
    sessions_dir : path-like
        Folder of session folders.
    blendshapes : BlendshapeSet
        The blendshape set to train.

    Notes
    -----
    Callbacks (each an :class:`Emitter`): ``sessions_changed()``, ``selection_changed()``,
    ``progress_changed(fraction, text)``, ``results_changed()``, ``status_changed(text, is_error)``,
    ``busy_changed(busy)``, ``exported(path)``, ``comparison_changed()``.
    """

    def __init__(self, sessions_dir: str | os.PathLike, blendshapes: BlendshapeSet = DEFAULT_SET) -> None:
        self.sessions_dir = Path(sessions_dir)
        self.blendshapes = blendshapes
        self.entries: list[SessionEntry] = []
        self.selected: set[str] = set()
        self.table_path: Path | None = None
        self.settings = TrainSettings()
        self.outcome: TrainingOutcome | None = None
        self.comparison: dict[str, Any] | None = None
        self._worker = _Worker()
        self.sessions_changed, self.selection_changed = Emitter(), Emitter()
        self.progress_changed, self.results_changed = Emitter(), Emitter()
        self.status_changed, self.busy_changed = Emitter(), Emitter()
        self.exported, self.comparison_changed = Emitter(), Emitter()
        self.refresh()

    # ---- data choice
    def refresh(self) -> None:
        """Rescan the sessions folder (the selection keeps the sessions still present)."""
        self.entries = scan_sessions(self.sessions_dir)
        ids = {e.session_id for e in self.entries}
        self.selected &= ids
        self.sessions_changed.emit()

    def set_selected(self, session_ids: Sequence[str], selected: bool = True) -> None:
        """Add or remove sessions from the training data (switches back from a loaded table)."""
        known = {e.session_id for e in self.entries}
        unknown = [s for s in session_ids if s not in known]
        if unknown:
            raise UserError(f"sessions: expected sessions of {self.sessions_dir}, found {unknown}")
        self.selected = (self.selected | set(session_ids)) if selected else (self.selected - set(session_ids))
        self.table_path = None
        self.selection_changed.emit()

    def load_table(self, path: str | os.PathLike) -> None:
        """Use a long training table instead of sessions (read now, so a bad file fails here)."""
        read_table(path, self.blendshapes)
        self.table_path = Path(path)
        self.selection_changed.emit()
        self.status_changed.emit(f"training data: table {self.table_path}", False)

    def set_settings(self, **changes: Any) -> None:
        """Change settings (validated: a bad value raises UserError and keeps the old ones)."""
        self.settings = dataclasses.replace(self.settings, **changes)

    def known_raters(self) -> list[str]:
        """Raters of the selected sessions (of every session when none is selected), sorted."""
        chosen = [e for e in self.entries if e.session_id in self.selected] or self.entries
        return sorted({r for e in chosen for r in e.raters})

    def set_rater_policy(self, policy: str) -> None:
        """Use ``"mean"`` or one rater of the selected sessions (a warning if some lack that rater).

        Raises
        ------
        UserError
            For an empty name or a rater who annotated none of the selected sessions (of the
            lab when none is selected); the settings keep the previous policy.
        """
        name = policy.strip()
        raters = self.known_raters()
        where = "the selected sessions" if self.selected else f"the sessions of {self.sessions_dir}"
        if name != "mean" and name not in raters:
            raise UserError(f"raters: expected 'mean' or a rater of {where} "
                            f"({', '.join(raters) or 'none annotated'}), found {name or 'nothing'!r}; "
                            f"training still uses {self.settings.rater_policy!r}")
        self.set_settings(rater_policy=name)
        missing = [e.session_id for e in self.entries if e.session_id in self.selected
                   and name != "mean" and name not in e.raters]
        if missing:
            self.status_changed.emit(f"raters: {name} did not annotate {len(missing)} of the selected "
                                     f"sessions ({', '.join(missing)}): training on them fails", True)
        else:
            self.status_changed.emit(
                f"raters: training uses {'the mean of the raters' if name == 'mean' else name}", False)

    def describe_data(self) -> str:
        """One line: what the next training run will use."""
        if self.table_path is not None:
            return f"table {self.table_path}"
        people = sorted({e.participant for e in self.entries if e.session_id in self.selected})
        return f"{len(self.selected)} sessions, {len(people)} participants ({', '.join(people)})"

    def table(self) -> tuple[pd.DataFrame, list[str]]:
        """The training table of the current choice, and its sources (reads files: call from a worker)."""
        if self.table_path is not None:
            return read_table(self.table_path, self.blendshapes), [str(self.table_path)]
        paths = [e.path for e in self.entries if e.session_id in self.selected]
        if not paths:
            raise UserError("sessions: expected at least one selected session or a loaded table, "
                            "found none")
        return self._sessions_table(paths), [str(p) for p in paths]

    def _sessions_table(self, paths: Sequence[Path]) -> pd.DataFrame:
        return sessions_table(paths, self.blendshapes, self.settings.rater_policy)

    def bundle_sessions(self, *bundles: str | os.PathLike) -> list[SessionEntry]:
        """Annotated sessions of this lab that the bundles were trained on, in the lab's order.

        A bundle's provenance lists its ``sources`` (session folders, matched here by name); a
        bundle trained on a table gives the lab's sessions of its ``participants`` instead.

        Raises
        ------
        UserError
            If a folder is not a readable bundle.
        """
        from effortface.train.bundle import read_bundle

        ids: set[str] = set()
        for bundle in bundles:
            prov = read_bundle(Path(bundle)).provenance
            named = {Path(str(src)).name for src in prov.get("sources", [])}
            found = {e.session_id for e in self.entries if e.session_id in named}
            people = set(prov.get("participants", []))
            ids |= found or {e.session_id for e in self.entries if e.participant in people}
        return [e for e in self.entries if e.session_id in ids and e.annotated]

    def comparison_data(self, bundle_a: str | os.PathLike, bundle_b: str | os.PathLike
                        ) -> tuple[list[SessionEntry], str]:
        """The sessions a comparison runs on, and a line saying which.

        The loaded table if there is one (no entries then), else the ticked sessions, else
        (nothing ticked) the sessions of this lab that the two models were trained on.

        Raises
        ------
        UserError
            If nothing is ticked and a folder is missing or not a bundle, or neither model was
            trained on annotated sessions of this lab.
        """
        if self.table_path is not None:
            return [], f"the loaded table {self.table_path}"
        ticked = [e for e in self.entries if e.session_id in self.selected]
        if ticked:
            return ticked, f"the {_count(ticked, 'ticked session')} ({_people(ticked)})"
        if not (str(bundle_a).strip() and str(bundle_b).strip()):
            raise UserError("compare: expected two model folders (Compare uses the sessions both were "
                            "trained on) or ticked sessions, found neither")
        trained = self.bundle_sessions(bundle_a, bundle_b)
        if not trained:
            raise UserError(f"compare: expected ticked sessions, or models trained on annotated "
                            f"sessions of {self.sessions_dir}; found neither (tick sessions to compare on)")
        return trained, (f"the {_count(trained, 'session')} the models were trained on (nothing "
                         f"ticked; {_people(trained)})")

    # ---- jobs
    @property
    def busy(self) -> bool:
        """True while training, exporting or comparing runs in the background."""
        return self._worker.busy

    def start_training(self) -> None:
        """Train on the current choice in the background; results arrive through :meth:`poll`."""
        settings, blendshapes = self.settings, self.blendshapes
        worker = self._worker

        def job() -> TrainingOutcome:
            table, sources = self.table()
            worker.report(0.02, "data read")
            return train_models(table, blendshapes, settings, sources, worker.report,
                                worker.cancel_event.is_set)

        self._start("train", job)

    @property
    def cancellable(self) -> bool:
        """True while a job that :meth:`cancel` can stop runs (training or comparison, not export)."""
        return self.busy and self._worker.job in CANCELLABLE_JOBS

    def cancel(self) -> None:
        """Ask the running training or comparison to stop at its next step; an export finishes."""
        if not self.busy:
            return
        if not self.cancellable:
            self.status_changed.emit(f"{self._worker.job} cannot be cancelled: it finishes on its own",
                                     False)
            return
        self._worker.cancel_event.set()
        self.status_changed.emit(f"{self._worker.job}: cancelling at the next step...", False)

    def export(self, out_dir: str | os.PathLike, *, overwrite: bool = False) -> None:
        """Export the last training's bundle, model card and report in the background.

        Raises
        ------
        UserError
            If nothing has been trained yet.
        FileExistsError
            If ``out_dir`` exists and ``overwrite`` is False (the GUI asks, then passes True).
        """
        if self.outcome is None:
            raise UserError("export: expected a trained model, found none (train first)")
        out = refuse_overwrite(out_dir, overwrite=overwrite, what="model folder")
        outcome = self.outcome
        self._start("export", lambda: export_outcome(outcome, out, overwrite=overwrite))

    def compare(self, bundle_a: str | os.PathLike, bundle_b: str | os.PathLike,
                session: str | None = None) -> None:
        """Load two bundles and predict over one session, in the background (cancellable).

        The data are :meth:`comparison_data`'s: the loaded table, the ticked sessions, or the
        sessions the two models were trained on. ``session`` defaults to the first of them.

        Raises
        ------
        UserError
            If there are no data to compare on, or a folder is not a readable bundle.
        """
        entries, what = self.comparison_data(bundle_a, bundle_b)
        table_path = self.table_path

        def job() -> dict[str, Any]:
            table = (read_table(table_path, self.blendshapes) if table_path is not None
                     else self._sessions_table([e.path for e in entries]))
            return {"data": what, **self._compare_on(table, bundle_a, bundle_b, session)}

        self._start("compare", job)

    def _compare_on(self, table: pd.DataFrame, bundle_a: str | os.PathLike, bundle_b: str | os.PathLike,
                    session: str | None) -> dict[str, Any]:
        """The comparison's results on a training table (runs on the worker; stops when cancelled)."""
        worker = self._worker

        def step(fraction: float, text: str) -> None:
            if worker.cancel_event.is_set():
                raise Cancelled(text)
            worker.report(fraction, text)

        step(0.4, "compare: data read")
        prepared = prepare(table)
        sid = session or str(prepared["session"].iloc[0])
        rows = prepared[prepared["session"] == sid]
        if rows.empty:
            raise UserError(f"session: expected one of the compared data, found {sid!r}")
        step(0.5, "compare: model A")
        a = compare_bundle(bundle_a, rows)
        step(0.75, "compare: model B")
        b = compare_bundle(bundle_b, rows)
        step(1.0, "compare: done")
        return {"session": sid, "sessions": sorted(prepared["session"].unique().tolist()),
                "measured": measured_curves(rows, self.blendshapes.names), "a": a, "b": b}

    def _start(self, job: str, fn: Callable[[], Any]) -> None:
        self._worker.start(job, fn)
        self.busy_changed.emit(True)
        self.progress_changed.emit(0.0, f"{job}: started")

    def poll(self) -> None:
        """Deliver the worker's messages as callbacks (call on the GUI thread, e.g. from a QTimer)."""
        for msg in self._worker.drain():
            if msg.kind == "progress":
                self.progress_changed.emit(*msg.value)
            elif msg.kind == "error":
                self._finish_error(msg)
            else:
                self._finish(msg)

    def _finish_error(self, msg: _Message) -> None:
        self.busy_changed.emit(False)
        if isinstance(msg.value, Cancelled):
            self.progress_changed.emit(0.0, "cancelled")
            self.status_changed.emit(f"{msg.job} cancelled; previous results kept", False)
        else:
            self.progress_changed.emit(0.0, f"{msg.job} failed")
            self.status_changed.emit(f"{msg.job} failed: {msg.value}", True)

    def _finish(self, msg: _Message) -> None:
        self.busy_changed.emit(False)
        self.progress_changed.emit(1.0, f"{msg.job}: done")
        if msg.job == "train":
            self.outcome = msg.value
            self.results_changed.emit()
            self.status_changed.emit(f"trained on {len(self.outcome.series)} sessions", False)
        elif msg.job == "export":
            self.exported.emit(msg.value)
            self.status_changed.emit(f"exported model to {msg.value}", False)
        elif msg.job == "compare":
            self.comparison = msg.value
            self.comparison_changed.emit()
            self.status_changed.emit(f"compared on {msg.value['session']} of {msg.value['data']}",
                                     False)

    def wait(self, timeout_s: float | None = None) -> None:
        """Block until the running job ends, then :meth:`poll` (tests and scripts, not the GUI)."""
        self._worker.join(timeout_s)
        self.poll()

    def shutdown(self) -> None:
        """Cancel a running training (the thread is a daemon; export finishes or is discarded)."""
        self._worker.cancel_event.set()
