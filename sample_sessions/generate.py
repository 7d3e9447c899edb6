"""Regenerate this sample lab: ``python sample_sessions/generate.py [--out DIR] [--only SESSION_ID]
[--seed N] [--force]`` (default ``--out``: this folder).

A thin wrapper: the generator ships with the package as :mod:`effortface.samplelab.generate` (so that
an installed effortface can build the lab into a user cache, see :mod:`effortface.samplelab`).
"""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:  # run as a script from a checkout: use this checkout's code
    sys.path.insert(0, str(HERE.parent))

from effortface.samplelab.generate import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(default_out=HERE))
