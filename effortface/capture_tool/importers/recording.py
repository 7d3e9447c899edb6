"""What every heart-rate file reader returns, and the checks every one of them passes.

A reader (:mod:`.fit`, :mod:`.xml_tracks`, :mod:`.polar_hrm`, :mod:`.table`) turns a file into
:class:`HrRecording`: absolute sample times (UTC seconds, or seconds from an unknown start), heart
rates in bpm, the R-R intervals (ms) observed with each sample, and the device and producer named in
the file. :func:`to_samples` checks the series (not empty, times never going backwards, rates in
bpm) and makes ``heart_rate.csv`` rows, marking a rate outside
:data:`effortface.core.physio_limits.IMPORT_HR_BPM` as not valid. Stdlib and numpy only.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
from pathlib import Path

import numpy as np

from effortface.core.bounds import BOUNDS
from effortface.core.errors import UserError
from effortface.core.hr_sample import HrSample
from effortface.core.physio_limits import IMPORT_HR_BPM, rr_plausible


class HrImportError(UserError):
    """A file that is not a usable heart-rate recording; the one-line message names the file."""


@dataclasses.dataclass
class HrRecording:
    """A heart-rate series read from a file.

    Attributes
    ----------
    path : Path
        The file.
    kind : str
        Format: ``fit``, ``tcx``, ``gpx``, ``hrm``, ``pwx``, ``csv``.
    t_s : list of float
        Sample times in seconds (UTC epoch seconds when ``start_utc`` is known from them).
    hr_bpm : list of float or None
        Heart rate of each sample (None: no rate with this sample, e.g. an R-R-only row).
    rr_ms : list of tuple of float
        R-R intervals first observed with each sample, oldest first.
    start_utc : datetime or None
        Absolute time of ``t_s[0]`` (None when the file has no date).
    device : str
        Device as the file names it (``garmin fenix5``, ``Polar S610``, ``EDGE705``).
    producer : str
        Program or firmware that wrote the file, when the file says it.
    laps : int
        Laps (summaries) found; a file with laps and no samples is refused.
    """

    path: Path
    kind: str
    t_s: list[float] = dataclasses.field(default_factory=list)
    hr_bpm: list[float | None] = dataclasses.field(default_factory=list)
    rr_ms: list[tuple[float, ...]] = dataclasses.field(default_factory=list)
    start_utc: dt.datetime | None = None
    device: str = ""
    producer: str = ""
    laps: int = 0

    def add(self, t_s: float, hr_bpm: float | None, rr_ms: tuple[float, ...] = ()) -> None:
        """Append one sample."""
        self.t_s.append(float(t_s))
        self.hr_bpm.append(None if hr_bpm is None else float(hr_bpm))
        self.rr_ms.append(tuple(float(r) for r in rr_ms))

    @property
    def has_rr(self) -> bool:
        """True if any sample carries R-R intervals."""
        return any(self.rr_ms)


def check_series(rec: HrRecording) -> None:
    """HrImportError (one line naming the file) unless ``rec`` is a usable heart-rate series.

    Refused: no samples (laps only, or nothing), a time that is not finite or goes backwards, a
    recording longer than a session may be (``BOUNDS["t_s"]``: a time column in another unit), and
    rates that are mostly outside :data:`IMPORT_HR_BPM` (a column in another unit).
    """
    name = f"{rec.path}: {rec.kind.upper()}"
    if not rec.t_s:
        if rec.laps:
            raise HrImportError(f"{name}: expected a per-sample heart-rate series, found laps only "
                                f"({rec.laps} lap summar{'y' if rec.laps == 1 else 'ies'}, no samples)")
        raise HrImportError(f"{name}: expected heart-rate samples, found none")
    t = np.asarray(rec.t_s, float)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise HrImportError(f"{name}: expected finite sample times, found {t[bad[0]]} at sample {int(bad[0])}")
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise HrImportError(f"{name}: expected times that never go backwards, found sample {i} at "
                            f"{t[i] - t[0]:.3f} s after one at {t[i - 1] - t[0]:.3f} s")
    longest = BOUNDS["t_s"].high
    if t[-1] - t[0] > longest:
        raise HrImportError(f"{name}: expected a recording of at most {longest:g} s, found {t[-1] - t[0]:.6g} s "
                            "from the first sample to the last (a time column in another unit?)")
    rates = np.asarray([h for h in rec.hr_bpm if h is not None and math.isfinite(h) and h > 0], float)
    if rates.size == 0 and not rec.has_rr:
        raise HrImportError(f"{name}: expected heart rates in bpm, found no rate above 0 in {len(t)} samples")
    low, high = IMPORT_HR_BPM
    inside = np.count_nonzero((rates >= low) & (rates <= high))
    if rates.size and inside * 2 < rates.size:
        raise HrImportError(f"{name}: expected heart rates of {low:g}-{high:g} bpm, found {rates.size - inside} "
                            f"of {rates.size} outside (median {float(np.median(rates)):.4g}): not a bpm "
                            "series (another unit?)")


def to_samples(rec: HrRecording, device: str) -> list[HrSample]:
    """``heart_rate.csv`` rows of a checked recording, times from its first sample.

    A rate outside :data:`IMPORT_HR_BPM` (or none) makes the row not valid, its rate kept empty; an
    R-R interval outside :data:`effortface.core.physio_limits.RR_MS` is dropped. An R-R-only row gets
    the rate of its last interval.
    """
    check_series(rec)
    low, high = IMPORT_HR_BPM
    t0 = rec.t_s[0]
    rows = []
    for t, hr, rr in zip(rec.t_s, rec.hr_bpm, rec.rr_ms):
        rr_ok = tuple(r for r in rr if rr_plausible(r))
        if hr is None and rr_ok:
            hr = 60000.0 / rr_ok[-1]
        ok = hr is not None and math.isfinite(hr) and low <= hr <= high
        rows.append(HrSample(round(t - t0, 4), hr if ok else None, rr_ok, None, device, ok))
    return rows

