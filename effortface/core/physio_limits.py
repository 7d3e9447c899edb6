"""Physiological limits of heart-rate data: the one place that says what a plausible sample is.

Applied where samples are born (the strap decoders, :mod:`effortface.capture_tool.protocols`) and
by every reader that must not trust a file (training's range check). A heart rate outside
:data:`HR_BPM` is not a heart rate but a strap artefact (a checksum-valid frame can carry 1 bpm or
255 bpm); an R-R interval outside :data:`RR_MS` is a timestamp glitch, not a beat (0 ms, or a
64 s wrap of a 1/1024 s counter). Stdlib only, so the runtime may import it.
"""

from __future__ import annotations

#: plausible heart rate, bpm: the lowest and highest rates reported in humans, rounded outwards
HR_BPM = (20.0, 250.0)
#: plausible R-R interval, ms: up to 60000 / 20 bpm; down to 200 ms, shorter than 60000 / 250 bpm
#: because a premature beat gives one short interval (the ANT reference recording holds 200.2 ms)
RR_MS = (200.0, 60_000.0 / HR_BPM[0])
#: heart rate an imported sample (a watch file, another app's stream) may have to be valid, bpm: the
#: ceiling of :data:`HR_BPM` with a stricter floor, since a file may hold anything under its name
IMPORT_HR_BPM = (25.0, HR_BPM[1])


def hr_plausible(hr_bpm: float | None) -> bool:
    """True if ``hr_bpm`` is a number within :data:`HR_BPM` (None and NaN are not).

    Parameters
    ----------
    hr_bpm : float or None
        A heart rate in beats per minute.

    Returns
    -------
    bool
    """
    return hr_bpm is not None and HR_BPM[0] <= hr_bpm <= HR_BPM[1]


def rr_plausible(rr_ms: float) -> bool:
    """True if ``rr_ms`` is an R-R interval within :data:`RR_MS` (NaN is not).

    Parameters
    ----------
    rr_ms : float
        An R-R interval in milliseconds.

    Returns
    -------
    bool
    """
    return RR_MS[0] <= rr_ms <= RR_MS[1]


#: plausible adult body dimensions, metres: the standing height (top of the head above the lowest
#: foot) and the main segment lengths between the joint centres a skeleton gives (hip to knee, knee
#: to ankle, shoulder to elbow, elbow to wrist, neck base to mid-hips). Wide on purpose: they refuse
#: the wrong unit (x 2.54, x 10), doubled bones and a wrong up axis, not a tall or a short adult;
#: a child or a creature passes with ``--trust-skeleton``.
BODY_M: dict[str, tuple[float, float]] = {
    "height_m": (1.2, 2.2),
    "thigh": (0.3, 0.6),
    "shank": (0.28, 0.6),
    "upper_arm": (0.18, 0.45),
    "forearm": (0.15, 0.4),
    "trunk": (0.3, 0.9),
}
#: the ground under a body, the plane the lowest joint of every frame lies on: at most this tilt
#: (degrees; a ramp or a staircase is below it, a body read with the wrong up axis above) and half
#: the frames within this distance (metres) of the plane (a hop leaves it, a body on its side does not
#: touch it)
GROUND_TILT_DEG = 45.0
GROUND_SPREAD_M = 0.25
