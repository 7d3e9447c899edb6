"""The Annotate stage's "Pre-annotate" action (Qt-free): the machine rater over chosen sessions, in
the background, with progress and cancel (:class:`effortface.core.jobs.Jobs`).

Each session is rated by :func:`effortface.annotate.machine.preannotate.preannotate_session` in turn;
a cancel stops the session under way, which writes nothing (the sessions finished before it keep
their tracks). A session that has a machine track already is left alone unless ``force``. The sessions
rated before the run's last are then mapped and calibrated again from their stored scores, so that each
sees every track of the run.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path

from effortface.annotate.machine.track import CSV_NAME, MACHINE_DIR
from effortface.core.events import Emitter
from effortface.core.jobs import Job, JobResult, Jobs

JOB_KEY = "pre-annotate"


@dataclasses.dataclass(frozen=True)
class PreannotateOutcome:
    """What a run did: ``written`` track files, ``skipped`` sessions (had a track), ``failed`` (session, message)."""

    written: list[Path]
    skipped: list[Path]
    failed: list[tuple[Path, str]]


def has_track(session_dir: Path) -> bool:
    """True when the session has ``machine/face_landmarker.csv``."""
    return (Path(session_dir) / MACHINE_DIR / CSV_NAME).is_file()


class PreannotateRun:
    """Pre-annotate sessions in a background job.

    Emitters: ``progress_changed(fraction, text)``, ``finished(text, is_error, outcome or None)``.
    Call :meth:`poll` from the GUI thread (a QTimer) to deliver them.
    """

    def __init__(self, rate: Callable[..., Path] | None = None) -> None:
        self.jobs = Jobs(workers=1, name="preannotate")
        self._rate = rate
        self.progress_changed, self.finished = Emitter(), Emitter()

    @property
    def busy(self) -> bool:
        """True while a run is under way."""
        return self.jobs.busy(JOB_KEY)

    def start(self, sessions: Sequence[Path], *, force: bool = False) -> Job:
        """Rate ``sessions`` (in order) in the background."""
        return self.jobs.submit(JOB_KEY, self._run, [Path(s) for s in sessions], force, takes_job=True,
                                done=self._done, progress=self.progress_changed.emit)

    def cancel(self) -> int:
        """Ask the run to stop (the session under way writes nothing)."""
        return self.jobs.cancel(JOB_KEY)

    def poll(self) -> None:
        """Deliver progress and the result (GUI thread)."""
        self.jobs.drain()

    def shutdown(self) -> None:
        """Cancel and stop the worker."""
        self.jobs.shutdown()

    def _run(self, job: Job, sessions: list[Path], force: bool) -> PreannotateOutcome:
        if self._rate is None:
            from effortface.annotate.machine.preannotate import preannotate_session
            rate = preannotate_session
        else:
            rate = self._rate
        from effortface.core.errors import UserError

        written: list[Path] = []
        skipped: list[Path] = []
        failed: list[tuple[Path, str]] = []
        rated: list[Path] = []
        for i, folder in enumerate(sessions):
            job.check("pre-annotate cancelled")
            if has_track(folder) and not force:
                skipped.append(folder)
                continue

            def progress(done: int, total: int, i: int = i, name: str = folder.name) -> None:
                job.report((i + done / max(total, 1)) / len(sessions), f"{name}: frame {done} of {total}")
            try:
                written.append(rate(folder, force=force, progress=progress, cancel=lambda: job.cancel_requested))
                rated.append(folder)
            except (UserError, OSError) as exc:
                failed.append((folder, str(exc)))
        if self._rate is None:
            self._map_again(job, rated[:-1], failed)
        return PreannotateOutcome(written, skipped, failed)

    @staticmethod
    def _map_again(job: Job, sessions: list[Path], failed: list[tuple[Path, str]]) -> None:
        """Map and calibrate the sessions rated before the run's last again, now that every track of the
        run is on disk (:func:`~effortface.annotate.machine.preannotate.remap_session`)."""
        from effortface.annotate.machine.preannotate import remap_session
        from effortface.core.errors import UserError

        for k, folder in enumerate(sessions):
            job.check("pre-annotate cancelled")
            job.report(k / len(sessions), f"{folder.name}: mapping again with the run's tracks")
            try:
                remap_session(folder)
            except (UserError, OSError) as exc:
                failed.append((folder, str(exc)))

    def _done(self, result: JobResult) -> None:
        if result.cancelled:
            self.finished.emit("pre-annotate cancelled: the session under way wrote nothing", True, None)
        elif result.error is not None:
            self.finished.emit(f"pre-annotate failed: {result.error}", True, None)
        else:
            o: PreannotateOutcome = result.value
            parts = [f"{len(o.written)} session{'s' * (len(o.written) != 1)} rated"]
            if o.skipped:
                parts.append(f"{len(o.skipped)} kept (a machine track exists)")
            parts += [f"{f.name}: {msg}" for f, msg in o.failed]
            self.finished.emit("pre-annotate: " + "; ".join(parts), bool(o.failed), o)
