"""The guide builds: ``python -m mkdocs build --strict`` (mkdocs.yml at the root), with the generated
command-line, error and API reference pages; the README stays a one-minute read."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

pytest.importorskip("mkdocs", reason="the guide's tools come with the docs extra: pip install -e '.[docs]'")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-6000:]
    return out


@pytest.mark.slow
def test_the_guide_builds_strictly_with_its_reference_pages(site: Path) -> None:
    pages = sorted(p.relative_to(site).as_posix() for p in site.rglob("*.html"))
    assert len(pages) >= 10, pages
    api = [p for p in pages if p.startswith("reference/api/")]
    assert "reference/api/effortface.runtime/index.html" in api and len(api) >= 50, api[:20]
    for page in ("guide/getting-started/index.html", "guide/layout/index.html", "reference/cli/index.html",
                 "reference/errors/index.html", "DESIGN/index.html", "SCIENCE/index.html"):
        assert page in pages, page


@pytest.mark.slow
def test_the_generated_references_hold_the_real_parsers_and_docstrings(site: Path) -> None:
    cli = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    assert "effortface synth" in cli and "--filter-tau-s" in cli and "effortface capture" in cli
    errors = (site / "reference" / "errors" / "index.html").read_text(encoding="utf-8")
    assert "expected a folder of sessions" in errors
    runtime = (site / "reference" / "api" / "effortface.runtime" / "index.html").read_text(encoding="utf-8")
    assert "load_model" in runtime


def test_every_guide_page_is_in_the_navigation() -> None:
    """Pages other changes add to docs/guide/ appear without editing mkdocs.yml (the hook lists them)."""
    sys.path.insert(0, str(ROOT / "tools"))
    import docs_hooks

    listed = docs_hooks.guide_pages()
    on_disk = sorted(f"guide/{p.name}" for p in (ROOT / "docs" / "guide").glob("*.md") if not p.name.startswith("_"))
    assert sorted(listed) == on_disk
    assert listed[0] == "guide/getting-started.md"


def test_the_guide_is_in_four_parts() -> None:
    """Tutorials, how-to guides, reference and explanation (issue 40); the tutorials are one per user,
    and every page of docs/guide/ is in one of them."""
    sys.path.insert(0, str(ROOT / "tools"))
    import docs_hooks

    nav = docs_hooks.navigation()
    assert [next(iter(e)) for e in nav] == ["Home", "Tutorials", "How-to guides", "Reference", "Explanation"]

    def pages(entries: list) -> list[str]:
        out = []
        for e in entries:
            (value,) = e.values()
            out += pages(value) if isinstance(value, list) else [value]
        return out

    parts = {name: pages(entries) for e in nav[1:] for name, entries in e.items()}
    assert parts["Tutorials"][1:] == ["guide/tutorial-record.md", "guide/tutorial-key.md", "guide/tutorial-train.md",
                                      "guide/tutorial-character.md"], parts["Tutorials"]
    assert {"reference/cli.md", "reference/errors.md", "guide/formats.md"} <= set(parts["Reference"])
    assert {"SCIENCE.md", "guide/layout.md", "guide/reliability.md"} <= set(parts["Explanation"])
    listed = [p for part in parts.values() for p in part]
    assert sorted(p for p in listed if p.startswith("guide/")) == sorted(docs_hooks.guide_pages())
    assert len(listed) == len(set(listed)), "a page in two parts"


def test_no_page_is_named_after_a_round() -> None:
    """Pages say what they hold, not the round of work that made them (what changed: CHANGELOG.md)."""
    sys.path.insert(0, str(ROOT / "tools"))
    import docs_hooks

    word = re.compile(r"\bround\b", re.I)
    for page in sorted((ROOT / "docs").rglob("*.md")):
        assert not word.search(page.stem.replace("-", " ").replace("_", " ")), page
        assert not word.search(docs_hooks._title(page.relative_to(ROOT / "docs").as_posix())), page
    for title in re.findall(r"'([^']+)'", str(docs_hooks.navigation())):
        assert not word.search(title), title


def test_the_readme_is_a_one_minute_read() -> None:
    size = (ROOT / "README.md").stat().st_size
    assert size <= 12_000, f"README.md: expected at most 12,000 bytes, found {size}"


def test_nothing_of_the_old_readme_is_lost() -> None:
    """Every line of the README before it became a guide appears in some page of docs/ (tools/readme_in_guide.py)."""
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "readme_in_guide.py")], cwd=ROOT, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
