"""The exercise vocabulary shared by every stage: the ids of the exercise catalog.

Capture logs and plans exercises by these ids and train estimates their work, so the catalog file
(``data/exercise_catalog.csv``) lives in the core below both, as the blendshape set does. This module
only reads its rows and ids (stdlib only); the work models are :mod:`effortface.synth.catalog`.
"""

from __future__ import annotations

import csv
import functools
import os
from pathlib import Path

from effortface.core.errors import UserError

CATALOG_CSV = Path(__file__).with_name("data") / "exercise_catalog.csv"


def read_catalog_rows(path: str | os.PathLike[str] = CATALOG_CSV) -> list[dict[str, str]]:
    """The rows of an exercise catalog CSV as dicts (``#`` lines are comments).

    Raises
    ------
    UserError
        If the file cannot be read as UTF-8 CSV (names the file).
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return list(csv.DictReader(line for line in fh if not line.startswith("#")))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UserError(f"{path}: expected an exercise catalog CSV, found {exc}") from None


def exercise_ids(path: str | os.PathLike[str] = CATALOG_CSV) -> tuple[str, ...]:
    """The exercise ids of a catalog, in file order (read once per path)."""
    return _ids(str(path))


@functools.lru_cache(maxsize=4)
def _ids(path: str) -> tuple[str, ...]:
    return tuple(row["id"].strip() for row in read_catalog_rows(path) if row.get("id"))


def check_exercise_id(exercise: str, where: str, path: str | os.PathLike[str] = CATALOG_CSV) -> str:
    """Return ``exercise`` if the catalog has it, else a UserError naming ``where`` and the catalog.

    Parameters
    ----------
    exercise : str
        The id to check.
    where : str
        The file and line (or option) it came from, for the message.
    path : path-like
        The catalog.
    """
    ids = exercise_ids(path)
    if exercise not in ids:
        raise UserError(f"{where}: exercise {exercise!r}: expected an id of the catalog {path} "
                        f"({', '.join(ids)})")
    return exercise
