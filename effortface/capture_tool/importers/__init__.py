"""Heart-rate files from watches, bike computers and phone apps -> session folders (``effortface import hr``).

:func:`read_hr_file` picks the reader by the file's first bytes and suffix: FIT (:mod:`.fit`), TCX,
GPX, PWX (:mod:`.xml_tracks`), Polar HRM (:mod:`.polar_hrm`), CSV/TSV tables (:mod:`.table`).
:func:`effortface.capture_tool.importers.session.write_hr_session` writes the session folder.
"""

from __future__ import annotations

import os
from pathlib import Path

from effortface.capture_tool.importers.recording import HrImportError, HrRecording, check_series

#: what ``import hr`` reads, for messages
KINDS = "FIT, TCX, GPX, Polar HRM, PWX, CSV/TSV"
_XML_ROOTS = {"TrainingCenterDatabase": "tcx", "gpx": "gpx", "pwx": "pwx"}


def sniff(path: Path) -> str:
    """The kind of a heart-rate file: ``fit``, ``tcx``, ``gpx``, ``pwx``, ``hrm`` or ``csv``.

    Raises
    ------
    HrImportError
        No such file, or a file of none of these kinds (one line naming what was found).
    """
    if not path.is_file():
        raise HrImportError(f"{path}: expected a heart-rate file ({KINDS}), found "
                            f"{'a folder' if path.is_dir() else 'no such file'}")
    with open(path, "rb") as f:
        head = f.read(4096)
    if len(head) >= 12 and head[8:12] == b".FIT":
        return "fit"
    text = head.decode("latin-1").lstrip("\ufeff\xef\xbb\xbf \r\n\t")
    if text.startswith("<"):
        for root, kind in _XML_ROOTS.items():
            if f"<{root}" in text or f":{root}" in text:
                return kind
        raise HrImportError(f"{path}: expected a heart-rate file ({KINDS}), found XML without a "
                            "TrainingCenterDatabase, gpx or pwx root")
    if text.startswith("[Params]"):
        return "hrm"
    if b"\0" in head or not text.strip():
        raise HrImportError(f"{path}: expected a heart-rate file ({KINDS}), found "
                            f"{'an empty file' if not text.strip() else 'binary data that is not FIT'}")
    return "csv"


def read_hr_file(path: str | os.PathLike, *, time_col: str | None = None, hr_col: str | None = None,
                 rr_col: str | None = None) -> HrRecording:
    """Read and check one heart-rate file.

    Parameters
    ----------
    path : path-like
        A FIT, TCX, GPX, PWX, Polar HRM or CSV/TSV file.
    time_col, hr_col, rr_col : str, optional
        Columns of a CSV/TSV table when its header is ambiguous.

    Returns
    -------
    HrRecording
        Checked: samples present, times never going backwards, rates in bpm.

    Raises
    ------
    HrImportError
        One line naming the file and what was found.
    """
    from effortface.capture_tool.importers import fit, polar_hrm, table, xml_tracks

    path = Path(path)
    kind = sniff(path)
    if kind == "fit":
        rec = fit.read_fit(path)
    elif kind == "hrm":
        rec = polar_hrm.read_hrm(path)
    elif kind == "csv":
        rec = table.read_table(path, time_col=time_col, hr_col=hr_col, rr_col=rr_col)
    else:
        rec = {"tcx": xml_tracks.read_tcx, "gpx": xml_tracks.read_gpx, "pwx": xml_tracks.read_pwx}[kind](path)
    check_series(rec)
    return rec


__all__ = ["HrImportError", "HrRecording", "KINDS", "read_hr_file", "sniff"]
