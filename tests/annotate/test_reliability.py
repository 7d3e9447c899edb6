"""The pose set, the long-format ratings and the paper's mean-disagreement figure."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from effortface.annotate.reliability import (
    Pose,
    Rating,
    mean_abs_disagreement_pct,
    read_poses,
    read_ratings,
    write_poses,
    write_ratings,
)
from effortface.core.errors import SessionFormatError


def test_disagreement_by_hand() -> None:
    # pose a, mouth_open: 0.2, 0.4, 0.5 -> pairs 0.2, 0.3, 0.1 -> 0.2
    # pose a, eye_squint: 0.0, 0.0, 0.6 -> pairs 0, 0.6, 0.6 -> 0.4
    ratings = [Rating("a", r, "mouth_open", w) for r, w in zip("XYZ", (0.2, 0.4, 0.5))]
    ratings += [Rating("a", r, "eye_squint", w) for r, w in zip("XYZ", (0.0, 0.0, 0.6))]
    assert mean_abs_disagreement_pct(ratings) == pytest.approx(30.0)


def test_disagreement_extremes_and_single_raters() -> None:
    same = [Rating("p", r, "b", 0.37) for r in "XYZ"]
    assert mean_abs_disagreement_pct(same) == 0.0
    assert mean_abs_disagreement_pct([Rating("p", "X", "b", 0.0), Rating("p", "Y", "b", 1.0)]) == 100.0
    # an item rated once carries no disagreement and does not dilute the mean
    assert mean_abs_disagreement_pct(same + [Rating("q", "X", "b", 0.9)]) == 0.0
    with pytest.raises(ValueError, match="at least one pose and blendshape rated by two raters"):
        mean_abs_disagreement_pct([Rating("q", "X", "b", 0.9)])


def test_disagreement_matches_a_numpy_computation() -> None:
    rng = np.random.default_rng(3)
    w = rng.random((18, 3, 4))  # poses x raters x blendshapes
    ratings = [Rating(f"p{i}", f"R{r}", f"b{b}", float(w[i, r, b]))
               for i in range(18) for r in range(3) for b in range(4)]
    pairs = [np.abs(w[:, a] - w[:, c]) for a, c in itertools.combinations(range(3), 2)]
    assert mean_abs_disagreement_pct(ratings) == pytest.approx(100 * np.mean(pairs))


def test_poses_and_ratings_round_trip(tmp_path) -> None:
    poses = [Pose("pose01", "P01_20260112-093000_cardio", 120, 15.0312), Pose("pose02", "P02_20260112-113700_strength", 7, 0.9)]
    ratings = [Rating("pose01", "R1", "mouth_open", 0.25), Rating("pose01", "R2", "mouth_open", 0.3)]
    assert read_poses(write_poses(tmp_path / "poses.csv", poses)) == poses
    assert read_ratings(write_ratings(tmp_path / "ratings.csv", ratings)) == ratings
    assert (tmp_path / "ratings.csv").read_text().splitlines()[0] == "pose_id,rater,blendshape,weight"


def test_writers_refuse_to_overwrite(tmp_path) -> None:
    write_poses(tmp_path / "poses.csv", [])
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_poses(tmp_path / "poses.csv", [])
    write_ratings(tmp_path / "r.csv", [])
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_ratings(tmp_path / "r.csv", [])
    write_ratings(tmp_path / "r.csv", [Rating("p", "R1", "b", 0.5)], overwrite=True)
    assert len(read_ratings(tmp_path / "r.csv")) == 1


@pytest.mark.parametrize("match, text", [
    (r"expected columns pose_id,rater,blendshape,weight, found pose,rater", "pose,rater\np,R1\n"),
    (r":2: expected a weight in \[0, 1\], found '1.5'", "pose_id,rater,blendshape,weight\np,R1,b,1.5\n"),
    (r":2: expected a weight in \[0, 1\], found 'high'", "pose_id,rater,blendshape,weight\np,R1,b,high\n"),
    (r":3: expected one non-empty pose_id,rater,blendshape",
     "pose_id,rater,blendshape,weight\np,R1,b,0.1\np,R1,b,0.2\n"),
])
def test_bad_ratings_name_the_file_and_line(tmp_path, match: str, text: str) -> None:
    path = tmp_path / "ratings.csv"
    path.write_text(text)
    with pytest.raises(SessionFormatError, match=match) as err:
        read_ratings(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("match, text", [
    (r"expected columns pose_id,session_id,frame,t_s", "pose_id,frame\n"),
    (r":2: expected pose_id,session_id,<int frame>,<float t_s>", "pose_id,session_id,frame,t_s\np,S,1.5,2\n"),
    (r":3: expected a unique pose_id", "pose_id,session_id,frame,t_s\np,S,1,2\np,S,2,3\n"),
    (r":2: expected a unique pose_id and frame >= 0", "pose_id,session_id,frame,t_s\np,S,-1,2\n"),
])
def test_bad_poses_name_the_file_and_line(tmp_path, match: str, text: str) -> None:
    path = tmp_path / "poses.csv"
    path.write_text(text)
    with pytest.raises(SessionFormatError, match=match):
        read_poses(path)


def test_unreadable_file_is_named(tmp_path) -> None:
    with pytest.raises(SessionFormatError, match="missing.csv"):
        read_ratings(tmp_path / "missing.csv")
