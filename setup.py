"""Build hook: the documents ``--help`` and the Help menu cite ship inside the package.

``docs/*.md`` and the guide's pages ``docs/guide/*.md`` stay in the repository's ``docs/`` (one copy,
no link); a wheel gets them as ``effortface/docs/*.md`` and ``effortface/docs/guide/*.md`` (so the
links of ``docs/index.md`` resolve in an installed copy too), copied into the build folder here. An editable install reads ``docs/``
itself (``effortface.core.docs.DOCS_DIR``). Everything else is in ``pyproject.toml``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


class BuildWithDocs(build_py):
    """``build_py`` that also copies ``docs/*.md`` to ``<build>/effortface/docs/``."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        target = Path(self.build_lib) / "effortface" / "docs"
        for doc in sorted([*(ROOT / "docs").glob("*.md"), *(ROOT / "docs" / "guide").glob("*.md")]):
            copy = target / doc.relative_to(ROOT / "docs")
            copy.parent.mkdir(parents=True, exist_ok=True)
            if not copy.exists():
                shutil.copy2(doc, copy)


setup(cmdclass={"build_py": BuildWithDocs})
