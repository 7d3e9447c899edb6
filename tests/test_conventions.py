"""The stage convention of effortface.core, enforced on the source (AST rules, like test_import_rules).

- Each stage's model is ``<stage>_session.py`` at the stage package root, class ``<Stage>Session``.
- Change notification is ``effortface.core.events.Emitter``, one per thing that changes, named
  ``<thing>_changed``; no string-keyed ``connect(event, callback)``.
- Background work in stage models and views goes through ``effortface.core.jobs.Jobs`` (no thread,
  executor or queue of their own), and results reach explicit callbacks: no handler is looked up by a
  name built at run time (``getattr(self, f"_on_{key}")(result)``).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from tests.conftest import product_sources

ROOT = Path(__file__).resolve().parents[1]
#: stage -> (its model's file, class)
STAGE_MODELS = {"capture": ("effortface/capture_tool/capture_session.py", "CaptureSession"),
                "annotate": ("effortface/annotate/annotate_session.py", "AnnotateSession"),
                "train": ("effortface/train/train_session.py", "TrainSession"),
                "synth": ("effortface/synth/synth_session.py", "SynthSession")}
#: modules that may run threads of their own: device readers and players, the job pool, the app's hooks
THREADS_ALLOWED = {"effortface/core/jobs.py", "effortface/app.py", "effortface/annotate/video_index.py"}
THREAD_MODULES = {"threading", "concurrent.futures", "queue", "multiprocessing"}


def _sources() -> list[Path]:
    """Source files, each once (in either layout: tests/conftest.py)."""
    return product_sources()


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def name_dispatch(source: str) -> list[str]:
    """Calls of a handler found by a name built at run time: ``getattr(obj, <not a literal>)(...)``,
    or any ``getattr`` whose built name starts like a handler (``_on_...``, ``on_...``)."""
    tree = ast.parse(source)
    called = {id(node.func) for node in ast.walk(tree) if isinstance(node, ast.Call)}
    found = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr"
                and len(node.args) >= 2 and not isinstance(node.args[1], ast.Constant)):
            continue
        name = ast.unparse(node.args[1])
        if id(node) in called or re.match(r"""^f?['"]_?on_""", name):
            found.append(f"line {node.lineno}: {ast.unparse(node)}")
    return found


def test_the_dispatch_rule_catches_the_old_pattern() -> None:
    old = 'def _drain(self):\n    for r in self.jobs.drain():\n        getattr(self, f"_on_{r.key}")(r)\n'
    assert name_dispatch(old) == ['line 3: getattr(self, f\'_on_{r.key}\')']
    assert name_dispatch('h = getattr(self, "_on_" + key)\n')
    assert name_dispatch('getattr(self, name)()\n')
    assert not name_dispatch('stop = getattr(widget, "shutdown", None)\nkey = getattr(Key, f"Key_{d}")\n')


@pytest.mark.parametrize("path", _sources(), ids=_rel)
def test_no_handler_is_called_by_a_name_string(path: Path) -> None:
    assert name_dispatch(path.read_text(encoding="utf-8")) == [], \
        f"{_rel(path)}: connect the handler explicitly (Jobs.submit(..., done=self._handler))"


@pytest.mark.parametrize("stage", STAGE_MODELS)
def test_each_stage_model_sits_at_its_package_root_under_one_name(stage: str) -> None:
    rel, cls = STAGE_MODELS[stage]
    path = ROOT / rel
    assert path.is_file() and "gui" not in Path(rel).parts
    assert path.name == f"{stage}_session.py" and cls == f"{stage.capitalize()}Session"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    assert cls in {n.name for n in tree.body if isinstance(n, ast.ClassDef)}
    view = path.parent / "gui" / f"{stage}_stage.py"  # its view: Qt<Stage>Stage in the stage's gui/
    assert f"Qt{stage.capitalize()}Stage" in {n.name for n in ast.parse(view.read_text(encoding="utf-8")).body
                                              if isinstance(n, ast.ClassDef)}


def _emitters(tree: ast.AST) -> list[str]:
    """Attribute names assigned ``Emitter()`` (``self.a, self.b = Emitter(), Emitter()`` included)."""
    names = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Assign):
            continue
        for target in node.targets:
            pairs = (zip(target.elts, node.value.elts) if isinstance(target, ast.Tuple)
                     and isinstance(node.value, ast.Tuple) else [(target, node.value)])
            names += [t.attr for t, v in pairs if isinstance(t, ast.Attribute) and isinstance(v, ast.Call)
                      and isinstance(v.func, ast.Name) and v.func.id == "Emitter"]
    return names


@pytest.mark.parametrize("stage", STAGE_MODELS)
def test_stage_models_notify_through_emitters_named_thing_changed(stage: str) -> None:
    tree = ast.parse((ROOT / STAGE_MODELS[stage][0]).read_text(encoding="utf-8"))
    names = _emitters(tree)
    assert names, f"{stage}: expected Emitter attributes"
    assert [n for n in names if not n.endswith("_changed")] == []
    methods = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
    assert not methods & {"connect", "_emit", "on"}, "string-keyed events are replaced by Emitters"


def _thread_imports(path: Path) -> set[str]:
    return _imported(path) & THREAD_MODULES


@pytest.mark.parametrize("path", [p for p in _sources() if "gui" in p.relative_to(ROOT).parts
                                  or _rel(p) in {v[0] for v in STAGE_MODELS.values()}], ids=_rel)
def test_stage_models_and_views_run_background_work_through_core_jobs(path: Path) -> None:
    assert _rel(path) in THREADS_ALLOWED or not _thread_imports(path), \
        f"{_rel(path)}: run background work through effortface.core.jobs.Jobs"


def test_psutil_is_for_the_benchmarks_only() -> None:
    """psutil installs with the ``bench`` extra: the package and the tests never import it."""
    tomllib = pytest.importorskip("tomllib", reason="tomllib is Python 3.11+")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = project["optional-dependencies"]
    assert not [d for d in project["dependencies"] + extras["test"] if d.startswith("psutil")]
    assert [d for d in extras["bench"] if d.startswith("psutil")]
    importers = [_rel(p) for p in [*_sources(), *sorted((ROOT / "tests").rglob("*.py"))]
                 if "psutil" in {n.split(".")[0] for n in _imported(p)}]
    assert importers == []


def _imported(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names
