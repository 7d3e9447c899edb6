"""The parametric face: each blendshape moves its own part of the face, visibly and in the right
direction; pose, lighting and noise behave; bad weights are refused.

Measured on the rendered pixels (colour masks of the known palette), not on internal geometry.
"""

from __future__ import annotations

import numpy as np
import pytest

from effortface.annotate.face import render_face

SIZE = (320, 240)


def _mask(img: np.ndarray, bgr: tuple[int, int, int], tol: int = 30) -> np.ndarray:
    return (np.abs(img.astype(int) - np.array(bgr)).max(axis=2) <= tol)


def _face(**weights: float) -> np.ndarray:
    return render_face(weights, SIZE)


def _rows_cols(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.nonzero(mask)


def test_output_is_bgr_uint8_of_the_asked_size_and_deterministic() -> None:
    img = render_face([0.3, 0.4, 0.5, 0.6], (160, 120))
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8
    assert np.array_equal(img, render_face([0.3, 0.4, 0.5, 0.6], (160, 120)))


def test_mouth_open_drops_the_jaw_on_a_dark_mouth() -> None:
    inside = (40, 30, 110)
    closed, half, wide = (_mask(_face(mouth_open=v), inside, 15).sum() for v in (0.0, 0.5, 1.0))
    assert closed == 0 and 100 < half and wide > 2 * half
    rows_wide = _rows_cols(_mask(_face(mouth_open=1.0), inside, 15))[0]
    assert rows_wide.min() > 0.6 * SIZE[1]  # the opening is in the lower face


def test_mouth_stretch_pulls_the_corners_wider() -> None:
    lip = (70, 70, 160)
    widths = []
    for v in (0.0, 0.5, 1.0):
        lower_face = _face(mouth_stretch=v)[int(0.6 * SIZE[1]):int(0.85 * SIZE[1])]
        cols = _rows_cols(_mask(lower_face, lip, 25))[1]
        widths.append(cols.max() - cols.min())
    assert widths[0] < widths[1] < widths[2] and widths[2] > 1.5 * widths[0]


def test_eye_squint_closes_the_lids() -> None:
    white = (245, 245, 245)
    areas = [_mask(_face(eye_squint=v), white, 25).sum() for v in (0.0, 0.5, 1.0)]
    assert areas[0] > 2 * areas[1] > 2 * areas[2] >= 0
    assert areas[0] > 300


def test_brow_lower_moves_the_brows_down_and_in() -> None:
    def brows(v: float) -> tuple[float, float]:
        w, h = SIZE
        top, left = int(0.28 * h), int(0.35 * w)  # below the hair line, inside the side hair
        band = _face(brow_lower=v)[top:int(0.5 * h), left:int(0.65 * w)]
        rows, cols = np.nonzero(_mask(band, (40, 55, 75), 20))
        inner = np.abs(cols + left - w / 2).min()
        return rows.mean() + top, inner

    (y0, in0), (y1, in1) = brows(0.0), brows(1.0)
    assert y1 > y0 + 8  # at least 8 px lower at 240 px height
    assert in1 < in0  # inner ends closer to the midline


def test_each_blendshape_only_changes_its_own_region() -> None:
    neutral = _face().astype(int)
    h = SIZE[1]
    regions = {"mouth_stretch": slice(int(0.6 * h), h), "mouth_open": slice(int(0.6 * h), h),
               "eye_squint": slice(int(0.35 * h), int(0.55 * h)), "brow_lower": slice(int(0.25 * h), int(0.55 * h))}
    for name, rows in regions.items():
        diff = np.abs(_face(**{name: 1.0}).astype(int) - neutral).max(axis=2) > 40
        inside = diff[rows].sum()
        assert inside > 100, name
        assert diff.sum() - inside < 0.15 * diff.sum(), name


def test_head_pose_moves_and_rolls_the_face() -> None:
    skin = (150, 180, 225)
    base = _rows_cols(_mask(_face(), skin, 10))
    moved = _rows_cols(_mask(render_face({}, SIZE, head_pose=(0.1, 0.05, 0.0)), skin, 10))
    assert moved[1].mean() - base[1].mean() == pytest.approx(0.1 * SIZE[0], abs=3)
    assert moved[0].mean() - base[0].mean() == pytest.approx(0.05 * SIZE[1], abs=3)
    rolled = render_face({}, SIZE, head_pose=(0.0, 0.0, 15.0))
    assert not np.array_equal(rolled, _face())


def test_lighting_scales_brightness_and_rng_adds_reproducible_noise() -> None:
    dim, bright = render_face({}, SIZE, lighting=0.8), render_face({}, SIZE, lighting=1.2)
    assert dim.mean() < _face().mean() < bright.mean()
    a = render_face({}, SIZE, rng=np.random.default_rng(5))
    b = render_face({}, SIZE, rng=np.random.default_rng(5))
    c = render_face({}, SIZE, rng=np.random.default_rng(6))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert 0.5 < np.abs(a.astype(int) - _face().astype(int)).mean() < 4


def test_weights_are_clipped_and_dict_and_vector_agree() -> None:
    as_dict = render_face({"mouth_open": 0.7, "eye_squint": 0.2}, (160, 120))
    assert np.array_equal(as_dict, render_face([0, 0.7, 0.2, 0], (160, 120)))
    assert np.array_equal(render_face([2, -1, 0, 0], (160, 120)), render_face([1, 0, 0, 0], (160, 120)))


@pytest.mark.parametrize("match, weights, size", [
    (r"weights: expected 4 values, found 3", [0.1, 0.2, 0.3], SIZE),
    (r"weights: expected names among .* found \['smile'\]", {"smile": 1.0}, SIZE),
    (r"size: expected at least 16x16 pixels, found 8x8", [0, 0, 0, 0], (8, 8)),
])
def test_bad_input_is_refused(match: str, weights, size) -> None:
    with pytest.raises(ValueError, match=match):
        render_face(weights, size)


def test_grid_of_faces_can_be_written_for_a_look(tmp_path) -> None:
    """The 4 x 4 grid used to check by eye that each blendshape reads at a glance."""
    import cv2

    rows = [np.hstack([render_face({n: v}, (160, 120)) for v in (0, 0.33, 0.66, 1.0)])
            for n in ("mouth_stretch", "mouth_open", "eye_squint", "brow_lower")]
    path = tmp_path / "faces.png"
    assert cv2.imwrite(str(path), np.vstack(rows))
    assert cv2.imread(str(path)).shape == (480, 640, 3)
