"""Shared test set-up: offscreen Qt before any QApplication exists, paths to the real data."""

from __future__ import annotations

import datetime as _dt
import os
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

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


# --- Builders shared across rooms: a model bundle, a session folder, spies on the one-job functions.
# Each is a fixture that returns the builder, so a test asks for it by name (``make_bundle``) instead
# of importing another test module.

#: module -> the one function of a job (the functions the CLI and the GUI must both call)
JOBS = {"train_models": "effortface.train.pipeline", "export_outcome": "effortface.train.pipeline",
        "evaluate_bundle": "effortface.train.evaluation", "write_curve_chunks": "effortface.synth.curves_io"}
#: the callers: the command modules and the GUI models (imported before the spies go in)
CALLERS = ("effortface.train.commands.train", "effortface.train.commands.evaluate",
           "effortface.synth.commands.synth", "effortface.commands.demo",
           "effortface.train.train_session", "effortface.synth.synth_session")
#: the video rate of a built session, frames per second
SESSION_FPS = 10.0


def _bundle_from_random_fits(seed: int = 0, n: int = 200) -> Any:
    """A :class:`~effortface.synth.bundle.ModelBundle` from real scikit-learn fits on random data."""
    import numpy as np
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVR

    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.synth.bundle import ModelBundle
    from effortface.synth.face import SvrModel
    from effortface.synth.physiology import NhrParams, NhrRegression

    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(0, 25, n), rng.uniform(0, 40, n), rng.uniform(0, 1, n),
                         rng.uniform(0, 1, n)])
    scaler = StandardScaler().fit(x)
    z = scaler.transform(x)
    svrs = [SVR(C=10.0, gamma=0.5, epsilon=0.05).fit(z, np.clip(z @ rng.normal(size=4) / 4 + 0.5,
                                                                0, 1)) for _ in DEFAULT_SET.names]
    model = SvrModel.from_estimators(svrs, scaler.mean_, scaler.scale_)
    return ModelBundle(
        blendshapes=DEFAULT_SET, scaler_mean=scaler.mean_, scaler_scale=scaler.scale_,
        nhr_coefficients=NhrParams(8.0, 0.004, 0.001), nhr_regression=NhrRegression(),
        svr_hyperparameters=[{"C": 10.0, "gamma": 0.5, "epsilon": 0.05} for _ in svrs],
        support_vectors=model.support_vectors, dual_coef=model.dual_coef,
        intercept=model.intercept, metrics={"r_mean": 0.8}, provenance={"data": "random"})


def _write_session(root: Path, rows: Any, *, raters: dict[str, float] | None = None,
                   participant: dict | None = None, hr: bool = True) -> Path:
    """Write one session folder from one session's synthetic rows (work.csv, strap, video times,
    one annotation file per rater with key-frames every 5 s; a rater's value offsets the weights)."""
    import datetime as dt

    import numpy as np
    import pandas as pd

    from effortface.annotate.keyframes import KeyframeTrack, RaterAnnotations
    from effortface.capture_tool.protocols import HrSample
    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.core.session.folder import (FrameTimeWriter, HrWriter, Participant, SessionInfo,
                                                create_session, make_session_id)

    first = rows.iloc[0]
    part = participant or {k: first[k] for k in ("sex", "age", "height_m", "mass_kg", "training_level")}
    code = str(first["participant"])
    stamp = dt.datetime(2026, 1, 1, 10, 0, 0) + dt.timedelta(minutes=len(list(root.glob("*"))))
    info = SessionInfo(make_session_id(code, stamp, str(first["exercise"])),
                       Participant(code, **{k: (float(v) if k != "sex" else v) for k, v in part.items()}),
                       complete=True)
    folder = create_session(root, info)
    t = rows["t_s"].to_numpy(float)
    pd.DataFrame({"t_s": t, "w_per_kg": rows["w_per_kg"], "p_per_kg": rows["p_per_kg"]}).to_csv(
        folder / "work.csv", index=False)
    writer = HrWriter(folder / "heart_rate.csv")
    for ti, h in zip(t, rows["hr_bpm"]):
        if hr:
            writer.write(HrSample(t_s=float(ti) + 0.3, hr_bpm=float(round(h, 1)), device="sim"))
    writer.close()
    frames = FrameTimeWriter(folder / "video_frames.csv")
    for i, ft in enumerate(np.arange(0, t[-1] + 1, 1 / SESSION_FPS)):
        frames.write(i, float(ft))
    frames.close()
    for rater, offset in (raters or {"R1": 0.0}).items():
        tracks = {}
        for name in DEFAULT_SET.names:
            track = KeyframeTrack()
            for ti in t[::5]:
                w = float(np.clip(rows.loc[rows["t_s"] == ti, name].iloc[0] + offset, 0, 1))
                track.add(int(round(ti * SESSION_FPS)), w, "linear")
            tracks[name] = track
        RaterAnnotations(rater, info.session_id, DEFAULT_SET, tracks).save(
            folder / "annotations" / f"{rater}.json")
    return folder


def _spy_on_jobs(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Count the calls of each job's function (the real function still runs); returns the counts.

    The spy replaces the function in its own module and in every loaded ``effortface`` module that
    imported it by name, so a caller is counted whichever import form it uses.
    """
    import importlib
    import sys

    for name in CALLERS:
        importlib.import_module(name)
    calls = dict.fromkeys(JOBS, 0)
    for name, owner in JOBS.items():
        original = getattr(importlib.import_module(owner), name)
        spy = _counting(original, name, calls)
        for module in [m for k, m in sys.modules.items() if k.startswith("effortface") and m is not None]:
            for attr, value in list(vars(module).items()):
                if value is original:
                    monkeypatch.setattr(module, attr, spy)
    return calls


def _counting(original: Callable[..., Any], name: str, calls: dict[str, int]) -> Callable[..., Any]:
    def spy(*args: Any, **kwargs: Any) -> Any:
        calls[name] += 1
        return original(*args, **kwargs)
    return spy


@pytest.fixture(scope="session")
def make_bundle() -> Callable[..., Any]:
    """``make_bundle(seed=0, n=200)``: a model bundle from real SVR fits on random data."""
    return _bundle_from_random_fits


@pytest.fixture(scope="session")
def make_session() -> Callable[..., Path]:
    """``make_session(root, rows, raters=, participant=, hr=)``: one session folder from synthetic rows."""
    return _write_session


@pytest.fixture(scope="session")
def spy_on_jobs() -> Callable[[pytest.MonkeyPatch], dict[str, int]]:
    """``spy_on_jobs(monkeypatch)``: count the calls of each one-job function; returns the counts."""
    return _spy_on_jobs


#: the one second every ``now()`` returns under :func:`freeze_now`
FROZEN_SECOND = _dt.datetime(2026, 3, 2, 10, 15, 7)


class _FrozenClock:
    """A ``datetime`` module as a frozen module sees it: every ``now()`` in :data:`FROZEN_SECOND`."""

    class datetime(_dt.datetime):
        @classmethod
        def now(cls, tz=None):
            return FROZEN_SECOND


@pytest.fixture
def freeze_now(monkeypatch: pytest.MonkeyPatch) -> Callable[[Any], _dt.datetime]:
    """``freeze_now(module)``: the module's ``_dt`` (its ``datetime`` import) says the same second for
    every ``now()`` (two sessions started in the same second); returns that second."""
    def freeze(module: Any) -> _dt.datetime:
        monkeypatch.setattr(module, "_dt", _FrozenClock)
        return FROZEN_SECOND
    return freeze
