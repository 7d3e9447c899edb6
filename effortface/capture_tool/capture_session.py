"""The Capture stage's model (Qt-free): drives a :class:`~effortface.capture_tool.recorder.Recorder`.

:class:`CaptureSession` follows the stage-model convention of :mod:`effortface.core`: the view
(:class:`~effortface.capture_tool.gui.capture_stage.QtCaptureStage`) calls its methods, listens to
its ``<thing>_changed`` emitters, and its QTimer calls :meth:`CaptureSession.poll`, which delivers
the background jobs (start, stop, recovery: they open devices, join threads and re-index files) and
the new rows of the live recording. Nothing here blocks the GUI thread or touches a widget (the rule: a view writes back only through model methods and keeps widget state only; worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget). What the live view plots is read back from the session files as they grow
(:class:`CsvTail`), so the screen shows exactly what is on disk.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import statistics
from pathlib import Path
from collections.abc import Callable, Sequence
from typing import Any

from effortface.core.errors import UserError
from effortface.core.events import Emitter
from effortface.core.exercises import check_exercise_id
from effortface.core.jobs import JobResult, Jobs
from effortface.capture_tool.corrections import CORRECTION_KIND, correction_value
from effortface.capture_tool.monitor import MonitorPool, StrapMonitor
from effortface.capture_tool.participants import (REGISTRY_TSV, lab_records, lab_registry, resolve_participant,
                                                  save_participant)
from effortface.capture_tool.plan import PlannedPhase, PlanRunner, parameter_events, read_plan
from effortface.capture_tool.sync import flash_offset_s, video_brightness
from effortface.capture_tool.recorder import Recorder, RecorderStatus, recover_session
from effortface.core.session.folder import (
    EVENTS_CSV,
    HEART_RATE_CSV,
    VIDEO_AVI,
    VIDEO_FRAMES_CSV,
    Event,
    Participant,
    list_sessions,
    read_events,
    read_session,
    read_session_info,
    read_video_frames,
)

#: what a capture session is doing: idle, starting, recording, stopping or recovering
STATES = ("idle", "starting", "recording", "stopping", "recovering")
#: the background jobs are busy in these states (Record and Recover wait)
BUSY_STATES = ("starting", "stopping", "recovering")


@dataclasses.dataclass(frozen=True)
class DeviceChoice:
    """What to record from: strap ``port`` (path or URL, '' for none), ``protocol``, ``camera``.

    ``camera`` is a camera index, a video file path, or None for no video.
    """

    port: str
    protocol: str
    camera: int | str | None


SYNC_KIND, FLASH_LABEL = "sync", "flash"


@dataclasses.dataclass(frozen=True)
class HrRow:
    """One ``heart_rate.csv`` row as the live view needs it."""

    t_s: float
    hr_bpm: float | None
    rr_ms: float | None
    valid: bool


@dataclasses.dataclass
class LiveUpdate:
    """What changed since the last :meth:`CaptureSession.poll`."""

    status: RecorderStatus
    hr_rows: list[HrRow]
    events: list[Event]
    frame: Any = None
    frames_bad: int = 0
    camera_ended: bool = False


#: bytes a :class:`CsvTail` reads at most per call (about 5,000 heart-rate rows): the GUI polls on its
#: own thread, so a burst (a flooding port, a poll that came late) is drawn over a few polls instead of
#: stalling one; a real strap writes about 100 bytes a second
TAIL_READ_BYTES = 128 * 1024


class CsvTail:
    """Read the complete lines appended to a CSV file since the last call (header skipped), at most
    :data:`TAIL_READ_BYTES` a call (the rest at the next).

    Parameters
    ----------
    path : path-like
        The growing file (it may not exist yet).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._offset = 0
        self._partial = b""
        self._header_seen = False

    def read_rows(self) -> list[list[str]]:
        """New complete rows, split into fields (a torn last line waits for the next call)."""
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self._offset)
                blob = fh.read(TAIL_READ_BYTES)
        except FileNotFoundError:
            return []
        self._offset += len(blob)
        lines = (self._partial + blob).split(b"\n")
        self._partial = lines.pop()
        text = [line.decode("utf-8", "replace") for line in lines if line.strip()]
        if text and not self._header_seen:
            text, self._header_seen = text[1:], True
        return list(csv.reader(text))


def _hr_row(fields: list[str]) -> HrRow | None:
    """``t_s,hr_bpm,rr_ms,beat_count,device,valid`` -> HrRow (None if malformed)."""
    try:
        t_s, hr, rr, _beat, _device, valid = fields
        rr_last = rr.split()[-1] if rr.strip() else None
        return HrRow(float(t_s), float(hr) if hr else None, float(rr_last) if rr_last else None,
                     valid.strip() == "1")
    except ValueError:
        return None


def _event(fields: list[str]) -> Event | None:
    try:
        t_s, kind, label, value = fields
        return Event(float(t_s), kind, label, value)
    except ValueError:
        return None


class CaptureSession:
    """Start, mark, poll and stop one recording at a time; find and recover crashed sessions.

    Parameters
    ----------
    out_dir : path-like
        Folder that receives the session folders.

    Attributes
    ----------
    recorder : Recorder or None
        The running recording.
    state : str
        One of :data:`STATES`.
    phase : str or None
        The exercise id of the phase running now, as logged (a catalog id: ``rest``, ``squats``...).
    events : list of Event
        The events of the running recording so far (read back from events.csv).
    plan : list of PlannedPhase
        The protocol plan the next recording steps through (empty: none).
    notes : str
        The experimenter's notes, saved as ``notes`` in session.json at Stop; emptied then, with the
        plan, so that nothing carries over into the next recording.
    monitor : StrapMonitor or None
        The strap watched before Record (live heart rate).
    last_session : Path or None
        The folder of the last recording stopped.
    recovery_failed : set of Path
        Sessions whose recovery failed in this run (not offered again).
    jobs : Jobs
        Start, stop and recovery, one at a time, in order.

    Notes
    -----
    Emitters: ``state_changed(state)``, ``recording_changed(path or None)`` (a recording started
    into ``path``, or stopped), ``live_changed(LiveUpdate)`` (from :meth:`poll`),
    ``status_changed(text, is_error)`` (what a start, stop or recovery did),
    ``incomplete_changed(sessions)`` (from :meth:`check_incomplete`), ``phase_changed(exercise or
    None)``, ``plan_changed(text)`` (the plan loaded, then its countdown lines),
    ``monitor_changed(MonitorStats or None)`` (from :meth:`poll` before Record),
    ``sync_changed(dict or None)`` (the sync test measured at Stop; None: none was done).
    """

    def __init__(self, out_dir: str | os.PathLike) -> None:
        self.out_dir = Path(out_dir)
        self.recorder: Recorder | None = None
        self.state = "idle"
        self.phase: str | None = None
        self.last_session: Path | None = None
        self.recovery_failed: set[Path] = set()
        self.jobs = Jobs(workers=1, name="capture")
        self._recovering: Path | None = None
        self._tails: tuple[CsvTail, CsvTail] | None = None
        self._latest_frame: Any = None
        self.state_changed, self.recording_changed = Emitter(), Emitter()
        self.live_changed, self.status_changed = Emitter(), Emitter()
        self.incomplete_changed = Emitter()
        self.phase_changed, self.plan_changed = Emitter(), Emitter()
        self.monitor_changed, self.sync_changed = Emitter(), Emitter()
        self.events: list[Event] = []
        self.plan: list[PlannedPhase] = []
        self.notes = ""
        self.monitor: StrapMonitor | None = None
        self.reps = 0
        self.flashes = 0  # sync flashes of the running recording
        self.phase_start_s: float | None = None
        self._corrected: dict[float, str] = {}
        self._runner: PlanRunner | None = None
        self._monitors = MonitorPool()

    @property
    def recording(self) -> bool:
        """True between :meth:`start` and :meth:`stop`."""
        return self.recorder is not None

    @property
    def busy(self) -> bool:
        """True while a start, stop or recovery runs in the background."""
        return self.state in BUSY_STATES

    def _set_state(self, state: str) -> None:
        if state not in STATES:
            raise ValueError(f"state: expected one of {', '.join(STATES)}, found {state!r}")
        self.state = state
        self.state_changed.emit(state)

    # ---------------------------------------------------------------- blocking primitives
    def start(self, participant: Participant, choice: DeviceChoice, label: str = "", lsl: bool = False,
              update_participant: bool = False) -> Path:
        """Open the devices and start a new session; return its folder (blocking). ``lsl``: also publish
        the strap and events as LSL streams, see :mod:`effortface.capture_tool.lsl`.
        ``update_participant``: a participant that differs from the lab's record changes it on purpose.

        Raises
        ------
        UserError
            If already recording, no port is chosen, or a device cannot be opened
            (DeviceError, a UserError, says which).
        """
        if self.recorder is not None:
            raise UserError("Record: expected no recording running, found one (stop it first)")
        if not choice.port:
            raise UserError("Strap port: expected a serial port or URL, found none chosen")
        participant, new = self.resolve_participant(participant, update=update_participant)
        recorder = Recorder(self.out_dir, participant, choice.port, choice.protocol,
                            video=choice.camera, label=label or None, lsl=lsl)
        path = recorder.start()
        self.recorder, self.phase, self._latest_frame = recorder, None, None
        self.events, self.reps, self._corrected, self.flashes = [], 0, {}, 0
        self._tails = (CsvTail(path / HEART_RATE_CSV), CsvTail(path / EVENTS_CSV))
        if new:
            save_participant(self.registry_path, participant)
        return path

    # ------------------------------------------------------------------------ participants
    @property
    def registry_path(self) -> Path:
        """The lab's participant registry (``participants.tsv`` in :attr:`out_dir`)."""
        return self.out_dir / REGISTRY_TSV

    def known_participants(self) -> dict[str, Participant]:
        """The lab's participants by code: its registry, or without one its sessions' latest records.

        Raises
        ------
        RegistryError
            If participants.tsv cannot be read (the message names the file and line).
        """
        return lab_registry(self.out_dir)

    def participant_records(self) -> tuple[dict[str, Participant], dict[str, str]]:
        """:meth:`known_participants` and, per code, the file its record comes from (relative to the
        lab folder, as the form shows it)."""
        people, sources = lab_records(self.out_dir)
        return people, {code: _relative(path, self.out_dir) for code, path in sources.items()}

    def resolve_participant(self, participant: Participant, update: bool = False) -> tuple[Participant, bool]:
        """Check that the form confirmed every required field and agrees with the lab's record
        (``update``: it changes the record on purpose).

        Returns
        -------
        (Participant, bool)
            The participant (measured HR completed from the registry) and True if it is saved to the
            registry when the recording starts (a new code, or a record changed on purpose).

        Raises
        ------
        RegistryError
            A required field (sex, age, height, mass, training level) not confirmed, or one that
            contradicts the registry; the message names them.
        """
        options = {f: getattr(participant, f) for f in ("sex", "age", "height_m", "mass_kg", "training_level",
                                                         "hr_rest_bpm", "hr_max_bpm")}
        return resolve_participant(participant.code, options, self.registry_path, update=update,
                                   hint="choose 'Use the record' or 'Change the record'")

    def stop(self) -> Path:
        """End the running phase, stop the recording (session complete) and measure the sync test.

        Blocking (the application calls it when it closes); :meth:`stop_in_background` for the GUI.

        Returns
        -------
        Path
            The session folder.
        """
        recorder = self.recorder
        if recorder is None:
            raise UserError("Stop: expected a recording running, found none")
        self._finish_plan()
        if self.phase is not None:
            recorder.mark("phase_end", self.phase)
        if self.notes.strip() and recorder.info is not None:
            recorder.info.extra["notes"] = self.notes.strip()
        path = recorder.stop()
        self.recorder, self.phase, self._tails, self.last_session = None, None, None, path
        self.notes, self.plan = "", []  # nothing carries over into the next recording
        store_sync_result(path)
        return path

    def recover(self, folder: str | os.PathLike) -> dict[str, Any]:
        """Finish an incomplete session (blocking: :meth:`recover_in_background` for the GUI)."""
        return recover_session(folder)

    # ------------------------------------------------------------------- background jobs
    def start_in_background(self, participant: Participant, choice: DeviceChoice, label: str = "",
                            lsl: bool = False, update_participant: bool = False) -> None:
        """Start a recording in a job: ``state_changed('starting')``, then ``recording_changed(path)``
        or ``status_changed(error, True)`` from :meth:`poll`."""
        self._set_state("starting")
        monitor, self.monitor = self.monitor, None  # the recorder opens the port: the monitor lets go
        self.jobs.submit("start", self._start_after, monitor, participant, choice, label, lsl, update_participant,
                         done=self._start_done)

    def _start_after(self, monitor: StrapMonitor | None, participant: Participant, choice: DeviceChoice,
                     label: str, lsl: bool = False, update_participant: bool = False) -> Path:
        """Runs in the job thread: stop the strap monitor, then :meth:`start`."""
        if monitor is not None:
            monitor.stop()
        return self.start(participant, choice, label, lsl, update_participant)

    def stop_in_background(self) -> None:
        """Stop in a job; the session is closed, marked complete and summarised."""
        self._finish_plan()  # here, on the GUI thread that steps it, never beside a step
        self._set_state("stopping")
        self.jobs.submit("stop", self._stop_and_summarise, done=self._stop_done)

    def _finish_plan(self) -> None:
        """Stop stepping the plan; a plan phase still open gets its ``phase_end`` now."""
        runner, self._runner = self._runner, None
        if runner is not None:
            runner.finish()

    def _stop_and_summarise(self) -> tuple[Path, str, dict[str, Any] | None]:
        """Runs in the job thread: stop, then read the session back for the summary line and sync test."""
        path = self.stop()
        return path, session_summary(path), read_session_info(path).extra.get("sync")

    def recover_in_background(self, folder: str | os.PathLike) -> bool:
        """Recover ``folder`` in a job (nothing happens while busy or recording); True if started."""
        if self.busy or self.recording or not str(folder):
            return False
        self._recovering = Path(folder)
        self._set_state("recovering")
        self.jobs.submit("recover", self.recover, folder, done=self._recover_done)
        return True

    def _start_done(self, result: JobResult) -> None:
        if result.error is not None:
            self._set_state("idle")
            self.status_changed.emit(f"Could not start: {result.error}", True)
            if not isinstance(result.error, (UserError, OSError)):
                raise result.error
            return
        self._set_state("recording")
        if self.plan:
            self._runner = PlanRunner(self.plan, self._plan_mark, self.plan_changed.emit)
        self.recording_changed.emit(Path(result.value))

    def _stop_done(self, result: JobResult) -> None:
        self._set_state("idle")
        if result.error is not None:
            self.status_changed.emit(f"Stop failed: {result.error}", True)
            raise result.error
        _path, summary, sync = result.value
        self.plan_changed.emit("")  # the plan was for that recording (stop() emptied it)
        self.recording_changed.emit(None)
        self.sync_changed.emit(sync)
        if sync is None and (Path(_path) / VIDEO_AVI).exists():  # said first: the banner shows two lines,
            # the rest is in its tooltip; without video there is nothing to synchronise
            summary = ("No sync test was measured: press F8 (the screen flashes) while the camera sees it. "
                       + summary)
        self.status_changed.emit(summary, False)

    def _recover_done(self, result: JobResult) -> None:
        """Say what the recovery did or why it failed; offer the incomplete sessions again.

        A session whose recovery failed is not offered again in this run, so a broken one never
        hides the others.
        """
        folder, self._recovering = self._recovering, None
        name = folder.name if folder is not None else "the session"
        self._set_state("idle")
        if result.error is not None:
            if folder is not None:
                self.recovery_failed.add(folder)
            self.status_changed.emit(f"Recovery of {name} failed: {_error_line(result.error)}", True)
        else:
            self.status_changed.emit(f"Recovered {name}: " + "; ".join(result.value.get("done", [])), False)
        self.check_incomplete()

    # ---------------------------------------------------------------------- marks, phases
    def mark(self, kind: str, label: str = "", value: str = "") -> float:
        """Write an event on the session clock; return its time in seconds.

        Raises
        ------
        UserError
            If nothing is recording.
        """
        if self.recorder is None:
            raise UserError(f"{kind}: expected a recording running, found none (press Record first)")
        return self.recorder.mark(kind, label, value)

    def start_phase(self, exercise: str, parameters: Sequence[tuple[str, float]] = ()) -> float:
        """End the running phase (if any) and start ``exercise`` with its parameters; return the start time.

        Parameters
        ----------
        exercise : str
            An exercise id of the catalog (``rest``, ``treadmill_walk``, ``squats``...).
        parameters : sequence of (column, value)
            Plan columns (``speed_m_s``, ``back_kg``...) logged right after ``phase_start``.

        Raises
        ------
        UserError
            Nothing recording, or an exercise id not in the catalog (names the catalog).
        """
        check_exercise_id(exercise, "exercise")
        if self.recorder is None:
            raise UserError(f"phase {exercise}: expected a recording running, found none (press Record first)")
        self.end_phase()
        t_s = self.mark("phase_start", exercise)
        self.phase, self.reps, self.phase_start_s = exercise, 0, t_s
        for kind, label, value in parameter_events(exercise, parameters):
            self.mark(kind, label, value)
        self.phase_changed.emit(exercise)
        return t_s

    def end_phase(self) -> float | None:
        """End the running phase (``phase_end``); return its time, None if no phase runs."""
        if self.phase is None:
            return None
        t_s = self.mark("phase_end", self.phase)
        self.phase = None
        self.phase_changed.emit(None)
        return t_s

    def log_parameters(self, parameters: Sequence[tuple[str, float]]) -> float | None:
        """Log a speed/grade/power/cadence/range/load change for the running exercise.

        Returns the time, or None when ``parameters`` is empty.

        Raises
        ------
        UserError
            Nothing recording, or a speed/power/cadence/load given with no phase running (they are
            labelled with the exercise).
        """
        if not parameters:
            return None
        needs_phase = [name for name, _ in parameters if not name.endswith("_kg")]
        if needs_phase and self.phase is None:
            raise UserError(f"{', '.join(needs_phase)}: expected a running exercise phase to label them with "
                            "(start one: F2), found none")
        t_s = None
        for kind, label, value in parameter_events(self.phase or "", parameters):
            t_s = self.mark(kind, label, value)
        return t_s

    def count_rep(self) -> int:
        """Count one repetition of the running exercise (a ``reps`` row: the count so far); return it.

        Raises
        ------
        UserError
            If no phase runs.
        """
        if self.phase is None:
            raise UserError("reps: expected a running exercise phase to count, found none (start one: F2)")
        self.reps += 1
        self.mark("reps", self.phase, str(self.reps))
        return self.reps

    @property
    def current_exercise(self) -> str | None:
        """The running phase's exercise, as corrected (:meth:`correct_phase`)."""
        if self.phase is None:
            return None
        return next((label for t_s, label in self._corrected.items()
                     if self.phase_start_s is not None and abs(t_s - self.phase_start_s) < 2e-4), self.phase)

    def correct_phase(self, phase_start: Event, exercise: str) -> float:
        """Say that the phase started by ``phase_start`` was in fact ``exercise`` (a ``correction`` row).

        History is never rewritten: the correction is a new row that readers apply
        (:func:`effortface.capture_tool.corrections.apply_corrections`).

        Raises
        ------
        UserError
            Nothing recording, an event that is not a phase start of this recording, or an
            exercise id not in the catalog.
        """
        check_exercise_id(exercise, "correction")
        if phase_start.kind != "phase_start" or phase_start not in self.events:
            raise UserError(f"correction: expected a phase start of this recording, found {phase_start.kind} "
                            f"{phase_start.label!r} at {phase_start.t_s:.1f} s")
        t_s = self.mark(CORRECTION_KIND, exercise, correction_value(phase_start.t_s))
        self._corrected[phase_start.t_s] = exercise
        self.phase_changed.emit(self.phase)
        return t_s

    def corrected_label(self, phase_start: Event) -> str | None:
        """The exercise a phase start was corrected to (None: not corrected)."""
        return self._corrected.get(phase_start.t_s)

    # ------------------------------------------------------------------------------ plan, notes
    def load_plan(self, path: str | os.PathLike | None) -> list[PlannedPhase]:
        """Read a protocol plan for the next recording (None or '' clears it); ``plan_changed``.

        Raises
        ------
        PlanError
            If the plan cannot be followed (names the file and line); the previous plan is kept.
        """
        if self.recording:
            raise UserError("plan: expected no recording running to change the plan, found one")
        self.plan = read_plan(path) if path else []
        text = (f"plan {Path(path).name}: {len(self.plan)} phases, {format_elapsed(self.plan[-1].end_s)} "
                f"(starts with Record)" if path and self.plan else "")
        self.plan_changed.emit(text)
        return self.plan

    def _plan_mark(self, kind: str, label: str, value: str) -> float:
        """The plan's rows go through the session so that the running phase is known."""
        if kind == "phase_start":
            self.end_phase()
            t_s = self.mark(kind, label, value)
            self.phase, self.reps, self.phase_start_s = label, 0, t_s
            self.phase_changed.emit(label)
            return t_s
        if kind == "phase_end":
            if self.phase == label:
                return self.end_phase() or 0.0
            return self.mark(kind, label, value)
        return self.mark(kind, label, value)

    def set_notes(self, text: str) -> None:
        """The experimenter's notes (saved as ``notes`` in session.json at Stop)."""
        self.notes = text

    # ------------------------------------------------------------------------- strap monitor
    def watch_strap(self, port: str, protocol: str) -> None:
        """Show the strap's live heart rate before Record: open ``port`` in a job (replaces a watch).

        Nothing happens while recording or busy; a port that cannot be opened is said by
        ``status_changed``.
        """
        if self.recording or self.busy:
            return
        self.unwatch_strap()
        if port:
            self.jobs.submit("monitor", self._open_monitor, port, protocol, done=self._monitor_done)

    def _open_monitor(self, port: str, protocol: str) -> StrapMonitor:
        return self._monitors.open(port, protocol)  # closed at shutdown even if never delivered

    def _monitor_done(self, result: JobResult) -> None:
        if result.error is not None:
            self.monitor_changed.emit(None)
            if not isinstance(result.error, (UserError, OSError)):
                raise result.error
            self.status_changed.emit(f"Live heart rate: {_error_line(result.error)}", True)
            return
        if self.recording or self.busy:  # Record was pressed while it opened
            self.jobs.submit("monitor-stop", result.value.stop, done=_ignore)
            return
        self.monitor = result.value

    def unwatch_strap(self) -> None:
        """Stop watching the strap (in a job: closing a port may take a moment)."""
        monitor, self.monitor = self.monitor, None
        if monitor is not None:
            self.jobs.submit("monitor-stop", monitor.stop, done=_ignore)
            self.monitor_changed.emit(None)

    def release_monitor(self) -> Callable[[], None]:
        """Stop showing the strap and return the blocking close of its port, to run in a job
        (protocol detection needs the port to itself)."""
        monitor, self.monitor = self.monitor, None
        if monitor is None:
            return _nothing
        self.monitor_changed.emit(None)
        return monitor.stop

    def watching(self, port: str, protocol: str | None = None) -> bool:
        """True if the monitor holds ``port`` now (with ``protocol``, if given): the pre-flight need
        not open it again."""
        monitor = self.monitor
        return (monitor is not None and monitor.port == port
                and (protocol is None or monitor.protocol == protocol))

    def sync_flash(self) -> float:
        """Record the on-screen flash of the sync self-test; return its time."""
        t_s = self.mark(SYNC_KIND, FLASH_LABEL)
        self.flashes += 1
        return t_s

    def needs_sync_reminder(self) -> bool:
        """True while recording video without a sync flash yet (Stop reminds the operator)."""
        recorder = self.recorder
        return recorder is not None and getattr(recorder, "camera", None) is not None and self.flashes == 0

    # ---------------------------------------------------------------------------- polling
    def poll(self) -> LiveUpdate | None:
        """Deliver finished jobs, then what the recording wrote since the last call (never blocks).

        The new rows go to ``live_changed`` and are returned (None when not recording).
        """
        self.jobs.drain()
        if self.monitor is not None and not self.recording:
            self.monitor_changed.emit(self.monitor.poll())
        update = self.live_update()
        if update is not None:
            if self._runner is not None and self.recorder is not None:
                self._runner.step(self.recorder.clock())
            self.events.extend(update.events)
            self.live_changed.emit(update)
        return update

    def live_update(self) -> LiveUpdate | None:
        """What changed since the last call (None when not recording); never blocks."""
        recorder = self.recorder
        if recorder is None or self._tails is None:
            return None
        hr_tail, event_tail = self._tails
        rows = [r for r in map(_hr_row, hr_tail.read_rows()) if r is not None]
        events = [e for e in map(_event, event_tail.read_rows()) if e is not None]
        camera = recorder.camera
        frame = None if camera is None else camera.latest_frame
        if frame is self._latest_frame:
            frame = None  # nothing new since the last poll
        else:
            self._latest_frame = frame
        return LiveUpdate(recorder.status(), rows, events, frame,
                          frames_bad=recorder.link.decoder.stats.frames_bad,
                          camera_ended=bool(camera is not None and camera.ended))

    # --------------------------------------------------------------------------- recovery
    def incomplete_sessions(self) -> list[Path]:
        """Session folders in :attr:`out_dir` that a crash left with ``complete: false``."""
        if not self.out_dir.is_dir():
            return []
        out = []
        for folder in list_sessions(self.out_dir):
            try:
                if not read_session_info(folder).complete:
                    out.append(folder)
            except UserError:
                continue
        return out

    def check_incomplete(self) -> list[Path]:
        """Scan for incomplete sessions, emit ``incomplete_changed(sessions)`` and return them."""
        sessions = self.incomplete_sessions()
        self.incomplete_changed.emit(sessions)
        return sessions

    def shutdown(self) -> None:
        """Stop the strap monitors (also one a job opened but did not deliver) and the background jobs."""
        self.monitor = None
        self.jobs.shutdown()
        self._monitors.close_all()


def _nothing() -> None:
    """Nothing to close."""


def _ignore(result: JobResult) -> None:
    """``done`` of a job whose outcome does not matter (closing a monitor's port)."""


def format_elapsed(t_s: float) -> str:
    """``h:mm:ss`` of a duration in seconds."""
    total = int(max(t_s, 0.0))
    return f"{total // 3600}:{total % 3600 // 60:02d}:{total % 60:02d}"


def session_summary(folder: Path) -> str:
    """One line about a stopped session: id, duration, samples, frames, events (from its files)."""
    session = read_session(folder)
    stats = session.info.extra.get("stats", {})
    phases = sum(e.kind == "phase_start" for e in session.events)
    return (f"Saved, complete: {session.info.session_id}  -  {format_elapsed(stats.get('duration_s', 0.0))}, "
            f"{len(session.heart_rate)} HR rows, {len(session.frame_times_s)} video frames "
            f"({stats.get('dropped_frames', 0)} dropped), {phases} phases, {len(session.events)} events")


def _relative(path: str, folder: Path) -> str:
    """``path`` relative to ``folder`` when inside it, else as given."""
    try:
        return str(Path(path).relative_to(folder))
    except ValueError:
        return path


def _error_line(error: BaseException) -> str:
    """One line for an error: its message (a UserError's says what and where), else type and message."""
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return text if isinstance(error, UserError) else f"{type(error).__name__}: {text}"


def measure_sync(folder: str | os.PathLike) -> dict[str, Any]:
    """Measure the video-to-HR offset from the sync flashes recorded in a session.

    Parameters
    ----------
    folder : path-like
        A session folder with ``events.csv`` (and ``video.avi`` + ``video_frames.csv``).

    Returns
    -------
    dict
        ``flashes`` (event times), ``offsets_s`` (one per flash seen in the video),
        ``video_offset_s`` (their median, or None) and a ``note``.
    """
    folder = Path(folder)
    flashes = [e.t_s for e in read_events(folder / EVENTS_CSV)
               if e.kind == SYNC_KIND and e.label == FLASH_LABEL]
    result: dict[str, Any] = {"flashes_t_s": flashes, "offsets_s": [], "video_offset_s": None}
    if not flashes:
        return {**result, "note": "no sync flash in events.csv"}
    if not (folder / VIDEO_AVI).exists():
        return {**result, "note": "no video recorded"}
    times = read_video_frames(folder / VIDEO_FRAMES_CSV)
    for t_flash in flashes:
        offset = _offset_near(folder / VIDEO_AVI, times, t_flash)
        if offset is not None:
            result["offsets_s"].append(round(offset, 4))
    if result["offsets_s"]:
        result["video_offset_s"] = round(statistics.median(result["offsets_s"]), 4)
        return {**result, "note": "video time minus event time of the first bright frame (median)"}
    return {**result, "note": "flash not seen in the video (camera not facing the screen, or a file)"}


def _offset_near(avi: Path, times: list[float], t_flash_s: float) -> float | None:
    """Offset of one flash, reading only the frames from 1 s before to 2 s after it."""
    idx = [i for i, t in enumerate(times) if t_flash_s - 1.0 <= t <= t_flash_s + 2.0]
    if not idx:
        return None
    brightness = video_brightness(avi, idx[0], idx[-1])
    return flash_offset_s(times[idx[0]:idx[0] + len(brightness)], brightness, t_flash_s)


def store_sync_result(folder: str | os.PathLike) -> dict[str, Any] | None:
    """Measure the sync test of a session and store it as ``sync`` in its ``session.json``.

    Returns the stored dict, or None when the session has no flash (nothing is written).
    """
    result = measure_sync(folder)
    if not result["flashes_t_s"]:
        return None
    info = read_session_info(folder)
    info.extra["sync"] = result
    info.save(folder, overwrite=True)
    return result
