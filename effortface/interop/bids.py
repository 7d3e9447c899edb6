"""BIDS out: session folders -> a BIDS-style dataset (``effortface export bids``).

Layout (BIDS 1.9, behavioural data with physiological recordings, attached mocap as motion)::

    dataset_description.json  participants.tsv  participants.json  README
    sub-<code>/sub-<code>_sessions.tsv (+ .json)   (each session's acq_time and body record)
    sub-<code>/ses-<YYYYmmddHHMMSS>/beh/
        sub-<code>_ses-<...>_task-<label>_recording-heartrate_physio.tsv.gz (+ .json)
        sub-<code>_ses-<...>_task-<label>_recording-work_physio.tsv.gz (+ .json, with work.csv)
        sub-<code>_ses-<...>_task-<label>_events.tsv (+ .json)
    sub-<code>/ses-<YYYYmmddHHMMSS>/motion/   (sessions with clips in motion/motion.json)
        sub-<code>_ses-<...>_task-<label>_tracksys-mocap[_run-<n>]_motion.tsv (+ .json, _channels.tsv)

Labels are sanitised to letters and digits (BIDS labels are alphanumeric): ``LAB2-07`` becomes
``LAB207`` (two codes that collide are an error), the task is the session label (``cardio``) or
``effort``. BIDS physiological files need a constant rate: heart rate is linearly interpolated
from the valid strap samples at :data:`HR_RATE_HZ` (``n/a`` across gaps longer than
``effortface.train.dataset.MAX_HR_GAP_S``), work and power at their own rate (irregular times, an
XDF stream with a drop-out, on a grid at their median rate, ``n/a`` where no sample is within half a
period: :func:`regular_grid`, stated). Two sessions of one participant starting in the same second get
``ses-<YYYYmmddHHMMSS><label>`` (:func:`session_labels`). Nothing is left out without a word: what an
export leaves out is listed in :class:`ExportNotes` and at the end of the README (:func:`export_bids`). Each
physio sidecar has ``SamplingFrequency``, ``StartTime`` (seconds from the session's time 0, which is
also the events' onset origin) and ``Columns``, with units per column, ``PhysioType`` and
``TaskName``.

The lab's own description: an optional ``dataset_description.json`` in the sessions folder, edited by
the user, gives the BIDS keys of the output's ``dataset_description.json`` (``Name``, ``Authors``,
``License``, ``Funding``...) and, under the key ``"effortface"``, what BIDS wants elsewhere:
``{"README": "text", "Tasks": {"cardio": {"TaskName": "cardio", "TaskDescription": "..."}},
"Sidecars": {"InstitutionName": "..."}, "PhysioType": "generic"}``: ``Tasks`` gives the keys of the
sidecars of each session label (``TaskName`` defaults to the label), ``Sidecars`` the keys of every
sidecar
(:data:`LAB_DESCRIPTION`, :func:`read_lab_description`). A failed export removes what it wrote.
"""

from __future__ import annotations

import collections
import csv
import dataclasses
import datetime
import gzip
import io
import os
import re
import secrets
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from effortface.core.session.hr_csv import read_hr_csv
from effortface.core.session.folder import (EVENTS_CSV, HEART_RATE_CSV, list_sessions, parse_session_id, read_events,
                                            read_session)
from effortface.core.errors import UserError
from effortface.core.participant import Participant
from effortface.core.fileio import atomic_write, atomic_write_text, check_apart, fsync_folder, read_json, write_json_atomic
from effortface.core.stops import stops_deferred
from effortface.core.version import __version__
from effortface.train.dataset import MAX_HR_GAP_S, WORK_CSV

BIDS_VERSION = "1.9.0"
HR_RATE_HZ = 4.0
DATATYPE = "beh"
#: attached mocap clips go to the BIDS motion datatype, tracking system ``mocap``
MOTION_DATATYPE, MOTION_TRACKSYS = "motion", "mocap"
#: the lab-level description the user edits, in the sessions folder
LAB_DESCRIPTION = "dataset_description.json"
#: keys of the lab description's ``"effortface"`` object
LAB_KEYS = ("README", "Tasks", "Sidecars", "PhysioType")
#: the physio types BIDS 1.10 defines
PHYSIO_TYPES = ("generic", "eyetrack")
DEFAULT_README = ("Exported by effortface: heart rate, mechanical work and events of exercise sessions "
                  "(see the effortface README).\n")


@dataclasses.dataclass(frozen=True)
class LabDescription:
    """What the lab's own ``dataset_description.json`` says.

    Attributes
    ----------
    bids : dict
        BIDS keys for the output's ``dataset_description.json`` (``Name``, ``Authors``...).
    readme : str
        The README text.
    tasks : dict
        Session label (``cardio``) -> keys of its sidecars (``TaskName``, ``TaskDescription``...).
    sidecars : dict
        Keys of every sidecar (``InstitutionName``...).
    physio_type : str
        ``PhysioType`` of the physio sidecars.
    """

    bids: dict
    readme: str
    tasks: dict
    sidecars: dict
    physio_type: str

    def sidecar_keys(self, label: str) -> dict:
        """The keys a sidecar of session label ``label`` gets: ``TaskName`` (the label by default)
        and the lab's."""
        return {"TaskName": label, **self.sidecars, **self.tasks.get(label, {})}


def read_lab_description(sessions_dir: str | os.PathLike) -> LabDescription:
    """The lab's description (:data:`LAB_DESCRIPTION` in ``sessions_dir``), or the defaults without one.

    Raises
    ------
    UserError
        A file that is not a JSON object, an ``"effortface"`` object with other keys or values of the
        wrong type, in one line naming the file.
    """
    path = Path(sessions_dir) / LAB_DESCRIPTION
    if not path.exists():
        return LabDescription({}, DEFAULT_README, {}, {}, "generic")
    doc = read_json(path, "a JSON object (the lab's BIDS dataset description)")
    if not isinstance(doc, dict):
        raise UserError(f"{path}: expected a JSON object, found {type(doc).__name__}")
    own = doc.get("effortface", {})
    if not isinstance(own, dict) or set(own) - set(LAB_KEYS):
        raise UserError(f"{path}: \"effortface\": expected an object with keys among {', '.join(LAB_KEYS)}, "
                        f"found {sorted(own) if isinstance(own, dict) else type(own).__name__}")
    readme, physio = own.get("README", DEFAULT_README), own.get("PhysioType", "generic")
    tasks, sidecars = own.get("Tasks", {}), own.get("Sidecars", {})
    if not isinstance(readme, str) or not readme.strip():
        raise UserError(f"{path}: \"effortface\".README: expected text, found {readme!r}")
    if not isinstance(tasks, dict) or not all(isinstance(v, dict) for v in tasks.values()):
        raise UserError(f"{path}: \"effortface\".Tasks: expected an object session label -> sidecar keys, "
                        f"found {tasks!r}")
    if not isinstance(sidecars, dict):
        raise UserError(f"{path}: \"effortface\".Sidecars: expected an object of sidecar keys, found {sidecars!r}")
    if physio not in PHYSIO_TYPES:
        raise UserError(f"{path}: \"effortface\".PhysioType: expected one of {', '.join(PHYSIO_TYPES)}, found {physio!r}")
    bids = {k: v for k, v in doc.items() if k != "effortface"}
    return LabDescription(bids, readme if readme.endswith("\n") else readme + "\n", tasks, sidecars, physio)


def bids_label(text: str) -> str:
    """A BIDS label: letters and digits only (``LAB2-07`` -> ``LAB207``)."""
    label = re.sub(r"[^A-Za-z0-9]", "", text)
    if not label:
        raise UserError(f"BIDS label: expected letters or digits in {text!r}, found none")
    return label


#: characters a BIDS TSV cell cannot hold (tab, line breaks, NUL and the other C0 controls, DEL)
_NOT_IN_A_CELL = re.compile(r"[\x00-\x1f\x7f]+")


def bids_text(text: str) -> str:
    """``text`` as one BIDS TSV cell: each run of tabs, line breaks, NUL or other control characters
    becomes one space (a marker from ``import xdf`` may hold any of them), ``n/a`` if nothing is left."""
    return _NOT_IN_A_CELL.sub(" ", text).strip() or "n/a"


def _tsv(rows: Sequence[Sequence[object]], header: Sequence[str] | None) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, delimiter="\t", lineterminator="\n")
    if header is not None:
        writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


def _value(v: float) -> str:
    return "n/a" if not np.isfinite(v) else f"{v:.6g}"


def hr_grid(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """Heart rate at :data:`HR_RATE_HZ` from the valid samples (NaN across long gaps)."""
    samples = [s for s in read_hr_csv(folder / HEART_RATE_CSV) if s.valid and s.hr_bpm is not None]
    if len(samples) < 2:
        return np.array([]), np.array([])
    t = np.array([s.t_s for s in samples])
    hr = np.array([float(s.hr_bpm) for s in samples])  # type: ignore[arg-type]
    grid = np.arange(np.ceil(t[0] * HR_RATE_HZ), np.floor(t[-1] * HR_RATE_HZ) + 1) / HR_RATE_HZ
    values = np.interp(grid, t, hr)
    gap_after = np.searchsorted(t, grid, side="right")
    gap_s = t[np.minimum(gap_after, len(t) - 1)] - t[np.maximum(gap_after - 1, 0)]
    values[gap_s > MAX_HR_GAP_S] = np.nan
    return grid, values


def _write_physio(stem: Path, columns: dict[str, str], t_s: np.ndarray, table: np.ndarray, rate_hz: float,
                  description: str, extra: dict) -> None:
    text = _tsv([[_value(v) for v in row] for row in table], None)
    atomic_write(stem.with_name(stem.name + "_physio.tsv.gz"),
                 lambda fh: fh.write(gzip.compress(text.encode(), mtime=0)))
    write_json_atomic(stem.with_name(stem.name + "_physio.json"), {
        "SamplingFrequency": rate_hz, "StartTime": float(t_s[0]) if len(t_s) else 0.0,
        "Columns": list(columns), "Description": description, **extra,
        **{name: {"Units": unit} for name, unit in columns.items()}})


def _events(folder: Path) -> list[list[str]]:
    """``onset, duration, trial_type, value`` rows of events.csv (phases get their duration), read by
    the session's checked reader (:func:`~effortface.core.session.folder.read_events`)."""
    events = read_events(folder / EVENTS_CSV)
    out = []
    for i, e in enumerate(events):
        duration = "n/a"
        if e.kind == "phase_start":
            end = next((n.t_s for n in events[i + 1:] if n.kind in ("phase_end", "phase_start")), None)
            duration = f"{end - e.t_s:.4f}" if end is not None else "n/a"
        label = _NOT_IN_A_CELL.sub(" ", e.label).strip()
        trial = f"{e.kind}:{label}" if label else e.kind
        out.append([f"{e.t_s:.4f}", duration, bids_text(trial), bids_text(e.value or "")])
    return out


@dataclasses.dataclass
class ExportNotes:
    """What an export left out or changed, stated on stderr by the command and (omissions) in the
    dataset's README.

    Attributes
    ----------
    skip_invalid : bool
        Leave out a session's part that cannot be read or derived (its work, a motion clip) instead
        of refusing (``--skip-invalid``).
    omitted : list of str
        One line per part left out: ``sub-P01/ses-...: mechanical work: <why>``.
    notes : list of str
        One line per other thing to know (resampled work, session labels made distinct).
    """

    skip_invalid: bool = False
    omitted: list[str] = dataclasses.field(default_factory=list)
    notes: list[str] = dataclasses.field(default_factory=list)

    def leave_out(self, where: str, what: str, exc: UserError, refuse: bool) -> None:
        """Record that ``what`` of ``where`` is left out because of ``exc``; with ``refuse`` (a file
        that cannot be read or derived) and without :attr:`skip_invalid`, raise it instead, naming
        the way on."""
        if refuse and not self.skip_invalid:
            raise UserError(f"{exc} (its {what} cannot be exported: fix it, or --skip-invalid to export "
                            f"without it, stated in the dataset's README)") from None
        self.omitted.append(f"{where}: {what} left out: {exc}")


def session_labels(folders: Sequence[Path]) -> dict[Path, str]:
    """Each session folder's BIDS session label: its start ``YYYYmmddHHMMSS``, followed by its
    sanitised session label (``20260112093000cardio``) when another session of the same participant
    starts in the same second.

    Raises
    ------
    UserError
        Two sessions of one participant that still get one label (labels equal once sanitised).
    """
    keys: dict[Path, tuple[str, str]] = {}
    for folder in folders:
        code, start, _ = parse_session_id(folder.name)
        keys[folder] = (bids_label(code), start.strftime("%Y%m%d%H%M%S"))
    out: dict[Path, str] = {}
    seen: dict[tuple[str, str], Path] = {}
    count = collections.Counter(keys.values())
    for folder, (sub, ses) in keys.items():
        if count[sub, ses] > 1:
            ses += bids_label(parse_session_id(folder.name)[2] or "effort")
        if (sub, ses) in seen:
            raise UserError(f"{folder}: expected one BIDS session per session folder, found the same "
                            f"sub-{sub}/ses-{ses} as {seen[sub, ses]} (same participant, same start second, "
                            f"same label once sanitised): rename one")
        seen[sub, ses] = folder
        out[folder] = ses
    return out


def export_session(folder: Path, out: Path, sub: str, lab: LabDescription | None = None, *,
                   ses: str | None = None, notes: ExportNotes | None = None) -> Path:
    """Write one session's files under ``out/sub-<sub>/ses-<ses>/beh``; return that folder.

    ``ses`` defaults to the session's start ``YYYYmmddHHMMSS`` (:func:`session_labels` makes the labels
    of a lab distinct); what is left out or resampled is recorded in ``notes`` (:class:`ExportNotes`).
    """
    lab = lab or LabDescription({}, DEFAULT_README, {}, {}, "generic")
    notes = notes if notes is not None else ExportNotes()
    _, start, label = parse_session_id(folder.name)
    ses, task = ses or start.strftime("%Y%m%d%H%M%S"), bids_label(label or "effort")
    where = f"sub-{sub}/ses-{ses} ({folder.name})"
    task_keys = lab.sidecar_keys(label or "effort")
    physio_keys = {"PhysioType": lab.physio_type, **task_keys}
    target = out / f"sub-{sub}" / f"ses-{ses}" / DATATYPE
    target.mkdir(parents=True, exist_ok=False)
    stem = target / f"sub-{sub}_ses-{ses}_task-{task}"
    grid, hr = hr_grid(folder)
    if len(grid):
        _write_physio(Path(f"{stem}_recording-heartrate"), {"hr_bpm": "bpm"}, grid, hr[:, None], HR_RATE_HZ,
                      "heart rate from the chest strap, linearly interpolated from its valid samples", physio_keys)
    else:
        notes.omitted.append(f"{where}: heart rate left out: {folder / HEART_RATE_CSV}: expected at least "
                             f"2 valid samples, found fewer")
    _export_work(folder, stem, physio_keys, where, notes)
    _write_motion(folder, out / f"sub-{sub}" / f"ses-{ses}" / MOTION_DATATYPE,
                  f"sub-{sub}_ses-{ses}_task-{task}", task_keys, where, notes)
    if (folder / EVENTS_CSV).is_file():
        atomic_write_text(Path(f"{stem}_events.tsv"), _tsv(_events(folder), ("onset", "duration", "trial_type", "value")))
        write_json_atomic(Path(f"{stem}_events.json"), {
            **task_keys,
            "onset": {"Units": "s", "Description": "session time of the event"},
            "trial_type": {"Description": "kind[:label] from events.csv (phase_start:rest, marker, sync...)"},
            "value": {"Description": "events.csv value (load, speed, sync offset...)"}})
    return target


def _export_work(folder: Path, stem: Path, physio_keys: dict, where: str, notes: ExportNotes) -> None:
    """The work physio file of a session at its own times: work.csv (or derived), written as it is when
    regular, else resampled to its median rate with ``n/a`` where no sample lies within half a period
    (stated in the sidecar and ``notes``); an underivable work is left out, stated (``notes``)."""
    from effortface.synth.work import NoWorkSource

    try:
        work = _work_rows(folder)
    except NoWorkSource as exc:
        notes.leave_out(where, "mechanical work", exc, refuse=False)
        return
    except UserError as exc:
        notes.leave_out(where, "mechanical work", exc, refuse=True)
        return
    rate = 1.0 / float(np.median(np.diff(work[:, 0]))) if len(work) > 1 else 1.0
    rows = (work[-1, 0] - work[0, 0]) * rate + 1
    if rows > MAX_GRID_FACTOR * len(work):
        source = folder / WORK_CSV if (folder / WORK_CSV).is_file() else folder
        notes.leave_out(where, "mechanical work", UserError(
            f"{source}: t_s: expected times a grid at their median step ({1 / rate:g} s) can hold in at most "
            f"{MAX_GRID_FACTOR} times their {len(work)} rows, found {work[-1, 0] - work[0, 0]:g} s of them"),
            refuse=True)
        return
    description = "mechanical work over the last 1 s (w) and 0.25 s (p), per kg"
    grid, table, how = regular_grid(work[:, 0], work[:, 1:3], rate)
    if how:
        notes.notes.append(f"{where}: mechanical work {how}")
        description += f"; {how}"
    _write_physio(Path(f"{stem}_recording-work"), {"w_per_kg": "W/kg", "p_per_kg": "W/kg"}, grid,
                  table, rate, description, physio_keys)


#: a time series is regular when every time lies within this fraction of a period of its grid place
REGULAR_TOLERANCE = 0.01
#: irregular work is placed on a grid of at most this many times its rows (drop-outs up to 9 times the
#: recorded time); more is no drop-out but times with no usable rate (a few far apart, most close)
MAX_GRID_FACTOR = 10


def regular_grid(t_s: np.ndarray, values: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray, str]:
    """Samples at ``t_s`` on a grid of ``rate_hz`` from ``t_s[0]``, as BIDS physio files need.

    Regular samples (each within :data:`REGULAR_TOLERANCE` of a period of ``t_s[0] + k / rate_hz``,
    one per grid place) are returned as they are, with ``""``. Otherwise each grid time gets the
    nearest sample within half a period, NaN (``n/a``) where there is none (a drop-out), never
    shifting a sample by more than half a period; the third value then says so in words.

    Returns
    -------
    (grid t_s, values on the grid, how: ``""`` or what was done)
    """
    period = 1.0 / rate_hz
    place = np.rint((t_s - t_s[0]) / period)
    if len(t_s) < 2 or (np.all(np.abs(t_s - t_s[0] - place * period) <= REGULAR_TOLERANCE * period)
                        and np.array_equal(place, np.arange(len(t_s)))):
        return t_s, values, ""
    grid = t_s[0] + np.arange(int(place[-1]) + 1) * period
    right = np.clip(np.searchsorted(t_s, grid), 1, len(t_s) - 1)
    nearest = np.where(np.abs(t_s[right - 1] - grid) <= np.abs(t_s[right] - grid), right - 1, right)
    out = values[nearest].astype(float)
    far = np.abs(t_s[nearest] - grid) > period / 2
    out[far] = np.nan
    gaps = np.diff(t_s) > 2 * period
    spans = ", ".join(f"{a:g}-{b:g} s" for a, b in zip(t_s[:-1][gaps][:5], t_s[1:][gaps][:5]))
    how = (f"resampled from {len(t_s)} samples at irregular times to {rate_hz:g} Hz (their median rate) "
           f"from {t_s[0]:g} s: each time gets the nearest sample within half a period, n/a where none "
           f"({int(far.sum())} of {len(grid)} rows)"
           + (f"; drop-outs at {spans}" + (" and more" if gaps.sum() > 5 else "") if gaps.any() else ""))
    return grid, out, how


def _write_motion(folder: Path, target: Path, stem: str, task_keys: dict, where: str = "",
                  notes: ExportNotes | None = None) -> None:
    """Each clip of ``motion/motion.json`` as the BIDS ``motion`` datatype: joint positions in metres
    (``tracksys-mocap``, ``run-<n>`` in the index's order), ``channels.tsv`` naming each column; an
    index or clip that cannot be read is refused, or left out and stated with ``--skip-invalid``."""
    from effortface.synth.motion import read_motion
    from effortface.synth.plausibility import spatial_axes
    from effortface.synth.work import MOTION_DIR, MOTION_JSON, read_motion_index

    notes = notes if notes is not None else ExportNotes()
    index = folder / MOTION_DIR / MOTION_JSON
    if not index.is_file():
        return
    try:
        entries = read_motion_index(index)
    except UserError as exc:
        notes.leave_out(where, "motion", exc, refuse=True)
        return
    for run, entry in enumerate(entries, start=1):
        try:
            clip = read_motion(index.parent / str(entry["path"]), unit_m=entry.get("unit_m"), up=entry.get("up"))
        except UserError as exc:
            notes.leave_out(where, f"motion clip {entry['path']}", exc, refuse=True)
            continue
        target.mkdir(parents=True, exist_ok=True)
        name = f"{stem}_tracksys-{MOTION_TRACKSYS}" + (f"_run-{run}" if len(entries) > 1 else "")
        table = clip.positions_m.reshape(clip.n_frames, -1)
        text = _tsv([[_value(v) for v in row] for row in table], None)
        atomic_write_text(target / f"{name}_motion.tsv", text)
        channels = [[f"{joint}_{axis}", axis, "POS", joint, "m"] for joint in clip.joint_names for axis in "xyz"]
        atomic_write_text(target / f"{name}_channels.tsv",
                          _tsv(channels, ("name", "component", "type", "tracked_point", "units")))
        write_json_atomic(target / f"{name}_motion.json", {
            **task_keys, "SamplingFrequency": float(clip.fps), "TrackingSystemName": MOTION_TRACKSYS,
            "MotionChannelCount": 3 * len(clip.joint_names), "POSChannelCount": 3 * len(clip.joint_names),
            "RecordingDuration": round(clip.n_frames / clip.fps, 4),
            "SpatialAxes": spatial_axes(clip, entry.get("mapping")),
            "TrackedPointsCount": len(clip.joint_names), "SamplingFrequencyEffective": float(clip.fps),
            "MissingValues": "n/a", "SubjectArtefactDescription": "n/a",
            **{f"{kind}ChannelCount": 0 for kind in ("ACCEL", "ANGACCEL", "GYRO", "JNTANG", "LATENCY", "MAGN",
                                                     "MISC", "ORNT", "VEL")},
            "Description": f"joint positions of {entry['path']} (metres, Z up, as effortface reads it: "
                          f"{_how_read(clip.reading)}); its first frame is at session time "
                          f"{float(entry.get('offset_s', 0.0)):g} s"})


def _how_read(reading: dict) -> str:
    """How a clip was read, for its BIDS description: ``'unit 0.01 m (...), up axis y (...)'``."""
    unit = f"unit {reading['unit_m']:g} m ({reading.get('unit_from', 'the file')})" if "unit_m" in reading \
        else "unit: the file's"
    up = f"up axis {reading['up_axis']} ({reading.get('up_from', 'the file')})" if "up_axis" in reading \
        else "up axis: the file's"
    return f"{unit}, {up}"


def export_bids(sessions_dir: str | os.PathLike, out_dir: str | os.PathLike, *, name: str | None = None,
                notes: ExportNotes | None = None) -> Path:
    """Export every session folder of ``sessions_dir`` as a BIDS dataset in ``out_dir`` (new or empty).

    ``name`` (the dataset ``Name``) overrides the lab description's; without either it is
    ``"effortface sessions"``.
    The dataset is written into a hidden folder beside ``out_dir`` and renamed into place at the end,
    so a failed export (a bad session, a full disk) leaves nothing that looks like a dataset.

    Nothing is left out without a word: a session's work that cannot be derived or read, or a motion
    clip that cannot be read, is refused (one line naming the file and ``--skip-invalid``) unless
    ``notes.skip_invalid``; what is left out (that, and a session with nothing to derive work from or
    without heart rate) is listed in ``notes.omitted`` and in the dataset's README (its files named
    from ``sessions_dir``). Each participant's
    record per session is kept in ``sub-<label>/sub-<label>_sessions.tsv`` (``participants.tsv``
    has the latest).

    Raises
    ------
    UserError
        No sessions, ``out_dir`` inside an input (the sessions folder or a session), a non-empty
        ``out_dir``, colliding participant or session labels, a part of a session that cannot be
        exported (without ``skip_invalid``).
    """
    notes = notes if notes is not None else ExportNotes()
    folders = list_sessions(sessions_dir)
    if not folders:
        raise UserError(f"{sessions_dir}: expected session folders (with session.json), found none")
    check_apart("--out", out_dir, [sessions_dir, *folders], "a dataset folder")
    out = Path(out_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"--out {out}: expected a new or empty folder, found {'a file' if not out.is_dir() else 'a folder with files'}")
    records: dict[Path, Participant] = {folder: read_session(folder).participant for folder in folders}
    codes: dict[str, str] = {}
    for folder, p in records.items():
        sub = bids_label(p.code)
        if codes.setdefault(sub, p.code) != p.code:
            raise UserError(f"{folder}: participant {p.code!r} becomes BIDS label {sub!r}, as does "
                            f"{codes[sub]!r}: rename one")
    labels = session_labels(folders)
    for folder, ses in labels.items():
        if not ses.isdigit():
            notes.notes.append(f"{folder.name}: another session of {records[folder].code} starts in the same "
                               f"second: exported as ses-{ses}")
    lab = read_lab_description(sessions_dir)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.with_name(f".{out.name}.{secrets.token_hex(6)}.tmp")
    staging.mkdir()
    try:
        for folder in folders:
            export_session(folder, staging, bids_label(records[folder].code), lab, ses=labels[folder], notes=notes)
        prefix = f"{Path(sessions_dir)}{os.sep}"  # the README names the lab's files from the lab folder
        _write_top(staging, records, labels, name, lab, [line.replace(prefix, "") for line in notes.omitted])
        with stops_deferred():  # a SIGTERM here waits for the rename: a dataset whole, or the folder as it was
            if out.is_dir():
                out.rmdir()  # the empty folder given (checked above)
            os.rename(staging, out)
        fsync_folder(out.parent)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out


#: participants.tsv and sessions.tsv columns -> Participant attributes
BODY_COLUMNS = {"sex": "sex", "age": "age", "height": "height_m", "weight": "mass_kg",
                "training_level": "training_level"}
BODY_SIDECAR: dict[str, dict] = {"sex": {"Description": "sex", "Levels": {"female": "female", "male": "male"}},
                "age": {"Units": "year"}, "height": {"Units": "m"}, "weight": {"Units": "kg"},
                "training_level": {"Description": "training level, 0 (sedentary) to 10"}}


def _body(p: Participant) -> list[object]:
    return [("n/a" if getattr(p, attr) is None else getattr(p, attr)) for attr in BODY_COLUMNS.values()]


def _write_top(out: Path, records: dict[Path, Participant], labels: dict[Path, str], name: str | None,
               lab: LabDescription, omitted: Sequence[str] = ()) -> None:
    """dataset_description.json, participants.tsv/.json (each participant's latest record), one
    sessions.tsv/.json per participant (each session's record: earlier values are kept), README
    (the lab's text, then what was left out)."""
    write_json_atomic(out / "dataset_description.json", {
        **lab.bids, "Name": name or lab.bids.get("Name") or "effortface sessions", "BIDSVersion": BIDS_VERSION, "DatasetType": "raw",
        "GeneratedBy": [{"Name": "effortface", "Version": __version__}]})
    by_sub: dict[str, list[tuple[datetime.datetime, str, Participant]]] = {}
    for folder, p in records.items():
        by_sub.setdefault(bids_label(p.code), []).append((parse_session_id(folder.name)[1], labels[folder], p))
    rows = [[f"sub-{sub}", *_body(max(sessions, key=lambda x: (x[0], x[1]))[2])]
            for sub, sessions in sorted(by_sub.items())]
    atomic_write_text(out / "participants.tsv", _tsv(rows, ("participant_id", *BODY_COLUMNS)))
    write_json_atomic(out / "participants.json", {
        "participant_id": {"Description": "participant code, letters and digits only"},
        **{k: {**v, "Description": f"{v.get('Description', k)}, from the participant's latest session "
                                   f"(each session's record: sub-<label>/sub-<label>_sessions.tsv)"}
           for k, v in BODY_SIDECAR.items()}})
    for sub, sessions in by_sub.items():
        rows = [[f"ses-{ses}", start.strftime("%Y-%m-%dT%H:%M:%S"), *_body(p)] for start, ses, p in sorted(sessions)]
        atomic_write_text(out / f"sub-{sub}" / f"sub-{sub}_sessions.tsv",
                          _tsv(rows, ("session_id", "acq_time", *BODY_COLUMNS)))
        write_json_atomic(out / f"sub-{sub}" / f"sub-{sub}_sessions.json", {
            "acq_time": {"Description": "session start, the lab's wall-clock time"},
            **{k: {**v, "Description": f"{v.get('Description', k)}, as recorded for this session"}
               for k, v in BODY_SIDECAR.items()}})
    readme = lab.readme
    if omitted:
        readme += ("\nLeft out of this export (effortface export bids):\n\n"
                   + "".join(f"- {line}\n" for line in omitted))
    atomic_write_text(out / "README", readme)


def _work_rows(folder: Path) -> np.ndarray:
    """``t_s, w_per_kg, p_per_kg`` rows: work.csv (:func:`effortface.synth.work.read_work_csv`), else
    derived as ``effortface work`` does (seconds that nothing covers stay, NaN: never closed up).

    Raises
    ------
    WorkError
        A work.csv that cannot be read, a work that cannot be derived (:class:`NoWorkSource` when the
        session has neither motion nor an exercise log to derive it from).
    """
    from effortface.synth.work import derive_work, read_work_csv

    if (folder / WORK_CSV).is_file():
        saved = read_work_csv(folder / WORK_CSV)
        return np.column_stack([saved.t_s, saved.w_per_kg, saved.p_per_kg])
    table = derive_work(folder)
    return np.column_stack([table.t_s, table.w_per_kg, table.p_per_kg])
