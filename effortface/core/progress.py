"""Progress on stderr for long commands: a tqdm bar on a terminal, plain lines in a log or a pipe.

``train``, ``export``, ``preannotate`` and ``synth`` of a folder report through :class:`ProgressBar`, so
a redirected stderr never holds tqdm's carriage returns and escape codes.
"""

from __future__ import annotations

import sys
from typing import Any


class ProgressBar:
    """A progress bar on stderr driven by a :data:`ProgressFn`; it appears at its first report.

    So a run refused by its data checks prints its one error line and no bar. On a terminal it is
    a tqdm bar; when stderr is redirected (a log file, a pipe) it writes plain lines instead,
    ``<desc>: <percent>% <step>``, one per new step or 10 % (no carriage returns or escape codes).

    Parameters
    ----------
    desc : str
        The bar's label.
    enabled : bool
        False shows nothing.
    """

    #: percent between two plain lines of the same step
    PLAIN_STEP_PERCENT = 10

    def __init__(self, desc: str, enabled: bool = True) -> None:
        self.desc, self.enabled = desc, enabled
        self._bar: Any = None
        self._last_plain: tuple[int, str] | None = None

    def __call__(self, fraction: float, text: str) -> None:
        """Show ``fraction`` (0-1) done and ``text``."""
        if not self.enabled:
            return
        percent = round(100 * fraction)
        if not _is_terminal(sys.stderr):
            self._plain_line(percent, text)
            return
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=100, desc=self.desc, unit="%", file=sys.stderr)
        self._bar.n = percent
        self._bar.set_postfix_str(text)

    def _plain_line(self, percent: int, text: str) -> None:
        """One stderr line when the step or the tenth of the way changes."""
        key = (percent // self.PLAIN_STEP_PERCENT, text)
        if key != self._last_plain:
            self._last_plain = key
            print(f"{self.desc}: {percent:3d}% {text}", file=sys.stderr, flush=True)

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()


def _is_terminal(stream: Any) -> bool:
    """Whether ``stream`` is an interactive terminal (False for files, pipes, captured streams)."""
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())
