"""BIDS out: session folders -> a BIDS-style dataset (``effortface export bids``).

Layout (BIDS 1.9, behavioural data with physiological recordings)::

    dataset_description.json  participants.tsv  participants.json  README
    sub-<code>/ses-<YYYYmmddHHMMSS>/beh/
        sub-<code>_ses-<...>_task-<label>_recording-heartrate_physio.tsv.gz (+ .json)
        sub-<code>_ses-<...>_task-<label>_recording-work_physio.tsv.gz (+ .json, with work.csv)
        sub-<code>_ses-<...>_task-<label>_events.tsv (+ .json)

Labels are sanitised to letters and digits (BIDS labels are alphanumeric): ``LAB2-07`` becomes
``LAB207`` (two codes that collide are an error), the task is the session label (``cardio``) or
``effort``. BIDS physiological files need a constant rate: heart rate is linearly interpolated
from the valid strap samples at :data:`HR_RATE_HZ` (``n/a`` across gaps longer than
``effortface.train.dataset.MAX_HR_GAP_S``), work and power are written at their own 1 Hz. Each
physio sidecar has ``SamplingFrequency``, ``StartTime`` (seconds from the session's time 0, which is
also the events' onset origin) and ``Columns``, with units per column.
"""

from __future__ import annotations

import csv
import gzip
import io
import json
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from effortface.capture_tool.hr_csv import read_hr_csv
from effortface.capture_tool.session import EVENTS_CSV, HEART_RATE_CSV, list_sessions, parse_session_id, read_session
from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write, atomic_write_text, write_json_atomic
from effortface.core.version import __version__
from effortface.train.dataset import MAX_HR_GAP_S, WORK_CSV

BIDS_VERSION = "1.9.0"
HR_RATE_HZ = 4.0
DATATYPE = "beh"


def bids_label(text: str) -> str:
    """A BIDS label: letters and digits only (``LAB2-07`` -> ``LAB207``)."""
    label = re.sub(r"[^A-Za-z0-9]", "", text)
    if not label:
        raise UserError(f"BIDS label: expected letters or digits in {text!r}, found none")
    return label


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
                  description: str) -> None:
    text = _tsv([[_value(v) for v in row] for row in table], None)
    atomic_write(stem.with_name(stem.name + "_physio.tsv.gz"),
                 lambda fh: fh.write(gzip.compress(text.encode(), mtime=0)))
    write_json_atomic(stem.with_name(stem.name + "_physio.json"), {
        "SamplingFrequency": rate_hz, "StartTime": float(t_s[0]) if len(t_s) else 0.0,
        "Columns": list(columns), "Description": description,
        **{name: {"Units": unit} for name, unit in columns.items()}})


def _events(folder: Path) -> list[list[str]]:
    """``onset, duration, trial_type, value`` rows of events.csv (phases get their duration)."""
    with open(folder / EVENTS_CSV, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    out = []
    for i, r in enumerate(rows):
        duration = "n/a"
        if r["kind"] == "phase_start":
            end = next((float(e["t_s"]) for e in rows[i + 1:] if e["kind"] in ("phase_end", "phase_start")), None)
            duration = f"{end - float(r['t_s']):.4f}" if end is not None else "n/a"
        out.append([f"{float(r['t_s']):.4f}", duration, f"{r['kind']}:{r['label']}" if r["label"] else r["kind"],
                    r["value"] or "n/a"])
    return out


def export_session(folder: Path, out: Path, sub: str) -> Path:
    """Write one session's files under ``out/sub-<sub>/ses-<...>/beh``; return that folder."""
    _, start, label = parse_session_id(folder.name)
    ses, task = start.strftime("%Y%m%d%H%M%S"), bids_label(label or "effort")
    target = out / f"sub-{sub}" / f"ses-{ses}" / DATATYPE
    target.mkdir(parents=True, exist_ok=False)
    stem = target / f"sub-{sub}_ses-{ses}_task-{task}"
    grid, hr = hr_grid(folder)
    _write_physio(Path(f"{stem}_recording-heartrate"), {"hr_bpm": "bpm"}, grid, hr[:, None], HR_RATE_HZ,
                  "heart rate from the chest strap, linearly interpolated from its valid samples")
    work = _work_rows(folder)
    if work is not None:
        rate = 1.0 / float(np.median(np.diff(work[:, 0]))) if len(work) > 1 else 1.0
        _write_physio(Path(f"{stem}_recording-work"), {"w_per_kg": "W/kg", "p_per_kg": "W/kg"}, work[:, 0],
                      work[:, 1:3], rate, "mechanical work over the last 1 s (w) and 0.25 s (p), per kg")
    if (folder / EVENTS_CSV).is_file():
        atomic_write_text(Path(f"{stem}_events.tsv"), _tsv(_events(folder), ("onset", "duration", "trial_type", "value")))
        write_json_atomic(Path(f"{stem}_events.json"), {
            "onset": {"Units": "s", "Description": "session time of the event"},
            "trial_type": {"Description": "kind[:label] from events.csv (phase_start:rest, marker, sync...)"},
            "value": {"Description": "events.csv value (load, speed, sync offset...)"}})
    return target


def export_bids(sessions_dir: str | os.PathLike, out_dir: str | os.PathLike, *, name: str = "effortface sessions"
                ) -> Path:
    """Export every session folder of ``sessions_dir`` as a BIDS dataset in ``out_dir`` (new or empty).

    Raises
    ------
    UserError
        No sessions, a non-empty ``out_dir``, colliding participant labels.
    """
    folders = list_sessions(sessions_dir)
    if not folders:
        raise UserError(f"{sessions_dir}: expected session folders (with session.json), found none")
    out = Path(out_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"--out {out}: expected a new or empty folder, found {'a file' if not out.is_dir() else 'a folder with files'}")
    participants: dict[str, object] = {}
    for folder in folders:
        p = read_session(folder).participant
        sub = bids_label(p.code)
        if sub in participants and getattr(participants[sub], "code") != p.code:
            raise UserError(f"{folder}: participant {p.code!r} becomes BIDS label {sub!r}, as does "
                            f"{getattr(participants[sub], 'code')!r}: rename one")
        participants[sub] = p
    out.mkdir(parents=True, exist_ok=True)
    for folder in folders:
        export_session(folder, out, bids_label(read_session(folder).participant.code))
    _write_top(out, participants, name)
    return out


def _write_top(out: Path, participants: dict[str, object], name: str) -> None:
    write_json_atomic(out / "dataset_description.json", {
        "Name": name, "BIDSVersion": BIDS_VERSION, "DatasetType": "raw",
        "GeneratedBy": [{"Name": "effortface", "Version": __version__}]})
    cols = ("participant_id", "sex", "age", "height", "weight", "training_level")
    rows = [[f"sub-{sub}", *(("n/a" if v is None else v) for v in (getattr(p, "sex"), getattr(p, "age"),
             getattr(p, "height_m"), getattr(p, "mass_kg"), getattr(p, "training_level")))]
            for sub, p in sorted(participants.items())]
    atomic_write_text(out / "participants.tsv", _tsv(rows, cols))
    write_json_atomic(out / "participants.json", {
        "sex": {"Description": "sex", "Levels": {"female": "female", "male": "male"}},
        "age": {"Units": "year"}, "height": {"Units": "m"}, "weight": {"Units": "kg"},
        "training_level": {"Description": "training level, 0 (sedentary) to 10"}})
    atomic_write_text(out / "README", "Exported by effortface: heart rate, mechanical work and events of "
                      "exercise sessions (see the effortface README).\n")


def _work_rows(folder: Path) -> np.ndarray | None:
    """``t_s, w_per_kg, p_per_kg`` rows: work.csv, else derived as ``effortface work`` does (None if
    the session has neither motion nor an exercise log to derive it from)."""
    if (folder / WORK_CSV).is_file():
        return np.loadtxt(folder / WORK_CSV, delimiter=",", skiprows=1, ndmin=2)
    from effortface.train.work import derive_work

    try:
        table = derive_work(folder)
    except UserError:
        return None
    rows = np.column_stack([table.t_s, table.w_per_kg, table.p_per_kg])
    return rows[np.isfinite(rows).all(axis=1)]
