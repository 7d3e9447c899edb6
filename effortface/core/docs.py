"""The documentation the product ships and cites: ``docs/`` in the repository, ``effortface/docs/`` installed.

``--help`` texts, the training report and the main window's Help menu cite these documents by their
repository path (``docs/DESIGN.md``); :func:`doc_path` finds the file wherever effortface runs from
(a checkout or an editable install reads the repository's ``docs/``; a wheel carries the files as package
data in ``effortface/docs/``, copied there at build time by ``setup.py``). A test checks that every
path cited exists in the repository and in a built wheel.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGED = Path(__file__).resolve().parents[1] / "docs"
#: the folder of the shipped documents: the installed copy (a wheel), else the repository's docs/
DOCS_DIR = _PACKAGED if _PACKAGED.is_dir() else Path(__file__).resolve().parents[2] / "docs"
#: session folder, long table, exercise log, model bundle, command line and architecture
DESIGN = "docs/DESIGN.md"
#: the science the product implements (the paper's model and our marked choices)
SCIENCE = "docs/SCIENCE.md"
#: notes on where the code made or changed a choice of SCIENCE.md (calibrations, derivations)
SCIENCE_NOTES = "docs/SCIENCE_NOTES.md"


def doc_path(cited: str) -> Path:
    """The file of a cited document (``"docs/DESIGN.md"``) where this effortface is installed.

    Parameters
    ----------
    cited : str
        The path as cited, relative to the repository root (``docs/<name>`` or ``docs/guide/<page>``).

    Returns
    -------
    Path
        The document (it exists in a repository checkout and in an installed wheel).
    """
    parts = Path(cited).parts
    return DOCS_DIR.joinpath(*parts[1:]) if parts[:1] == ("docs",) else DOCS_DIR / Path(cited).name


def cite(cited: str) -> str:
    """How a help text names a document: ``docs/DESIGN.md (installed: /.../effortface/docs/DESIGN.md)``."""
    return f"{cited} (installed: {doc_path(cited)})"
