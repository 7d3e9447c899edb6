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
