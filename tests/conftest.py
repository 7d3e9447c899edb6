"""Shared test set-up: offscreen Qt before any QApplication exists, paths to the real data."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

# A suite started in the background by a non-interactive shell (``cmd &``) inherits SIGINT ignored,
# and so would every command it starts, which then could not be stopped with Ctrl-C as the capture,
# recover and pre-annotate tests do: give the suite (and so its children) the default handling.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

ROOT = Path(__file__).resolve().parents[1]
#: The real captures, clips and recordings the tests need: a copy of ../shared/data kept in the
#: repository (tests/data, about 3 MB, with its licences and provenance), so that a fresh clone runs
#: every test without ../shared. tests/test_test_data.py checks the copy against its SHA256SUMS.
SHARED_DATA = ROOT / "tests" / "data"
#: the design card's top-level stage folders (real code before tools/restructure.py, pointers after)
STAGE_FOLDERS = ("capture_tool", "annotate", "train")


def product_sources() -> list[Path]:
    """The product's Python files, each once, in either layout (links are not followed).

    Before ``tools/restructure.py`` the stages are top-level folders reached through links in
    ``effortface/``; after it they are real folders of ``effortface/``. ``os.walk`` does not follow
    links, so no file is listed twice.
    """
    out: list[Path] = []
    for top in ("effortface", *STAGE_FOLDERS):
        for folder, dirs, files in os.walk(ROOT / top):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            out += [Path(folder) / f for f in files if f.endswith(".py")]
    return sorted(out)


def module_name(path: Path) -> str:
    """The dotted module name of a product file in either layout (``train/x.py`` -> ``effortface.train.x``)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[0] in STAGE_FOLDERS:
        parts.insert(0, "effortface")
    return ".".join(parts).removesuffix(".__init__")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--hr-port", default=None, help="a real strap's serial port, e.g. /dev/ttyUSB0")
    parser.addoption("--hr-protocol", default="hxm", help="that strap's protocol (ant, hxm, hrmi, lines)")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real captures, clips and recordings in tests/data (skip, saying so, if absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder not found: {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture
def hr_port(request: pytest.FixtureRequest) -> str:
    """A real strap's port; hardware tests skip unless --hr-port is given."""
    port = request.config.getoption("--hr-port")
    if not port:
        pytest.skip("needs a real strap: run pytest --hr-port=/dev/ttyUSB0")
    return port


@pytest.fixture
def hr_protocol(request: pytest.FixtureRequest) -> str:
    """The protocol of the strap given with --hr-port."""
    return request.config.getoption("--hr-protocol")


@pytest.fixture(autouse=True)
def _gc_in_gui_thread(request: pytest.FixtureRequest):
    """In Qt tests, collect garbage in the GUI thread only, as the application does."""
    if "qtbot" not in request.fixturenames:
        yield
        return
    request.getfixturevalue("qapp")
    from effortface.core.gui.gui_gc import collect_in_gui_thread

    with collect_in_gui_thread(interval_s=0.5):
        yield
