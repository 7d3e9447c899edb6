"""model.json's ``output_filter`` and ``rest_anchor`` sections are bounds-checked where they are read
(issue 37): a 400-digit integer, a time constant of 1e300 s or ``rest_anchor.at_rest = -1e300`` (which
mapped every output to weight 1.0, exit 0) are one line naming model.json and the field, exit 2,
nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from effortface.cli import main
from effortface.core.errors import UserError
from effortface.synth.bundle import read_bundle, write_bundle

ROOT = Path(__file__).resolve().parents[2]
CLIP = ROOT / "tests" / "data" / "motion" / "amp_humanoid_run.npz"
BIG = 10 ** 400


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory, make_bundle) -> Path:
    """A bundle from real fits, with a rest anchor as train writes it."""
    out = tmp_path_factory.mktemp("model") / "m"
    write_bundle(make_bundle(), out)
    doc = json.loads((out / "model.json").read_text())
    doc["rest_anchor"] = {"features": [0, 0, 0, 0], "at_rest": [0.1, 0.05, 0.2, 0.0], "level": [0.0] * 4,
                          "raters_rest_level": [0.02, None, 0.1, 0.0]}
    (out / "model.json").write_text(json.dumps(doc))
    return out


def _spoiled(model: Path, tmp_path: Path, section: str, key: str, index: int, value: object) -> Path:
    out = tmp_path / "spoiled"
    out.mkdir()
    for f in model.iterdir():
        (out / f.name).write_bytes(f.read_bytes())
    doc = json.loads((out / "model.json").read_text())
    doc[section][key][index] = value
    (out / "model.json").write_text(json.dumps(doc))
    return out


def test_the_intact_sections_read(model: Path) -> None:
    bundle = read_bundle(model)
    assert bundle.rest_anchor is not None and bundle.rest_anchor.at_rest == (0.1, 0.05, 0.2, 0.0)
    assert bundle.filter_tau_s == (0.15,) * 4


@pytest.mark.parametrize("section, key, index, value, message", [
    ("output_filter", "time_constant_s", 0, BIG, r"output_filter\.time_constant_s\[0\]: expected a number from 0 "
                                                 r"to 3600 s, found 1000000000"),
    ("output_filter", "time_constant_s", 2, 1e300, r"output_filter\.time_constant_s\[2\]: expected a number from 0 "
                                                   r"to 3600 s, found 1e\+300"),
    ("rest_anchor", "at_rest", 0, -1e300, r"rest_anchor\.at_rest\[0\]: expected a number from -1 to 0\.99, "
                                          r"found -1e\+300"),
    ("rest_anchor", "at_rest", 1, -BIG, r"rest_anchor\.at_rest\[1\]: expected a number from -1 to 0\.99, found -1000"),
    ("rest_anchor", "level", 3, "0", r"rest_anchor\.level\[3\]: expected a number from 0 to 0\.99, found '0'"),
    ("rest_anchor", "raters_rest_level", 0, BIG, r"rest_anchor\.raters_rest_level\[0\]: expected a number"),
], ids=["tau-400-digits", "tau-1e300", "at_rest-minus-1e300", "at_rest-400-digits", "level-string",
        "raters-400-digits"])
def test_a_section_value_out_of_bounds_is_one_line(model: Path, tmp_path: Path, section: str, key: str, index: int,
                                                   value: object, message: str) -> None:
    spoiled = _spoiled(model, tmp_path, section, key, index, value)
    with pytest.raises(UserError, match=r"spoiled/model\.json\." + message) as caught:
        read_bundle(spoiled)
    assert "\n" not in str(caught.value)


def test_synth_refuses_an_anchor_at_minus_1e300_and_writes_nothing(model: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    spoiled = _spoiled(model, tmp_path, "rest_anchor", "at_rest", 0, -1e300)
    out = tmp_path / "curves.csv"
    assert main(["synth", str(spoiled), str(CLIP), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "rest_anchor.at_rest[0]: expected a number from -1 to 0.99, found -1e+300" in err and err.count("\n") == 1
    assert not out.exists()
