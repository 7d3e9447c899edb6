"""MkDocs hooks (``mkdocs.yml``: ``hooks``): the pages made from the code at build time.

- the navigation: the guide in four parts, :data:`PARTS` (tutorials, how-to guides, reference,
  explanation); every other ``docs/guide/*.md`` joins the how-to guides by name (a page another
  change adds appears without editing anything);
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
#: the guide in four parts (tutorials, how-to guides, reference, explanation): part -> pages, in reading
#: order; a ``(title, [pages])`` entry is a sub-section. A docs/guide/*.md page not listed here goes
#: to the how-to guides (by name), so a page another change adds appears without editing anything.
PARTS: dict[str, list[Any]] = {
    "Tutorials": ["guide/getting-started.md", "guide/tutorial-record.md", "guide/tutorial-key.md",
                  "guide/tutorial-train.md", "guide/tutorial-character.md"],
    "How-to guides": ["guide/import-heart-rate.md", "guide/read-c3d-from-qualisys.md", "guide/skeleton-mapping.md",
                      "guide/recover-a-crashed-session.md", "guide/train-on-a-cluster.md", "guide/export-bids.md",
                      "guide/serve-live-to-unreal.md", "guide/blender.md", "guide/troubleshooting.md",
                      ("Extend effortface", ["guide/extend-strap-protocol.md", "guide/extend-motion-format.md",
                                             "guide/extend-output-format.md", "guide/extend-live-protocol.md"])],
    "Reference": [("The application's stages", ["guide/app.md", "guide/capture.md", "guide/annotate.md",
                                                 "guide/machine-rater.md", "guide/machine-rater-annotate.md",
                                                 "guide/train.md", "guide/synthesize.md", "guide/motion-and-work.md",
                                                 "guide/interop.md"]),
                  ("Command line", "reference/cli.md"), "guide/formats.md", ("Design card", "DESIGN.md"),
                  "guide/sample-data.md", ("Errors", "reference/errors.md")],
    "Explanation": ["guide/science-in-brief.md", ("The science", "SCIENCE.md"), ("Science notes", "SCIENCE_NOTES.md"),
                    "guide/layout.md", ("Engine guide", "ENGINE.md"), "guide/machine-rater-effort-mapping.md",
                    "guide/reliability.md", "guide/app-lab-records.md",
                    "guide/training-at-scale.md", "guide/scores-and-live-streams.md",
                    "guide/files-from-other-labs.md"],
}
#: the pages a part lists that are generated at build time (not on disk)
GENERATED = {"reference/cli.md", "reference/errors.md"}
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


def _listed(entries: list[Any]) -> list[str]:
    """The page paths of a part's entries, sub-sections included."""
    out: list[str] = []
    for e in entries:
        if isinstance(e, str):
            out.append(e)
        elif isinstance(e[1], list):
            out += _listed(e[1])
        else:
            out.append(e[1])
    return out


def guide_pages() -> list[str]:
    """``guide/*.md`` paths in navigation order (``_drafts`` left out): the parts' pages, then the others by name."""
    found = sorted(f"guide/{p.name}" for p in (ROOT / "docs" / "guide").glob("*.md") if not p.name.startswith("_"))
    listed = [p for part in PARTS.values() for p in _listed(part) if p in found]
    return [*listed, *[p for p in found if p not in listed]]


def _nav(entries: list[Any]) -> list[Any]:
    """MkDocs navigation entries of a part (pages that do not exist left out)."""
    out: list[Any] = []
    for e in entries:
        if isinstance(e, str):
            if (ROOT / "docs" / e).is_file():
                out.append({_title(e): e})
        elif isinstance(e[1], list):
            out.append({e[0]: _nav(e[1])})
        elif e[1] in GENERATED or (ROOT / "docs" / e[1]).is_file():
            out.append({e[0]: e[1]})
    return out


def navigation() -> list[Any]:
    """Home, the four parts (unlisted guide pages join the how-to guides) and the API reference."""
    api: dict[str, list[Any]] = {}
    for module in public_modules():
        room = ".".join(module.split(".")[:2])
        api.setdefault(room, []).append({module: f"reference/api/{module}.md"})
    listed = {p for part in PARTS.values() for p in _listed(part)}
    others = [p for p in guide_pages() if p not in listed]
    parts = {name: _nav(entries) for name, entries in PARTS.items()}
    parts["How-to guides"] += _nav(others)
    parts["Reference"].append({"API": [{room: pages} for room, pages in api.items()]})
    return [{"Home": "index.md"}, *({name: entries} for name, entries in parts.items())]


def on_config(config: Any) -> Any:
    """The navigation, made from the pages that exist."""
    config["nav"] = navigation()
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
