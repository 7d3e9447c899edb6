"""Reading ``.npz`` files written elsewhere: no pickle, no zip bomb, one error type (numpy only).

Model bundles (``svr.npz``) and retargeted motion clips come from other machines and other
programs. :func:`load_npz` checks each member's declared size and each array header against what
the archive really holds before numpy allocates anything, and turns every exception a damaged zip
makes zipfile or numpy raise into the caller's one-line :class:`UserError` subclass.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path
from typing import IO

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import check_zip_sizes

#: what a damaged zip makes zipfile and numpy raise (a name that is not UTF-8, an unknown compression
#: method, an "encrypted" flag, corrupt deflate data, a lone .npy...), found by benchmarks/fuzz_long.py
NPZ_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, TypeError, NotImplementedError,
              RuntimeError)
#: the largest content accepted, uncompressed (a trained bundle holds a few MB, a long clip tens)
MAX_NPZ_BYTES = 256 * 1024 * 1024


def load_npz(path: str | os.PathLike[str], error: type[UserError], what: str,
             max_bytes: int | None = None) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` archive, or ``error`` naming the file.

    Parameters
    ----------
    path : path-like
        The archive.
    error : type
        The UserError subclass to raise.
    what : str
        What the file should be, for the message (``"a numpy .npz without pickles"``).
    max_bytes : int, optional
        Limit of the uncompressed content; :data:`MAX_NPZ_BYTES` by default.

    Returns
    -------
    dict of str to ndarray

    Raises
    ------
    UserError
        Of type ``error``: not a zip of ``.npy`` arrays, pickled objects, a zip bomb (content over
        ``max_bytes`` or a header declaring more than its member holds).
    """
    path = Path(path)
    _check_magic(path, error, what)
    check_npz_sizes(path, error, MAX_NPZ_BYTES if max_bytes is None else max_bytes)
    try:
        with np.load(path, allow_pickle=False) as npz:  # a lone .npy has no "with": TypeError
            return {k: npz[k] for k in npz.files}
    except NPZ_ERRORS as exc:
        raise error(f"{path}: expected {what}, found {str(exc) or type(exc).__name__}") from None


#: how a zip archive (``.npz``) and a lone ``.npy`` array begin; numpy takes anything else for a pickle
_NPZ_MAGICS = (b"PK\x03\x04", b"PK\x05\x06", b"\x93NUMPY")


def _check_magic(path: Path, error: type[UserError], what: str) -> None:
    """Refuse a file that is neither a zip nor a ``.npy`` by what it starts with (a text file is not
    "pickled data", as numpy would say)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(6)
    except OSError:
        return  # np.load says what is wrong with the path
    if not head.startswith(_NPZ_MAGICS):
        raise error(f"{path}: expected {what}, found a file that is neither a zip of arrays nor a .npy "
                    f"(it starts with {head!r})")


def check_npz_sizes(path: Path, error: type[UserError], max_bytes: int) -> None:
    """Refuse a zip bomb: member sizes summed over ``max_bytes`` (:func:`~effortface.core.fileio.check_zip_sizes`),
    or an array header declaring more data than its member holds (checked before numpy allocates the array)."""
    try:
        infos = check_zip_sizes(path, error, max_bytes, "arrays")
        with zipfile.ZipFile(path) as zf:
            for info in infos:
                with zf.open(info) as fh:
                    _check_npy_header(path, info, fh, error)
    except UserError:
        raise
    except NPZ_ERRORS:
        return  # np.load names what is wrong with the file itself


def _check_npy_header(path: Path, info: zipfile.ZipInfo, fh: IO[bytes], error: type[UserError]) -> None:
    """Raise unless the ``.npy`` member's header declares no more data than the member holds."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, dtype = read(fh)
    except ValueError as exc:
        raise error(f"{path}: {info.filename}: expected a .npy array, found {exc}") from None
    declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if declared > info.file_size:
        raise error(f"{path}: {info.filename}: expected an array of at most {info.file_size} "
                    f"bytes (its stored size), found a header declaring shape {shape}")
