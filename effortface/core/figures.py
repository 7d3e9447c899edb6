"""Figures for files (PNG reports), drawn without pyplot so that any thread may draw them.

pyplot keeps global state and may switch backends, which is unsafe off the main thread (the Train
stage writes its report from a worker thread). A :class:`matplotlib.figure.Figure` with its own Agg
canvas has no global state; matplotlib is imported here, on first use, so importing the callers
stays cheap.
"""

from __future__ import annotations

from typing import Any, Literal

from effortface.core.errors import UserError


def agg_figure(figsize: tuple[float, float], *,
               layout: Literal["constrained", "compressed", "tight"] | None = None) -> Any:
    """A new figure on its own Agg canvas (no pyplot, no display, nothing to close).

    Parameters
    ----------
    figsize : tuple of float
        Width and height in inches.
    layout : str, optional
        matplotlib layout engine, e.g. ``"constrained"`` or ``"tight"``.

    Returns
    -------
    matplotlib.figure.Figure
        Draw with ``fig.subplots(...)``; write with ``fig.savefig(path)``.

    Raises
    ------
    UserError
        If matplotlib is not installed.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise UserError("plots: expected matplotlib installed (pip install matplotlib), found none") from None
    fig = Figure(figsize=figsize, layout=layout)
    FigureCanvasAgg(fig)
    return fig
