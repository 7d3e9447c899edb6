"""MkDocs hooks (``mkdocs.yml``: ``hooks``): the pages made from the code at build time.

- the navigation: the guide's pages in :data:`GUIDE_ORDER`, then every other ``docs/guide/*.md``
  by name (a page another change adds appears without editing anything), the science, the design
  card and the engine guide, then the references;
- ``reference/cli.md``: every command's options, from the real argparse parsers
  (:func:`effortface.cli.command_parser`);
- ``reference/errors.md``: the one-line errors the sources raise (``UserError`` and its subclasses),
  found statically;
- ``reference/api/<module>.md``: one page per public module of the ``effortface`` package (walked on
  disk, so a moved or new module gets its page), rendered by mkdocstrings from the numpydoc
  docstrings (griffe reads the sources; nothing is imported).
"""

from __future__ import annotations

import argparse
import ast
import io
import os
import re
from contextlib import redirect_stdout
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "effortface"
#: the guide's own pages, in reading order (other docs/guide/*.md pages follow, by name)
GUIDE_ORDER = ["getting-started.md", "layout.md", "app.md", "capture.md", "heart-rate-devices.md", "annotate.md",
               "machine-rater.md", "machine-rater-effort-mapping.md", "machine-rater-annotate.md",
               "train.md", "motion-and-work.md", "skeleton-mapping.md", "synthesize.md", "blender.md", "interop.md",
               "formats.md", "sample-data.md",
               "troubleshooting.md", "extend-strap-protocol.md", "extend-motion-format.md",
               "extend-output-format.md", "extend-live-protocol.md"]
BACKGROUND = [("Design card", "DESIGN.md"), ("The science", "SCIENCE.md"), ("Science notes", "SCIENCE_NOTES.md"),
              ("Engine guide", "ENGINE.md")]
#: exception classes whose messages are the one-line errors a user reads
ERROR_CLASSES = {"UserError", "SessionFormatError", "MotionFormatError", "CatalogError", "LockedError",
                 "DeviceError", "BundleError", "ModelFormatError"}


def public_modules() -> list[str]:
    """Dotted names of the package's public modules (no ``_private`` part, no ``__main__``), sorted."""
    names = []
    for folder, dirs, files in os.walk(PACKAGE, followlinks=True):  # the stage links of the old layout
        dirs[:] = sorted(d for d in dirs if not d.startswith(("_", ".")) and (Path(folder, d, "__init__.py")).is_file())
        rel = Path(folder).relative_to(ROOT).parts
        for f in sorted(files):
            if f.endswith(".py") and (f == "__init__.py" or not f.startswith("_")):
                names.append(".".join(rel if f == "__init__.py" else (*rel, f[:-3])))
    return sorted(names)


def _title(path: str) -> str:
    """A page's first ``# heading`` (or its file name)."""
    for line in (ROOT / "docs" / path).read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return Path(path).stem.replace("-", " ").capitalize()


def guide_pages() -> list[str]:
    """``guide/*.md`` paths in navigation order (``_drafts`` left out)."""
    found = sorted(p.name for p in (ROOT / "docs" / "guide").glob("*.md") if not p.name.startswith("_"))
    return [f"guide/{n}" for n in [*[n for n in GUIDE_ORDER if n in found], *[n for n in found if n not in GUIDE_ORDER]]]


def on_config(config: Any) -> Any:
    """The navigation, made from the pages that exist."""
    api: dict[str, list[Any]] = {}
    for module in public_modules():
        room = ".".join(module.split(".")[:2])
        api.setdefault(room, []).append({module: f"reference/api/{module}.md"})
    config["nav"] = [
        {"Home": "index.md"},
        {"Guide": [{_title(p): p} for p in guide_pages()]},
        {"Background": [{t: p} for t, p in BACKGROUND if (ROOT / "docs" / p).is_file()]},
        {"Reference": [{"Command line": "reference/cli.md"}, {"Errors": "reference/errors.md"},
                       {"API": [{room: pages} for room, pages in api.items()]}]},
    ]
    return config


def _help(parser: argparse.ArgumentParser) -> str:
    out = io.StringIO()
    with redirect_stdout(out):
        parser.print_help()
    return out.getvalue().replace(str(ROOT), "<repository>")


def cli_page() -> str:
    """The command-line reference: ``effortface --help`` and every command's ``--help``."""
    from effortface import cli

    parts = ["# Command-line reference\n", "Made from the command line's own parsers when the guide is built "
             "(`effortface --help`, `effortface COMMAND --help`).\n", "## effortface\n",
             "```text\n" + _help(cli.top_parser()) + "```\n"]
    for name in cli.COMMANDS:
        parts += [f"## effortface {name}\n", "```text\n" + _help(cli.command_parser(name)) + "```\n"]
    return "\n".join(parts)


def _message(node: ast.expr) -> str | None:
    """The text of a string or f-string argument (``{...}`` for the parts filled at run time)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "{...}" for v in node.values)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, right = _message(node.left), _message(node.right)
        return None if left is None or right is None else left + right
    return None


def error_messages() -> dict[str, list[tuple[str, str]]]:
    """Module -> [(exception class, message)] for every ``raise X("...")`` of an error class."""
    out: dict[str, list[tuple[str, str]]] = {}
    for module in public_modules():
        path = ROOT.joinpath(*module.split("."))
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and node.exc.args
                    and isinstance(node.exc.func, ast.Name) and node.exc.func.id in ERROR_CLASSES):
                text = _message(node.exc.args[0])
                if text:
                    out.setdefault(module, []).append((node.exc.func.id, " ".join(text.split())))
    return out


def errors_page() -> str:
    """The error reference: every one-line error message, by module (see the troubleshooting page)."""
    lines = ["# Error reference\n",
             "Every one-line error the code raises for bad input, found in the sources when the guide is "
             "built. A command prints it as `effortface COMMAND: error: MESSAGE` and exits with status 2; "
             "`{...}` stands for what is filled in at run time (a path, a value, what was found). "
             "What the common ones mean: [Troubleshooting](../guide/troubleshooting.md).\n"]
    for module, found in error_messages().items():
        lines.append(f"## `{module}`\n")
        lines += [f"- `{kind}`: {msg.replace('|', '/').replace('`', '')}" for kind, msg in found]
        lines.append("")
    return "\n".join(lines)


def api_page(module: str) -> str:
    """One module's API page (mkdocstrings renders it from the docstrings)."""
    return f"# `{module}`\n\n::: {module}\n    options:\n      show_root_heading: false\n"


_LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s#]+)(#[^)\s]*)?\)")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    """A link from a page to a repository file outside ``docs/`` (``../../tests/data/README.md``),
    which the site cannot serve, becomes the file's repository path in code; a link to a file that
    does not exist is left for MkDocs to refuse (the strict build fails)."""
    if page.file.abs_src_path is None:  # a generated page
        return markdown
    here = Path(page.file.abs_src_path).parent
    docs_dir = Path(config["docs_dir"]).resolve()

    def outside(m: re.Match[str]) -> str:
        target = m.group(3)
        if "://" in target or target.startswith(("mailto:", "/")):
            return m.group(0)
        path = (here / target).resolve()
        if path.is_relative_to(docs_dir) or not path.exists() or not path.is_relative_to(ROOT):
            return m.group(0)
        return f"{m.group(2)} (`{path.relative_to(ROOT).as_posix()}`)"

    return _LINK.sub(outside, markdown)


def on_files(files: Files, config: Any) -> Files:
    """Add the generated pages to the build."""
    pages = {"reference/cli.md": cli_page(), "reference/errors.md": errors_page()}
    pages.update({f"reference/api/{m}.md": api_page(m) for m in public_modules()})
    for path, text in pages.items():
        files.append(File.generated(config, path, content=text))
    return files
