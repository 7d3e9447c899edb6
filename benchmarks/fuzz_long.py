"""The long fuzzing run: tests/test_fuzz.py with many examples and fresh random seeds.

The CI job (``.ci/fuzz``) runs the same properties briefly on every change with a fixed seed; this
run explores much further (minutes to hours) and prints hypothesis's statistics and any falsifying
example, which becomes a fixed test once understood.

Run: ``python benchmarks/fuzz_long.py [--examples 5000] [--fixed-seed] [-k ann]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    """Run the fuzz module with ``--examples`` per property; return pytest's exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=5000, help="examples per property (default 5000)")
    parser.add_argument("--fixed-seed", action="store_true", help="the CI's seed instead of random ones")
    parser.add_argument("-k", default=None, help="pytest -k expression to pick properties")
    args = parser.parse_args(argv)
    env = {**os.environ, "EFFORTFACE_FUZZ_EXAMPLES": str(args.examples),
           "EFFORTFACE_FUZZ_RANDOM": "0" if args.fixed_seed else "1", "QT_QPA_PLATFORM": "offscreen",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--hypothesis-show-statistics",
           "-o", "faulthandler_timeout=0", str(ROOT / "tests" / "test_fuzz.py")]
    if args.k:
        cmd += ["-k", args.k]
    start = time.perf_counter()
    status = subprocess.call(cmd, cwd=ROOT, env=env)
    print(f"fuzz_long: {args.examples} examples per property, {time.perf_counter() - start:.0f} s, "
          f"{'no failure' if status == 0 else 'FAILURES above'}")
    return status


if __name__ == "__main__":
    sys.exit(main())
