"""Is the face framed for the machine rater? Face found, its height as a share of the frame, brightness.

The machine rater (:mod:`effortface.annotate.machine`) finds no face smaller than about a fifth of
the frame's height: its face detector sees the whole frame shrunk to 128 x 128 pixels. Capture's
camera check and its sampling during a recording (:class:`effortface.capture_tool.framing_sampler.FramingSampler`)
and ``effortface preannotate``'s end-of-run warning ask :func:`check_framing`:

- the detector on the whole frame, as the rater runs it: when it finds the face, the face's share
  is its box's height over the frame's height;
- when it does not, the detector on overlapping crops of a half and of a third of the frame (a face
  too small for the whole frame is large enough in a crop): a face found there is too small for
  the rater, and its share says how much closer the camera must come;
- the mean brightness (0-255) of the frame, to name darkness as the likely cause when no face is found.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from effortface.core.face_landmarker import FaceLandmarker

#: the face's height as a share of the frame's that the rater needs (it finds none below about 0.22)
MIN_FACE_SHARE = 0.25
#: a mean brightness (0-255) below this is too dark for the detector
DARK_BRIGHTNESS = 40.0
#: crops tried when the whole frame shows no face: (fraction of the frame's side, steps per side)
CROP_LEVELS = ((0.5, 3), (1 / 3, 5))


@dataclasses.dataclass(frozen=True)
class Framing:
    """What the face detector sees in one frame.

    Attributes
    ----------
    face_share : float or None
        The face's height over the frame's height; None when no face was found, even in crops.
    rater_sees : bool
        The detector found the face in the whole frame, as the rater runs it.
    brightness : float
        Mean brightness of the frame, 0-255.
    """

    face_share: float | None
    rater_sees: bool
    brightness: float

    @property
    def ok(self) -> bool:
        """The rater will see the face: found in the whole frame, at least :data:`MIN_FACE_SHARE` high."""
        return self.rater_sees and self.face_share is not None and self.face_share >= MIN_FACE_SHARE

    @property
    def cause(self) -> str:
        """Why the rater may miss the face: ``"size"``, ``"darkness"``, ``"none found"``, or ``""`` when framed."""
        if self.ok:
            return ""
        if self.face_share is not None:
            return "size"
        return "darkness" if self.brightness < DARK_BRIGHTNESS else "none found"

    def line(self) -> str:
        """One line for the operator: the framing is good, or what to change."""
        if self.ok:
            return (f"face found: {_pct(self.face_share)} of the frame height (the rater needs "
                    f"{_pct(MIN_FACE_SHARE)}), brightness {self.brightness:.0f} of 255")
        if self.cause == "size":
            return (f"move the camera closer: the face is {_pct(self.face_share)} of the frame; the rater needs "
                    f"{_pct(MIN_FACE_SHARE)}")
        if self.cause == "darkness":
            return (f"no face found: the image is dark (brightness {self.brightness:.0f} of 255); light the face "
                    "or open the camera's exposure")
        return "no face found: turn the camera to the participant's face"


def _pct(share: float | None) -> str:
    return f"{100 * (share or 0.0):.0f} %"


def brightness(rgb: np.ndarray) -> float:
    """Mean brightness (Rec. 601 luma, 0-255) of an RGB image."""
    mean = np.asarray(rgb, dtype=np.float64).reshape(-1, rgb.shape[-1])[:, :3].mean(axis=0)
    return float(0.299 * mean[0] + 0.587 * mean[1] + 0.114 * mean[2])


def check_framing(rgb: np.ndarray, detector: FaceLandmarker) -> Framing:
    """The face detector's view of one RGB frame (see the module's description).

    Parameters
    ----------
    rgb : numpy.ndarray
        The frame, H x W x 3 uint8 RGB.
    detector : FaceLandmarker
        The engine whose detector runs (:meth:`~effortface.core.face_landmarker.FaceLandmarker.detect_face`);
        its tracking is not touched.
    """
    light = brightness(rgb)
    found = detector.detect_face(rgb)
    if found is not None:
        (_, y0, _, y1), _, _ = found
        return Framing(y1 - y0, True, light)
    return Framing(_share_in_crops(rgb, detector), False, light)


def _share_in_crops(rgb: np.ndarray, detector: Any) -> float | None:
    """The height share of the best face the detector finds in overlapping crops, or None."""
    frame_h, frame_w = rgb.shape[:2]
    for fraction, steps in CROP_LEVELS:
        crop_h, crop_w = max(1, round(frame_h * fraction)), max(1, round(frame_w * fraction))
        best: tuple[float, float] | None = None  # (score, share)
        for top in np.linspace(0, frame_h - crop_h, steps).round().astype(int):
            for left in np.linspace(0, frame_w - crop_w, steps).round().astype(int):
                found = detector.detect_face(np.ascontiguousarray(rgb[top:top + crop_h, left:left + crop_w]))
                if found is not None and (best is None or found[2] > best[0]):
                    (_, y0, _, y1), _, score = found
                    best = (score, (y1 - y0) * crop_h / frame_h)
        if best is not None:
            return best[1]
    return None
