"""The Train stage's model (Qt-free): pick data, train in a worker thread, show, export, compare.

:class:`TrainSession` follows the stage-model convention of :mod:`effortface.core`: the widgets of
:mod:`effortface.train.gui.train_stage` call its methods and connect to its ``<thing>_changed``
emitters; its background work (training, export, comparison) runs in the core
:class:`~effortface.core.jobs.Jobs`, which a QTimer drains through :meth:`TrainSession.poll` on the
GUI thread (the rule: a view writes back only through model methods and keeps widget state only; worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget). The training and the export are the command line's own
(:func:`effortface.train.pipeline.train_models`, which reports progress and can be cancelled between
cross-validation folds, and :func:`effortface.train.pipeline.export_outcome`).
"""

from __future__ import annotations

import dataclasses
import collections
import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from effortface.annotate.machine.track import CSV_NAME, MACHINE_DIR
from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core.events import Emitter
from effortface.core.errors import UserError
from effortface.core.fileio import refuse_overwrite
from effortface.core.jobs import Cancelled, Job, JobResult, Jobs
from effortface.annotate.completeness import session_status, summary
from effortface.core.session.folder import (VIDEO_FRAMES_CSV, list_sessions, parse_session_id, read_session_info,
                                             read_video_frames)
from effortface.train.dataset import ANNOTATIONS_DIR, prepare, read_table, sessions_table
from effortface.train.pipeline import (TrainingOutcome, TrainSettings, export_outcome, partial_export_line,
                                       train_models, training_table)
from effortface.train.run_log import bundle_settings, fold_scores, grid_edge_warnings, grid_table, timing_text

ANY = "any"
#: sessions shorter than this (their video, seconds) are not trained on: too few rows to fit or score
#: (a 42 s one-rater session gave a fold r of 0.28 on the sample lab)
MIN_TRAIN_S = 120.0
#: the background jobs that :meth:`TrainSession.cancel` can stop (an export always finishes)
CANCELLABLE_JOBS = ("train", "compare")
#: errors a job reports in the status line only; any other also goes to sys.excepthook
_EXPECTED_ERRORS = (UserError, ValueError, OSError, Cancelled)


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
    #: each rater's complete tracks over tracks, e.g. ``"R1 4/4, R2 2/4"``
    #: (:mod:`effortface.annotate.completeness`: only complete tracks are trained on)
    tracks: str = ""
    #: the video's length, seconds (NaN when it has no readable video_frames.csv)
    duration_s: float = float("nan")
    #: True when the machine rater has rated the session (``machine/face_landmarker.csv``)
    machine_rated: bool = False

    @property
    def annotated(self) -> bool:
        """True when at least one rater's key-frames exist."""
        return bool(self.raters)

    @property
    def unusable(self) -> str:
        """Why the session cannot be trained on human labels ('' when it can): see :meth:`unusable_for`."""
        return self.unusable_for("humans")

    def unusable_for(self, raters: str) -> str:
        """Why the session cannot be trained on ('' when it can) under the label sources ``raters``
        (``"humans"`` or ``"humans+machine"``): no annotations (nor, with the machine, a machine
        track), or too short."""
        if not self.raters and not (raters == "humans+machine" and self.machine_rated):
            return "no annotations: key it in Annotate first"
        if self.duration_s == self.duration_s and self.duration_s < MIN_TRAIN_S:
            return f"too short: {self.duration_s:.0f} s of video (at least {MIN_TRAIN_S:.0f} s to train on)"
        return ""


def scan_sessions(folder: str | os.PathLike) -> list[SessionEntry]:
    """The finished sessions of ``folder``: unreadable ones, incomplete ones (recovered in Capture first)
    and one being recorded (left out by ``list_sessions``) are skipped."""
    out = []
    for path in list_sessions(folder) if Path(folder).is_dir() else []:
        try:
            info = read_session_info(path)
        except UserError:
            continue
        if not info.complete:
            continue
        label = parse_session_id(info.session_id)[2] or "session"
        raters = tuple(sorted(p.stem for p in (path / ANNOTATIONS_DIR).glob("*.json")))
        tl = info.participant.training_level
        out.append(SessionEntry(path, info.session_id, info.participant.code, label,
                                float("nan") if tl is None else float(tl), raters, info.complete,
                                _tracks_summary(path), _duration_s(path),
                                (path / MACHINE_DIR / CSV_NAME).is_file()))
    return out


def _duration_s(path: Path) -> float:
    """The session's video length in seconds (first to last frame); NaN if unreadable or absent."""
    try:
        t_s = read_video_frames(path / VIDEO_FRAMES_CSV)
    except (UserError, OSError):
        return float("nan")
    return t_s[-1] - t_s[0] if len(t_s) > 1 else 0.0


def _tracks_summary(path: Path) -> str:
    """``"R1 4/4, R2 2/4"``: each rater's complete tracks; ``"unreadable"`` if a file is malformed."""
    frames = path / VIDEO_FRAMES_CSV
    if not frames.is_file():
        return ""
    try:
        status = session_status(path, read_video_frames(frames))
    except (UserError, OSError):
        return "unreadable"
    return ", ".join(f"{r} {summary(st)}" for r, st in status.items())


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


# --------------------------------------------------------------------------- comparing bundles


@dataclasses.dataclass
class BundleSummary:
    """One model bundle as the comparison shows it."""

    path: Path
    hr: pd.DataFrame          # model, r, RMSE %, HR RMSE bpm (from model.json)
    face: pd.DataFrame        # blendshape, model, r, RMSE % (held out, from model.json)
    curves: dict[str, np.ndarray]   # predicted nhr and weights on the comparison session
    settings: dict[str, Any] = dataclasses.field(default_factory=dict)  # run_log.bundle_settings


def compare_bundle(path: str | os.PathLike, session_rows: pd.DataFrame) -> BundleSummary:
    """Metrics of a bundle and its predictions over one session's measured work (per second).

    The character is the session's participant, with the expressiveness of their key-frames
    (the maximal key-framed weight of each blendshape, as in training).
    """
    from effortface.synth.bundle import read_bundle
    from effortface.train.face_fit import expressiveness
    from effortface.synth.runtime import Character, load_model

    model = load_model(path)
    stored = read_bundle(Path(path))
    met = stored.metrics
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
    return BundleSummary(Path(path), hr, face, curves, bundle_settings(stored.provenance, met))


def measured_curves(prepared_rows: pd.DataFrame, names: Sequence[str]) -> dict[str, np.ndarray]:
    """Measured NHR and key-framed weights of one prepared session (the comparison's reference)."""
    out = {"t_s": prepared_rows["t_s"].to_numpy(float), "nhr": prepared_rows["nhr"].to_numpy(float)}
    out.update({n: prepared_rows[n].to_numpy(float) for n in names if n in prepared_rows})
    return out


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
    Emitters: ``sessions_changed()``, ``selection_changed()``, ``progress_changed(fraction, text)``,
    ``results_changed()``, ``status_changed(text, is_error)``, ``busy_changed(busy)``,
    ``export_changed(path)`` (a bundle was exported), ``comparison_changed()``,
    ``log_changed(line)`` (a line added to :attr:`run_log`; ``""`` when it was cleared).
    Progress texts end with the elapsed time and, from the first step, an estimate of the time left.
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
        self.run_log: list[str] = []
        self.fold_table = pd.DataFrame()      # run_log.fold_scores of the last training
        self.grid_results = pd.DataFrame()    # run_log.grid_table of the last training
        self.grid_edges: list[str] = []        # run_log.grid_edge_warnings of the last training
        self._started_s = time.monotonic()
        self._stamps: collections.deque[float] = collections.deque()  # report times, job thread -> GUI
        self.jobs = Jobs(workers=1, name="train")
        self.sessions_changed, self.selection_changed = Emitter(), Emitter()
        self.progress_changed, self.results_changed = Emitter(), Emitter()
        self.status_changed, self.busy_changed = Emitter(), Emitter()
        self.export_changed, self.comparison_changed = Emitter(), Emitter()
        self.log_changed = Emitter()
        self.refresh()

    # ---- data choice
    def refresh(self) -> None:
        """Rescan the sessions folder (the selection keeps the sessions still present)."""
        self.entries = scan_sessions(self.sessions_dir)
        ids = {e.session_id for e in self.entries}
        self.selected &= ids
        self.sessions_changed.emit()

    def set_selected(self, session_ids: Sequence[str], selected: bool = True) -> None:
        """Add or remove sessions from the training data (switches back from a loaded table).

        A session that cannot be trained on (:attr:`SessionEntry.unusable`: no annotations, too short)
        is never added; the status line says which and why.
        """
        known = {e.session_id for e in self.entries}
        unknown = [s for s in session_ids if s not in known]
        if unknown:
            raise UserError(f"sessions: expected sessions of {self.sessions_dir}, found {unknown}")
        raters = self.settings.raters
        refused = {e.session_id: e.unusable_for(raters) for e in self.entries
                   if e.session_id in session_ids and e.unusable_for(raters)}
        wanted = set(session_ids) - set(refused) if selected else set(session_ids)
        self.selected = (self.selected | wanted) if selected else (self.selected - wanted)
        self.table_path = None
        self.selection_changed.emit()
        if selected and refused:
            sid, why = next(iter(refused.items()))
            more = f" and {len(refused) - 1} more" if len(refused) > 1 else ""
            self.status_changed.emit(f"not ticked: {sid}{more}: {why}", False)

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

    @property
    def can_train(self) -> bool:
        """True when there is something to train on (ticked sessions or a loaded table)."""
        return self.table_path is not None or bool(self.selected)

    def describe_data(self) -> str:
        """One line: what the next training run will use."""
        if self.table_path is not None:
            return f"table {self.table_path}"
        people = sorted({e.participant for e in self.entries if e.session_id in self.selected})
        return f"{len(self.selected)} sessions, {len(people)} participants ({', '.join(people)})"

    def table(self) -> tuple[pd.DataFrame, list[str]]:
        """The training table of the current choice, and its sources (reads files: call from a worker)."""
        paths = [e.path for e in self.entries if e.session_id in self.selected]
        if self.table_path is None and not paths:
            raise UserError("sessions: expected at least one selected session or a loaded table, "
                            "found none")
        return training_table(paths, self.table_path, self.blendshapes, self.settings.rater_policy,
                              self.settings.raters)

    def _sessions_table(self, paths: Sequence[Path]) -> pd.DataFrame:
        return sessions_table(paths, self.blendshapes, self.settings.rater_policy, self.settings.raters)

    def bundle_sessions(self, *bundles: str | os.PathLike) -> list[SessionEntry]:
        """Annotated sessions of this lab that the bundles were trained on, in the lab's order.

        A bundle's provenance lists its ``sources`` (session folders, matched here by name); a
        bundle trained on a table gives the lab's sessions of its ``participants`` instead.

        Raises
        ------
        UserError
            If a folder is not a readable bundle.
        """
        from effortface.synth.bundle import read_bundle

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
        return self.jobs.busy()

    @property
    def running_job(self) -> str:
        """The job running now (``train``, ``export``, ``compare``), '' when none."""
        running = self.jobs.running()
        return running[0] if running else ""

    def start_training(self) -> None:
        """Train on the current choice in the background; results arrive through :meth:`poll`.

        Clears the run log and replaces the status line (an old error does not stay up).
        """
        settings, blendshapes = self.settings, self.blendshapes
        if not self.can_train:
            raise UserError("sessions: expected at least one selected session or a loaded table, "
                            "found none")

        def train(job: Job) -> tuple[TrainingOutcome, pd.DataFrame, pd.DataFrame]:
            table, sources = self.table()
            job.report(0.02, "data read")
            outcome = train_models(table, blendshapes, settings, sources, job.report,
                                   lambda: job.cancel_requested)
            return outcome, fold_scores(outcome), grid_table(outcome)

        self._start("train", train, self._trained)
        self.status_changed.emit(f"training on {self.describe_data()}...", False)
        self.log(f"settings: raters {settings.rater_policy} ({settings.raters}), grid {settings.grid}, cv {settings.cv}, "
                 f"{settings.max_rows_per_participant} face rows per participant")

    def log(self, line: str, at_s: float | None = None) -> None:
        """Add a line to the run log, prefixed with the wall-clock time and the seconds since the job
        started, both of when it happened (``at_s``: a ``time.monotonic()`` taken in the job's thread)."""
        at_s = time.monotonic() if at_s is None else at_s
        wall = time.strftime("%H:%M:%S", time.localtime(time.time() - (time.monotonic() - at_s)))
        self.run_log.append(f"[{wall} {at_s - self._started_s:7.2f} s] {line}")
        self.log_changed.emit(self.run_log[-1])

    @property
    def cancellable(self) -> bool:
        """True while a job that :meth:`cancel` can stop runs (training or comparison, not export)."""
        return self.running_job in CANCELLABLE_JOBS

    def cancel(self) -> None:
        """Ask the running training or comparison to stop at its next step; an export finishes."""
        job = self.running_job
        if not job:
            return
        if not self.cancellable:
            self.status_changed.emit(f"{job} cannot be cancelled: it finishes on its own", False)
            return
        self.jobs.cancel(job)
        self.status_changed.emit(f"{job}: cancelling at the next step...", False)

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
        self._start("export", lambda _job: export_outcome(outcome, out, force=overwrite), self._exported)

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

        def compare(job: Job) -> dict[str, Any]:
            table = (read_table(table_path, self.blendshapes) if table_path is not None
                     else self._sessions_table([e.path for e in entries]))
            return {"data": what, **self._compare_on(job, table, bundle_a, bundle_b, session)}

        self._start("compare", compare, self._compared)

    def _compare_on(self, job: Job, table: pd.DataFrame, bundle_a: str | os.PathLike,
                    bundle_b: str | os.PathLike, session: str | None) -> dict[str, Any]:
        """The comparison's results on a training table (runs in the job; stops when cancelled)."""

        def step(fraction: float, text: str) -> None:
            job.check(text)
            job.report(fraction, text)

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

    def _start(self, key: str, fn: Callable[[Job], Any], done: Callable[[JobResult], None]) -> None:
        """Run ``fn(job)`` in the background, one job at a time; ``done`` gets its result."""
        if self.busy:
            raise UserError(f"{key}: expected no other job running, found {self.running_job!r} still running")
        self._started_s = time.monotonic()
        if key == "train":
            self.run_log = []
            self.log_changed.emit("")
        stamps = self._stamps = collections.deque()

        def stamped(job: Job) -> Any:
            """Run ``fn`` with each progress report timed where it happens (the job's thread)."""
            report = job.report

            def timed_report(fraction: float, text: str) -> None:
                stamps.append(time.monotonic())  # deque.append: thread-safe
                report(fraction, text)
            job.report = timed_report  # type: ignore[method-assign]
            return fn(job)
        self.jobs.submit(key, stamped, takes_job=True, progress=self._progress, done=done)
        self.busy_changed.emit(True)
        self.progress_changed.emit(0.0, f"{key}: started")
        self.log(f"{key}: started")

    def _progress(self, fraction: float, text: str) -> None:
        """A job's progress (GUI thread): with elapsed time and time left, and into the run log."""
        try:
            at_s = self._stamps.popleft()  # when the job reported it, not when it was delivered
        except IndexError:
            at_s = time.monotonic()
        elapsed_s = at_s - self._started_s
        self.progress_changed.emit(fraction, f"{text} - {timing_text(fraction, elapsed_s)}")
        self.log(f"{text} ({fraction:.0%})", at_s)

    def poll(self) -> None:
        """Deliver the jobs' progress and results to the emitters (GUI thread, e.g. a QTimer)."""
        self.jobs.drain()

    def _ended(self, result: JobResult) -> bool:
        """Report the end of a job; True if it succeeded (an unexpected error is re-raised after)."""
        self.busy_changed.emit(False)
        elapsed = f"{time.monotonic() - self._started_s:.1f} s"
        if result.error is None:
            self.progress_changed.emit(1.0, f"{result.key}: done in {elapsed}")
            self.log(f"{result.key}: done in {elapsed}")
            return True
        self.log(f"{result.key}: {'cancelled' if result.cancelled else 'failed'} after {elapsed}: "
                 f"{result.error}")
        if result.cancelled:
            self.progress_changed.emit(0.0, "cancelled")
            self.status_changed.emit(f"{result.key} cancelled; previous results kept", False)
            return False
        self.progress_changed.emit(0.0, f"{result.key} failed")
        self.status_changed.emit(f"{result.key} failed: {result.error}", True)
        if not isinstance(result.error, _EXPECTED_ERRORS):
            raise result.error
        return False

    def _trained(self, result: JobResult) -> None:
        if self._ended(result):
            self.outcome, self.fold_table, self.grid_results = result.value
            for (fold, who), rows in self.fold_table.groupby(["fold", "held out"], sort=True):
                r = rows["r"].to_numpy(float)
                mean_r = f"mean r {np.nanmean(r):.2f}" if np.isfinite(r).any() else "r undefined"
                self.log(f"face CV fold {fold} (held out {who}): {mean_r}, mean RMSE {rows['RMSE'].mean():.3f}")
            chosen = self.grid_results[self.grid_results["chosen"] == "yes"]
            for r in chosen.itertuples(index=False):
                self.log(f"grid: {r.blendshape} chose C {r.C:g}, gamma {r.gamma:g}, epsilon {r.epsilon:g}")
            self.grid_edges = grid_edge_warnings(self.grid_results)
            for line in self.grid_edges:
                self.log(f"warning: grid edge: {line}")
            self.results_changed.emit()
            edge = (f"; warning: {_count(self.grid_edges, 'blendshape')} chose a value at the grid's edge (see the "
                    f"run log): a wider grid may fit better" + (" (Wider grid)" if self.wider_grid() else "")
                    if self.grid_edges else "")
            notes = "".join(f"; note: {n}" for n in self.label_notes())
            self.status_changed.emit(f"trained on {len(self.outcome.series)} sessions{notes}{edge}", False)

    def label_notes(self) -> list[str]:
        """What the label sources gave, when it is not what was asked: sessions left out (labelled only by
        keys accepted from the machine), and humans + machine that added no machine-labelled second."""
        o = self.outcome
        if o is None:
            return []
        notes = []
        if o.settings.raters == "humans+machine" and o.label_comparison is None and o.label_note:
            notes.append(f"humans + machine added nothing: {o.label_note}, so the model learnt the humans' "
                         "labels alone")
        left_out = o.label_origins.get("left_out", []) if o.label_origins else []
        if left_out:
            notes.append(f"{_count(left_out, 'session')} left out ({'; '.join(left_out)})")
        return notes

    def wider_grid(self) -> str:
        """The next wider grid of :data:`~effortface.train.face_fit.GRIDS` than the current one ('' if none)."""
        from effortface.train.face_fit import GRIDS

        names = sorted(GRIDS, key=lambda g: math.prod(len(v) for v in GRIDS[g].values()))
        i = names.index(self.settings.grid) if self.settings.grid in names else len(names)
        return names[i + 1] if i + 1 < len(names) else ""

    def _exported(self, result: JobResult) -> None:
        if self._ended(result):
            exported = result.value
            self.export_changed.emit(exported.model_dir)
            if exported.not_written:  # the model is saved; say what is not, as the CLI's exit 3 does
                self.status_changed.emit(partial_export_line(exported), True)
            else:
                self.status_changed.emit(f"exported model to {exported.model_dir}", False)

    def _compared(self, result: JobResult) -> None:
        if self._ended(result):
            self.comparison = result.value
            self.comparison_changed.emit()
            self.status_changed.emit(f"compared on {result.value['session']} of {result.value['data']}",
                                     False)

    def wait(self, timeout_s: float | None = None) -> None:
        """Block until the running job ends, then :meth:`poll` (tests and scripts, not the GUI)."""
        self.jobs.wait(timeout_s)
        self.poll()

    def shutdown(self) -> None:
        """Cancel a running training (the threads are daemons; an export finishes or is discarded)."""
        self.jobs.shutdown()
