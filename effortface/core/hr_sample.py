"""One decoded heart-rate observation: what strap decoders return and ``heart_rate.csv`` holds.

Defined in the core because the session-folder format (read by every stage) and the decoders of
the capture stage both use it; ``effortface.capture_tool.protocols`` re-exports it.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class HrSample:
    """One decoded heart-rate observation, one row of ``heart_rate.csv``.

    Attributes
    ----------
    t_s : float
        Host arrival time of the bytes that completed this sample (session seconds).
    hr_bpm : float or None
        Heart rate; None when the strap reports no contact (then ``valid`` is False).
    rr_ms : tuple of float
        R-R intervals first observed in this sample, oldest first (may be empty).
    beat_count : int or None
        The strap's own beat counter (ANT beat count, HxM heartbeat number), if it has one.
    device : str
        Device identifier (e.g. ``"ant:3425"``, ``"hxm"``).
    valid : bool
        False on contact loss or an invalid (0) HR; such rows are kept, never written as 0 bpm.
    """

    t_s: float
    hr_bpm: float | None
    rr_ms: tuple[float, ...] = ()
    beat_count: int | None = None
    device: str = ""
    valid: bool = True
