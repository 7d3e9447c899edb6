"""Issue 37: two captures of one participant in the same second get two folders (the second suffixed)."""

from __future__ import annotations

from effortface.capture_tool.recorder import Recorder
from effortface.core.session.folder import ID_TAKEN_KEY, Participant, read_session


def test_a_capture_in_the_same_second_as_another_gets_a_suffix(tmp_path, freeze_now) -> None:
    """The recorder (capture, the Capture stage) takes the first free id too, and records the one it wanted."""
    from effortface.capture_tool import recorder

    freeze_now(recorder)
    out = tmp_path / "lab"
    first = Recorder(out, Participant("P01"), "loop://", "lines")
    first.start()
    second = Recorder(out, Participant("P01"), "loop://", "lines")
    try:
        second.start()
    finally:
        first.stop()
        second.stop()
    assert (first.path.name, second.path.name) == ("P01_20260302-101507", "P01_20260302-101507_2")
    assert read_session(second.path).info.extra[ID_TAKEN_KEY] == first.path.name
    assert ID_TAKEN_KEY not in read_session(first.path).info.extra
