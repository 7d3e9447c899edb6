"""Code lines per room: each package of ``effortface/`` (and each top-level stage folder that holds code).

A code line is a line of a ``.py`` file that is neither blank nor only a comment (docstrings count:
they are the code's documentation). Links are not followed, so each file counts once in either
layout. Usage: ``python tools/room_sizes.py`` prints the table; ``--max-share 33`` exits 1 if a room
holds more than 33 % of the lines.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGE_FOLDERS = ("capture_tool", "annotate", "train")


def code_lines(path: Path) -> int:
    """Lines of ``path`` that are not blank and not only a comment."""
    lines = path.read_text(encoding="utf-8").splitlines()
    return sum(1 for line in lines if line.strip() and not line.lstrip().startswith("#"))


def room_of(rel: Path) -> str:
    """The room of a repository path: ``effortface/<package>``, a top-level stage folder, or the front door."""
    if rel.parts[0] != "effortface":
        return rel.parts[0] + "/"
    return f"effortface/{rel.parts[1]}/" if len(rel.parts) > 2 else "effortface/*.py (front door)"


def room_sizes(root: Path = ROOT) -> dict[str, int]:
    """Room -> code lines, for the product's Python files (tests, benchmarks and tools excluded)."""
    sizes: dict[str, int] = {}
    for top in ("effortface", *STAGE_FOLDERS):
        for folder, dirs, files in os.walk(root / top):
            dirs[:] = [d for d in dirs if d != "__pycache__"]
            for name in files:
                if name.endswith(".py"):
                    path = Path(folder) / name
                    room = room_of(path.relative_to(root))
                    sizes[room] = sizes.get(room, 0) + code_lines(path)
    return sizes


def main(argv: list[str] | None = None) -> int:
    """Print the table, largest room first; 1 if a room exceeds ``--max-share`` percent."""
    parser = argparse.ArgumentParser(description="code lines per room of the product")
    parser.add_argument("--max-share", type=float, default=100.0, help="percent a room may hold (default 100)")
    args = parser.parse_args(argv)
    sizes = room_sizes()
    total = sum(sizes.values())
    print(f"{'room':<36} {'lines':>7} {'share':>7}")
    for room, n in sorted(sizes.items(), key=lambda kv: -kv[1]):
        print(f"{room:<36} {n:>7} {100 * n / total:>6.1f}%")
    print(f"{'total':<36} {total:>7}")
    return 1 if max(sizes.values()) > args.max_share * total / 100 else 0


if __name__ == "__main__":
    raise SystemExit(main())
