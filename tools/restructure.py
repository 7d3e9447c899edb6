"""Move the code into one real package tree with one room per job (run once, on the merged tree).

restructure: keep old names (this file names the old paths on purpose; the rewrite skips it)

What it does, in order (every step is skipped when already done, so a second run changes nothing):

1. removes every symbolic link git tracks (``git ls-files -s``, mode 120000): the links
   ``effortface/capture_tool -> ../capture_tool`` (and annotate, train, docs);
2. rewrites, in every tracked text file, the dotted names of the modules that move
   (``effortface.train.energy`` -> ``effortface.synth.energy``, also in strings such as
   ``monkeypatch.setattr("effortface.train.motion.read_motion", ...)``), the repository paths of
   every moved file (``train/motion.py`` -> ``effortface/synth/motion.py``), and relative imports
   that would cross a room into absolute ones;
3. ``git mv``: the named modules of ``train/`` into ``effortface/synth/`` (the body model and
   everything game code needs) and ``effortface/interop/`` (live server, XDF, BIDS, engine
   reference), the session-folder format into ``effortface/core/session/``, then the three stage
   folders whole (so modules this script does not name stay in their stage) into ``effortface/``;
4. leaves a one-file pointer (``README.md``) in the top-level ``capture_tool/``, ``annotate/``, ``train/``;
5. writes the old -> new names into ``effortface/_moved.py`` (old import paths keep working for one
   release, with a DeprecationWarning), the import-linter layers and the runtime's forbidden
   contract into ``pyproject.toml``, and the runtime distribution's folders into ``runtime-dist/setup.py``;
6. prints every effortface module ``effortface.runtime`` imports (directly or not) that is still
   under ``effortface/train/``: add it to :data:`SYNTH` and run again.

Usage (from the repository root, on a clean work tree)::

    python tools/restructure.py            # do it
    python tools/restructure.py --dry-run  # print the moves, change nothing
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: train/ files (relative to train/) -> their place in effortface/synth/ (the room below training:
#: the body model, motion readers, physiology, the runtime and synthesis that game code uses)
SYNTH = {f"{m}.py": f"{m}.py" for m in (
    "motion", "motion_csv", "segments", "energy", "work", "catalog", "exercise_log", "iir",
    "physiology", "runtime", "bundle", "face", "npzio", "curves_io", "batch_synth", "synth_session",
    "character_options", "parallel", "attach")}
SYNTH.update({
    "interop/c3d_motion.py": "c3d_motion.py",
    "gui/synth_stage.py": "gui/synth_stage.py",
    "commands/synth.py": "commands/synth.py",
    "commands/motion.py": "commands/motion.py",
    "commands/work.py": "commands/work.py",
    "data/resting_hr_chart.csv": "data/resting_hr_chart.csv",
    "data/segment_inertia_tables.csv": "data/segment_inertia_tables.csv",
})
#: train/ files -> effortface/interop/ (the room above training: LSL, XDF, BIDS, the live server);
#: the rest of train/interop/ follows the folder (INTEROP_DIR)
INTEROP = {
    "commands/serve.py": "commands/serve.py",
    "commands/import_data.py": "commands/import_data.py",
    "commands/export_data.py": "commands/export_data.py",
}
INTEROP_DIR = "interop"  # train/interop/ -> effortface/interop/ (after c3d_motion left it)
#: capture_tool/ files -> effortface/core/session/ (the session-folder format, below every stage)
SESSION = {"session.py": "folder.py", "hr_csv.py": "hr_csv.py"}
#: the stage folders that become real folders of the package
STAGES = ("capture_tool", "annotate", "train")

NEW_PACKAGES = {
    "effortface/synth": "The body model and everything game code needs: motion readers, segments, energies, work,\n"
                        "filters, physiology, the runtime, curve files, synthesis and batch synthesis (the Synthesize\n"
                        "stage). Below training: ``effortface.train`` imports it, never the reverse.",
    "effortface/synth/gui": "The Synthesize stage's Qt widgets.",
    "effortface/synth/commands": "``effortface synth``, ``effortface motion``, ``effortface work``.",
    "effortface/interop": "Interop above training: the live server (``effortface serve``), XDF import, BIDS export and\n"
                          "the engine reference.",
    "effortface/interop/commands": "``effortface serve``, ``effortface import``, ``effortface export``.",
    "effortface/core/session": "The session-folder format (``session.json``, ``heart_rate.csv``, frames, events): read,\n"
                               "write and check, Qt-free, below every stage.",
}

POINTER = """# {stage}/ moved

The code of this stage is in [`effortface/{stage}/`](../effortface/{stage}/) (one real package tree,
no links: the same files on every platform). {extra}See the guide's *Layout* page
([`docs/guide/layout.md`](../docs/guide/layout.md)).
"""
POINTER_EXTRA = {
    "train": "The body model, motion readers, physiology, the runtime and synthesis are in "
             "[`effortface/synth/`](../effortface/synth/), the live server, XDF and BIDS in "
             "[`effortface/interop/`](../effortface/interop/). ",
    "capture_tool": "The session-folder format is in [`effortface/core/session/`](../effortface/core/session/). ",
    "annotate": "",
}

LAYERS = '''name = "Data flows one way: core <- capture_tool <- annotate <- synth <- train <- interop <- front door"
type = "layers"
layers = [
    "effortface.cli : effortface.app : effortface.commands : effortface.demo : effortface.runtime",
    "effortface.samplelab",
    "effortface.interop",
    "effortface.train",
    "effortface.synth",
    "effortface.annotate",
    "effortface.capture_tool",
    "effortface.core",
]'''
RUNTIME_ROOMS = '''
[[tool.importlinter.contracts]]
name = "The runtime loads no stage, training or interop module (game code gets the model room only)"
type = "forbidden"
source_modules = ["effortface.runtime", "effortface.synth.runtime"]
forbidden_modules = ["effortface.train", "effortface.interop", "effortface.capture_tool", "effortface.annotate", "effortface.samplelab"]
'''
STAGES_COMMENT = """# One installed namespace, effortface.*, one real package tree: the stages are real folders of
# effortface/ (capture_tool, annotate, train; the model room synth, the interop room; the session
# format in core/session). The top-level capture_tool/, annotate/ and train/ are one-file pointers.
# No links: Git on Windows checks a link out as a text file. Nothing else installs at top level
# (tests/test_install.py checks what `pip install .` installs).
"""
RUNTIME_DIST_DIRS = '''PACKAGE_DIR = {"effortface": "../effortface", "effortface.core": "../effortface/core",
               "effortface.synth": "../effortface/synth"}
'''
TEXT_SUFFIXES = {".py", ".md", ".toml", ".cfg", ".ini", ".txt", ".yml", ".yaml", ".json", ""}
SKIP_MARK = "restructure: keep old names"


def git(*args: str, check: bool = True) -> str:
    """Run git in the repository; its stdout."""
    done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
    if check and done.returncode:
        sys.exit(f"git {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


def module_of(rel: str) -> str | None:
    """The module name of a repository .py path in either layout (None for other files)."""
    if not rel.endswith(".py"):
        return None
    parts = rel[:-3].split("/")
    if parts[0] in STAGES:
        parts = ["effortface", *parts]
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def planned_moves() -> list[tuple[str, str]]:
    """(old, new) repository paths of the files and folders to move, in order; done ones left out."""
    plan = [(f"train/{a}", f"effortface/synth/{b}") for a, b in SYNTH.items()]
    plan += [(f"train/{a}", f"effortface/interop/{b}") for a, b in INTEROP.items()]
    plan += [(f"capture_tool/{a}", f"effortface/core/session/{b}") for a, b in SESSION.items()]
    plan += [(f"train/{INTEROP_DIR}", "effortface/interop")]
    plan += [(s, f"effortface/{s}") for s in STAGES]
    return plan


def module_map() -> dict[str, str]:
    """Old dotted name -> new one, for every moved module or package (a prefix maps its submodules)."""
    out = {}
    for a, b in SYNTH.items():
        if a.endswith(".py"):
            out[module_of(f"train/{a}")] = module_of(f"effortface/synth/{b}")
    for a, b in INTEROP.items():
        out[module_of(f"train/{a}")] = module_of(f"effortface/interop/{b}")
    for a, b in SESSION.items():
        out[module_of(f"capture_tool/{a}")] = module_of(f"effortface/core/session/{b}")
    out["effortface.train.interop"] = "effortface.interop"
    return {k: v for k, v in out.items() if k and v}


def new_module(name: str, moves: dict[str, str]) -> str:
    """``name`` after the move (its longest moved prefix replaced)."""
    parts = name.split(".")
    for k in range(len(parts), 1, -1):
        prefix = ".".join(parts[:k])
        if prefix in moves:
            return moves[prefix] + name[len(prefix):]
    return name


def tracked() -> list[str]:
    """Tracked files (links included), repository paths."""
    return [p for p in git("ls-files", "-z").split("\0") if p]


def remove_links(dry: bool) -> None:
    """Step 1: every symbolic link git tracks goes (from the index and the disk)."""
    for line in git("ls-files", "-s").splitlines():
        mode, _, _, path = line.split(None, 3)
        if mode == "120000":
            print(f"remove link {path}")
            if not dry:
                git("rm", "-q", "--cached", path)
                if os.path.islink(ROOT / path):
                    os.unlink(ROOT / path)


def path_map(files: list[str]) -> dict[str, str]:
    """Old repository path -> new one, for every tracked file that moves (either layout's spelling)."""
    out: dict[str, str] = {}
    for old, new in planned_moves():
        for f in files:
            if (f == old or f.startswith(old + "/")) and not os.path.islink(ROOT / f) and f not in out:
                out[f] = new + f[len(old):]
    return out


def _rewrite_relative(text: str, rel: str, moves: dict[str, str]) -> str:
    """Relative imports of ``rel`` whose target moves become absolute (new names)."""
    module = module_of(rel)
    if module is None:
        return text
    package = module if rel.endswith("__init__.py") else module.rpartition(".")[0]

    def absolute(m: re.Match[str]) -> str:
        dots, name = m.group(2), m.group(3) or ""
        base = package.split(".")
        base = base[:len(base) - (len(dots) - 1)]
        target = ".".join(base + ([name] if name else []))
        names = [n.strip() for n in m.group(4).split(",")]
        moved = new_module(target, moves) != target or any(
            new_module(f"{target}.{n.split(' as ')[0]}", moves) != f"{target}.{n.split(' as ')[0]}" for n in names)
        return f"{m.group(1)}from {target} import {m.group(4)}" if moved else m.group(0)

    return re.sub(r"(?m)^([ \t]*)from (\.+)([\w.]*) import ([^\n(]+)$", absolute, text)


def _rewrite_from_imports(text: str, moves: dict[str, str]) -> str:
    """``from effortface.train import iir`` -> ``from effortface.synth import iir`` (one line per new package)."""

    def fix(m: re.Match[str]) -> str:
        indent, package, names = m.group(1), m.group(2), [n.strip() for n in m.group(3).split(",")]
        groups: dict[str, list[str]] = {}
        for n in names:
            new = new_module(f"{package}.{n.split(' as ')[0]}", moves)
            groups.setdefault(new.rpartition(".")[0] if new != f"{package}.{n.split(' as ')[0]}" else package,
                              []).append(n)
        return "\n".join(f"{indent}from {p} import {', '.join(ns)}" for p, ns in groups.items())

    return re.sub(r"(?m)^([ \t]*)from (effortface(?:\.\w+)*) import ([\w, ]+?)[ \t]*$", fix, text)


def rewrite_text(files: list[str], moves: dict[str, str], paths: dict[str, str], dry: bool) -> None:
    """Step 2: old dotted names, old file paths and crossing relative imports, in every tracked text file."""
    dotted = re.compile(r"\beffortface(?:\.\w+)+")
    by_len = sorted(paths, key=len, reverse=True)
    path_re = re.compile(r"(?<![\w.-])(?:effortface/)?(" + "|".join(map(re.escape, by_len)) + r")(?![\w/])") \
        if by_len else None
    for rel in files:
        path = ROOT / rel
        if (Path(rel).suffix not in TEXT_SUFFIXES or rel.startswith(("tests/data/", "sample_sessions/P"))
                or not path.is_file() or path.is_symlink() or path.stat().st_size > 2_000_000):
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        if SKIP_MARK in text:
            continue
        new = _rewrite_relative(text, rel, moves) if rel.endswith(".py") else text
        new = _rewrite_from_imports(new, moves) if rel.endswith(".py") else new
        new = dotted.sub(lambda m: new_module(m.group(0), moves), new)
        if path_re is not None:
            new = path_re.sub(lambda m: paths[m.group(1)], new)
        if new != text:
            print(f"rewrite {rel}")
            if not dry:
                path.write_text(new, encoding="utf-8")


def move(dry: bool) -> None:
    """Step 3: ``git mv`` the planned files and folders (those already moved are skipped)."""
    for old, new in planned_moves():
        src, dst = ROOT / old, ROOT / new
        listed = git("ls-files", old).split() if src.is_dir() else [old]
        if not src.exists() or src.is_symlink() or not listed or listed == [f"{old}/README.md"]:
            continue  # moved already (a stage folder that holds only its pointer README)
        print(f"git mv {old} {new}")
        if dry:
            continue
        if src.is_dir() and dst.is_dir():  # merge a folder into one that exists: file by file
            for f in git("ls-files", "-z", old).split("\0"):
                if f:
                    (ROOT / new / f[len(old) + 1:]).parent.mkdir(parents=True, exist_ok=True)
                    git("mv", f, new + f[len(old):])
            shutil.rmtree(src, ignore_errors=True)
        else:
            dst.parent.mkdir(parents=True, exist_ok=True)
            git("mv", old, new)


def write_packages(dry: bool) -> None:
    """New packages get an ``__init__.py`` (a docstring); the stage folders a pointer README."""
    for folder, doc in NEW_PACKAGES.items():
        init = ROOT / folder / "__init__.py"
        if not init.exists():
            print(f"create {folder}/__init__.py")
            if not dry:
                init.parent.mkdir(parents=True, exist_ok=True)
                init.write_text(f'"""{doc}"""\n', encoding="utf-8")
                git("add", str(init.relative_to(ROOT)))
    for stage in STAGES:
        folder = ROOT / stage
        if (ROOT / "effortface" / stage).is_dir() and not (folder / "README.md").exists():
            print(f"create {stage}/README.md (pointer)")
            if not dry:
                shutil.rmtree(folder, ignore_errors=True)  # caches left behind (__pycache__)
                folder.mkdir()
                (folder / "README.md").write_text(POINTER.format(stage=stage, extra=POINTER_EXTRA[stage]),
                                                  encoding="utf-8")
                git("add", f"{stage}/README.md")


def write_aliases(moves: dict[str, str], dry: bool) -> None:
    """Step 5a: the old names into ``effortface/_moved.py`` (between its BEGIN/END lines)."""
    path = ROOT / "effortface" / "_moved.py"
    text = path.read_text(encoding="utf-8")
    body = "".join(f'    "{k}": "{v}",\n' for k, v in sorted(moves.items()))
    new = re.sub(r"(# BEGIN MOVED\n).*?(    # END MOVED)", lambda m: m.group(1) + body + m.group(2), text,
                 flags=re.S)
    if new != text:
        print("write effortface/_moved.py")
        if not dry:
            path.write_text(new, encoding="utf-8")


def write_settings(dry: bool) -> None:
    """Step 5b: import-linter layers and contracts, package data, mypy and the runtime distribution."""
    path = ROOT / "pyproject.toml"
    text = path.read_text(encoding="utf-8")
    new = re.sub(r'name = "Data flows one way[^\n]*\ntype = "layers"\nlayers = \[\n.*?\n\]', lambda m: LAYERS,
                 text, count=1, flags=re.S)
    if "The runtime loads no stage" not in new:
        new = re.sub(r'(forbidden_modules = \[[^\n]*"pythonosc"\]\n)', lambda m: m.group(1) + RUNTIME_ROOMS, new,
                     count=1)
    new = re.sub(r'(?m)^"effortface" = \["docs/\*\.md"\]\n', "", new)
    new = new.replace("# the shipped documents --help, the report and the Help menu cite (effortface.core.docs): docs/ in the\n"
                      "# repository, reached through the link effortface/docs -> ../docs\n",
                      "# (the shipped documents --help, the report and the Help menu cite, docs/*.md, are copied into\n"
                      "# effortface/docs/ of a wheel by setup.py's build hook: effortface.core.docs)\n")
    new = re.sub(r"(?m)^# One installed namespace, effortface\.\*: the stage folders keep their place.*?\n(?=\[tool\.setuptools)",
                 lambda m: STAGES_COMMENT, new, count=1, flags=re.S)
    if '    "effortface.runtime",\n    "effortface.synth",\n' not in new:  # the runtime's room: strict, as its modules
        new = new.replace('    "effortface.runtime",\n', '    "effortface.runtime",\n    "effortface.synth",\n')
    new = re.sub(r'(?m)^# docs/ is reached through the effortface/docs link.*\n# not part of the package\n'
                 r'exclude = \["effortface/docs/"\]\n', "", new)
    new = re.sub(r'(?m)^"effortface.train" = \["data/\*\.csv"\]\n',
                 '"effortface.synth" = ["data/*.csv"]\n"effortface.train" = ["data/*.csv"]\n', new)
    new = new.replace('"effortface.synth" = ["data/*.csv"]\n"effortface.synth" = ["data/*.csv"]\n',
                      '"effortface.synth" = ["data/*.csv"]\n')
    if new != text:
        print("write pyproject.toml")
        if not dry:
            path.write_text(new, encoding="utf-8")
    path = ROOT / "runtime-dist" / "setup.py"
    text = path.read_text(encoding="utf-8")
    new = re.sub(r"PACKAGE_DIR = \{.*?\}\n", lambda m: RUNTIME_DIST_DIRS, text, count=1, flags=re.S)
    new = new.replace('package_data={"effortface.train": ["data/*.csv"]}',
                      'package_data={"effortface.synth": ["data/*.csv"]}')
    if new != text:
        print("write runtime-dist/setup.py")
        if not dry:
            path.write_text(new, encoding="utf-8")


def _imports(path: Path) -> set[str]:
    """The effortface modules a file imports (function-level ones too)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return {n for n in names if n.startswith("effortface")}


def source_of(module: str) -> Path | None:
    """The file of an effortface module in the tree (package ``__init__.py`` or module file)."""
    base = ROOT.joinpath(*module.split("."))
    for p in (base / "__init__.py", base.with_suffix(".py")):
        if p.is_file():
            return p
    return None


def runtime_closure() -> set[str]:
    """Every effortface module ``effortface.runtime`` imports, directly or not."""
    todo, done = ["effortface.runtime"], set()
    while todo:
        m = todo.pop()
        if m in done or source_of(m) is None:
            continue
        done.add(m)
        todo += [m.rsplit(".", k)[0] for k in range(1, m.count("."))] + sorted(_imports(source_of(m)))
    return done


def main(argv: list[str] | None = None) -> int:
    """Run the steps; 1 if the runtime still imports a module under effortface/train/."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dry-run", action="store_true", help="print what would change, change nothing")
    args = parser.parse_args(argv)
    if not args.dry_run and git("status", "--porcelain", "--untracked-files=no").strip():
        sys.exit("tools/restructure.py: expected a clean work tree (commit first), found changes: git status")
    moves = module_map()
    remove_links(args.dry_run)
    files = tracked()
    rewrite_text(files, moves, path_map(files), args.dry_run)
    move(args.dry_run)
    write_packages(args.dry_run)
    write_aliases(moves, args.dry_run)
    write_settings(args.dry_run)
    if args.dry_run:
        return 0
    left = sorted(m for m in runtime_closure() if m == "effortface.train" or m.startswith("effortface.train."))
    for m in left:
        print(f"STILL UNDER train/ and imported by effortface.runtime: {m} (add it to SYNTH in {__file__})")
    git("add", "-u")
    print("done: review with 'git status', run the tests, commit")
    return 1 if left else 0


if __name__ == "__main__":
    raise SystemExit(main())
