"""The one crash-safe writer and the one overwrite guard every stage uses."""

import pytest

from effortface.core.fileio import atomic_write, refuse_overwrite, write_json_atomic


def test_a_failed_write_leaves_the_old_file_and_no_temp_file(tmp_path) -> None:
    target = tmp_path / "keys.json"
    write_json_atomic(target, {"v": 1})

    def half_then_crash(fh) -> None:
        fh.write(b'{"v": 2, "trunc')
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(target, half_then_crash)
    assert target.read_text() == '{\n  "v": 1\n}\n'
    assert [p.name for p in tmp_path.iterdir()] == ["keys.json"]


def test_refuse_overwrite_names_the_path_and_what_it_is(tmp_path) -> None:
    folder = tmp_path / "model"
    assert refuse_overwrite(folder, what="model folder") == folder  # absent: fine
    folder.mkdir()
    with pytest.raises(FileExistsError, match=r"model: model folder exists; refusing to overwrite \(use --force\)"):
        refuse_overwrite(folder, what="model folder", hint=" (use --force)")
    assert refuse_overwrite(folder, overwrite=True) == folder


def _modes_written_under(umask: int, folder) -> dict[str, int]:
    """Write three files with atomic_write in a child process whose umask is ``umask``; their modes."""
    import subprocess
    import sys

    code = ("import os, sys, threading; os.umask(int(sys.argv[2], 8))\n"
            "from effortface.core.fileio import atomic_write_text\n"
            "ts = [threading.Thread(target=atomic_write_text, args=(os.path.join(sys.argv[1], f'f{i}.json'), '{}'))"
            " for i in range(3)]\n"
            "[t.start() for t in ts]; [t.join() for t in ts]\n")
    subprocess.run([sys.executable, "-c", code, str(folder), f"{umask:o}"], check=True)
    return {p.name: p.stat().st_mode & 0o777 for p in folder.iterdir()}


@pytest.mark.parametrize(("umask", "mode"), [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600)])
def test_a_new_file_honours_the_umask_even_from_threads(tmp_path, umask: int, mode: int) -> None:
    # tempfile.mkstemp made every file 0600 whatever the umask: colleagues could not read them
    assert _modes_written_under(umask, tmp_path) == {"f0.json": mode, "f1.json": mode, "f2.json": mode}


def test_a_replaced_file_keeps_its_mode(tmp_path) -> None:
    target = tmp_path / "session.json"
    write_json_atomic(target, {"v": 1})
    target.chmod(0o664)
    write_json_atomic(target, {"v": 2})
    assert target.stat().st_mode & 0o777 == 0o664
    assert [p.name for p in tmp_path.iterdir()] == ["session.json"]
