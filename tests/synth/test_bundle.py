"""Model bundle: write -> read round trip, refusal to overwrite, and a table of bad bundles."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from effortface.core.blendshapes import DEFAULT_SET
from effortface.core.errors import UserError
from effortface.synth.bundle import BundleFormatError, read_bundle, write_bundle
from effortface.synth.face import DEFAULT_FILTER_TAU_S
from effortface.synth.physiology import NhrParams, NhrRegression




def test_round_trip(tmp_path: Path, make_bundle) -> None:
    bundle = make_bundle()
    write_bundle(bundle, tmp_path / "m")
    back = read_bundle(tmp_path / "m")
    assert back.blendshapes == DEFAULT_SET
    assert back.nhr_regression == NhrRegression()
    assert back.nhr_coefficients == NhrParams(8.0, 0.004, 0.001)
    assert back.metrics == {"r_mean": 0.8} and back.provenance == {"data": "random"}
    assert back.physiology == bundle.physiology
    x = np.random.default_rng(1).uniform(0, 1, (50, 4)) * [20, 30, 1, 1]
    np.testing.assert_array_equal(back.face_model().predict(x), bundle.face_model().predict(x))
    doc = json.loads((tmp_path / "m" / "model.json").read_text())
    assert [f["name"] for f in doc["features"]] == ["w_per_kg", "p_per_kg", "nhr", "epoc_norm"]
    assert doc["blendshapes"][1]["arkit"] == ["jawOpen"]
    assert doc["svr"][0]["gamma"] == 0.5


def test_refuses_to_overwrite_but_tolerates_extra_files(tmp_path: Path, make_bundle) -> None:
    folder = write_bundle(make_bundle(), tmp_path / "m")
    (folder / "face.onnx").write_bytes(b"onnx")
    (folder / "MODEL_CARD.md").write_text("# card\n")
    read_bundle(folder)  # extra files are ignored
    with pytest.raises(FileExistsError, match="not empty"):
        write_bundle(make_bundle(1), folder)
    write_bundle(make_bundle(1), folder, overwrite=True)
    assert (folder / "face.onnx").read_bytes() == b"onnx"
    assert not list(folder.glob("*.tmp"))


def _edit_json(folder: Path, edit) -> None:
    doc = json.loads((folder / "model.json").read_text())
    edit(doc)
    (folder / "model.json").write_text(json.dumps(doc))


def _edit_npz(folder: Path, edit) -> None:
    with np.load(folder / "svr.npz") as npz:
        arrays = dict(npz)
    edit(arrays)
    np.savez(folder / "svr.npz", **arrays)


BAD = {
    r"model.json: expected a model file, found none":
        lambda f: (f / "model.json").unlink(),
    r"model.json: expected JSON":
        lambda f: (f / "model.json").write_text("{not json"),
    r"model.json: schema_version: expected 1, found 7":
        lambda f: _edit_json(f, lambda d: d.update(schema_version=7)),
    r"model.json.features: expected \['w_per_kg'":
        lambda f: _edit_json(f, lambda d: d["features"].reverse()),
    r"model.json.scaler.mean: expected 4 finite numbers":
        lambda f: _edit_json(f, lambda d: d["scaler"].update(mean=[0, 1])),
    r"model.json.nhr.tl_regression.c_inc: expected field 'slope'":
        lambda f: _edit_json(f, lambda d: d["nhr"]["tl_regression"]["c_inc"].pop("slope")),
    r"model.json.svr\[2\].gamma: expected a positive finite number, found -1":
        lambda f: _edit_json(f, lambda d: d["svr"][2].update(gamma=-1)),
    r"model.json.svr\[0\].gamma: expected int or float, found str 'scale'":
        lambda f: _edit_json(f, lambda d: d["svr"][0].update(gamma="scale")),
    r"model.json.physiology.hr_max_formula: expected one of tanaka":
        lambda f: _edit_json(f, lambda d: d["physiology"].update(hr_max_formula="karvonen")),
    r"model.json.svr: expected one entry per blendshape":
        lambda f: _edit_json(f, lambda d: d["svr"].pop()),
    r"svr.npz: expected the SVR arrays file, found none":
        lambda f: (f / "svr.npz").unlink(),
    r"svr.npz: expected arrays dual_coef_eye_squint":
        lambda f: _edit_npz(f, lambda a: a.pop("dual_coef_eye_squint")),
    r"svr.npz: expected a numpy .npz without pickles":
        lambda f: _edit_npz(f, lambda a: a.update(intercept=np.array([{"x": 1}], dtype=object))),
    r"svr.npz: dual_coef_mouth_open: expected shape \(\d+,\) \(one per support vector\), found \(1,\)":
        lambda f: _edit_npz(f, lambda a: a.update(dual_coef_mouth_open=np.ones(1))),
    r"svr.npz: support_vectors_brow_lower: expected shape \(n, 4\), found \(2, 3\)":
        lambda f: _edit_npz(f, lambda a: a.update(support_vectors_brow_lower=np.ones((2, 3)))),
    # audit (fz/): a name given as a list/object raised TypeError (unhashable) in _read_blendshapes
    r"model.json.blendshapes\[0\].name: expected str, found list":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][0].update(name=["a"])),
    r"model.json.blendshapes\[1\].name: expected str, found dict":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][1].update(name={})),
    r"model.json.blendshapes\[2\]: expected an object \{name, drives, arkit\}, found str":
        lambda f: _edit_json(f, lambda d: d["blendshapes"].__setitem__(2, "eye_squint")),
    r"model.json.blendshapes\[0\].drives: expected str, found list":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][0].update(drives=[])),
    # audit: arkit entries that are null/number/list loaded, then crashed --format livelink
    r"model.json.blendshapes\[0\].arkit: expected ARKit blendshape names \(strings\), found None":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][0]["arkit"].__setitem__(0, None)),
    r"model.json.blendshapes\[1\].arkit: expected ARKit blendshape names \(strings\), found -1":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][1]["arkit"].__setitem__(0, -1)),
    r"model.json.blendshapes\[3\].arkit: expected ARKit blendshape names \(strings\), found \[\]":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][3]["arkit"].append([])),
    r"model.json.blendshapes\[0\].arkit: expected list, found str 'x'":
        lambda f: _edit_json(f, lambda d: d["blendshapes"][0].update(arkit="x")),
    # audit: an empty svr.npz raised EOFError in _read_npz
    r"svr.npz: expected a numpy .npz without pickles, found a file that is neither a zip of arrays nor a \.npy \(it starts with b''\)":
        lambda f: (f / "svr.npz").write_bytes(b""),
    # audit: reshaped arrays were accepted
    r"svr.npz: intercept: expected shape \(4,\) \(one per blendshape\), found \(4, 1\)":
        lambda f: _edit_npz(f, lambda a: a.update(intercept=a["intercept"].reshape(-1, 1))),
    r"svr.npz: dual_coef_eye_squint: expected shape \(\d+,\) \(one per support vector\), found \(\d+, 1\)":
        lambda f: _edit_npz(f, lambda a: a.update(dual_coef_eye_squint=a["dual_coef_eye_squint"][:, None])),
    r"svr.npz: support_vectors_mouth_open: expected shape \(n, 4\), found \(4, \d+\)":
        lambda f: _edit_npz(f, lambda a: a.update(support_vectors_mouth_open=a["support_vectors_mouth_open"].T)),
    # audit: negative or huge NHR coefficients were accepted (SCIENCE.md 3: all three are positive)
    r"model.json.nhr.coefficients.t_root: expected a value above 0 and at most 1e\+06, found -1":
        lambda f: _edit_json(f, lambda d: d["nhr"]["coefficients"].update(t_root=-1)),
    r"model.json.nhr.coefficients.c_inc: expected a value above 0 and at most 1e\+06, found 0":
        lambda f: _edit_json(f, lambda d: d["nhr"]["coefficients"].update(c_inc=0)),
    r"model.json.nhr.coefficients.c_dec: expected a value above 0 and at most 1e\+06, found 1e\+308":
        lambda f: _edit_json(f, lambda d: d["nhr"]["coefficients"].update(c_dec=1e308)),
    r"model.json.nhr.tl_regression.t_root: expected a value from -1e\+06 to 1e\+06 at training level 0, "
    r"found 1e\+308":
        lambda f: _edit_json(f, lambda d: d["nhr"]["tl_regression"]["t_root"].update(intercept=1e308)),
    r"model.json.nhr.tl_regression.t_root: expected a value from -1e\+06 to 1e\+06 at training level 10, found inf":
        lambda f: _edit_json(f, lambda d: d["nhr"]["tl_regression"]["t_root"].update(slope=1e308)),
    r"model.json.nhr.tl_regression.c_dec: expected a value from -1e\+06 to 1e\+06 at training level 10, found inf":
        lambda f: _edit_json(f, lambda d: d["nhr"]["tl_regression"]["c_dec"].update(slope=1e308)),
    r"model.json.physiology.epoc.threshold: expected a fraction of VO2max from 0 to below 1, found 1\.5":
        lambda f: _edit_json(f, lambda d: d["physiology"]["epoc"].update(threshold=1.5)),
    r"model.json.physiology.epoc.tau_s: expected a positive finite number, found 0":
        lambda f: _edit_json(f, lambda d: d["physiology"]["epoc"].update(tau_s=0)),
    r"model.json.output_filter.kind: expected 'critically_damped', found 'one_euro'":
        lambda f: _edit_json(f, lambda d: d["output_filter"].update(kind="one_euro")),
    r"model.json.output_filter.time_constant_s: expected time constants of 0 s or more, found \[0.1, -1, 0.1, 0.1\]":
        lambda f: _edit_json(f, lambda d: d["output_filter"].update(time_constant_s=[0.1, -1, 0.1, 0.1])),
    r"model.json.output_filter.time_constant_s: expected 4 numbers \(one per blendshape\), found \[0.1\]":
        lambda f: _edit_json(f, lambda d: d["output_filter"].update(time_constant_s=[0.1])),
}


def test_output_filter_round_trip_and_old_bundles_get_the_default(tmp_path: Path, make_bundle) -> None:
    bundle = make_bundle()
    bundle.filter_tau_s = (0.1, 0.2, 0.0, 0.3)
    folder = write_bundle(bundle, tmp_path / "m")
    assert read_bundle(folder).filter_tau_s == (0.1, 0.2, 0.0, 0.3)
    doc = json.loads((folder / "model.json").read_text())
    assert doc["output_filter"] == {"kind": "critically_damped", "time_constant_s": [0.1, 0.2, 0.0, 0.3]}
    _edit_json(folder, lambda d: d.pop("output_filter"))  # a bundle written before the filter existed
    assert read_bundle(folder).filter_tau_s == (DEFAULT_FILTER_TAU_S,) * 4


@pytest.mark.parametrize(("message", "corrupt"), BAD.items(), ids=list(BAD))
def test_bad_bundles_name_file_and_field(tmp_path: Path, message: str, corrupt, make_bundle) -> None:
    folder = write_bundle(make_bundle(), tmp_path / "m")
    corrupt(folder)
    with pytest.raises(BundleFormatError, match=message) as info:
        read_bundle(folder)
    assert isinstance(info.value, UserError) and "\n" not in str(info.value)


def test_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(BundleFormatError, match="expected a model folder"):
        read_bundle(tmp_path / "nowhere")
