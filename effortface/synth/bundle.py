"""The model bundle (DESIGN.md "Model bundle"): ``model.json`` + ``svr.npz``, never a pickle.

``model.json`` holds everything small and readable: schema version, the blendshape set with its
ARKit mapping, feature names and units, the scaler, the NHR coefficients and their training-level
regressions, the physiology choices, per-blendshape SVR hyper-parameters (gamma as a number),
the output filter's time constants (optional: older bundles get the default), metrics and provenance. ``svr.npz`` holds the arrays: ``support_vectors_<b>``, ``dual_coef_<b>``
for each blendshape name ``b``, and ``intercept`` (B,). It is read with ``allow_pickle=False``.

The training stage adds ``face.onnx`` and ``MODEL_CARD.md`` beside them with its own code;
:func:`read_bundle` ignores other files. numpy only (the runtime imports this module).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core import bounds
from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write, atomic_write_text, read_json
from effortface.synth.npzio import load_npz
from effortface.synth.face import (DEFAULT_FILTER_TAU_S, FEATURE_NAMES, FEATURE_UNITS, RestAnchor, SvrModel,
                                   check_filter_tau)
from effortface.synth.physiology import HR_MAX_FORMULAS, EpocParams, NhrParams, NhrRegression

SCHEMA_VERSION = 1
MODEL_JSON = "model.json"
SVR_NPZ = "svr.npz"

#: Training levels at which the NHR TL regression is checked (the runtime's accepted range, 0-10;
#: the lines are linear, so checking both ends checks the whole range).
TL_CHECK_RANGE = (0.0, 10.0)
#: Largest accepted magnitude of an NHR coefficient or TL-regression value (choice): far above any
#: fit (the paper: t_root 7-12 W/kg, rates below 0.01 per W/kg per s; odd small data sets give
#: hundreds) and far enough from float overflow for the recursion (1e308 overflowed it).
NHR_MAX_ABS = bounds.BOUNDS["nhr_coefficient"].high


#: The output filter on the blendshape weights (effortface.synth.face.WeightFilter).
OUTPUT_FILTER_KIND = "critically_damped"


class BundleFormatError(UserError):
    """A model bundle folder or one of its files does not follow the bundle format."""


@dataclasses.dataclass
class ModelBundle:
    """A trained model, as exported by the training stage.

    Attributes
    ----------
    blendshapes : BlendshapeSet
        Output blendshapes in order, with their ARKit names.
    scaler_mean, scaler_scale : ndarray, shape (4,)
        Feature standardisation for [w_per_kg, p_per_kg, nhr, epoc_norm].
    nhr_coefficients : NhrParams
        Pooled NHR coefficients (t_root, c_inc, c_dec), for reference.
    nhr_regression : NhrRegression
        (intercept, slope) of t_root, c_inc and c_dec against training level: what the runtime uses.
    svr_hyperparameters : list of dict
        Per blendshape ``{"C", "gamma", "epsilon"}``; gamma is a number.
    support_vectors, dual_coef : list of ndarray
        Per blendshape, shapes (S_b, 4) and (S_b,).
    intercept : ndarray, shape (B,)
        SVR intercepts.
    physiology : dict
        Choices: ``hr_max_formula``, ``update_period_s``, ``epoc`` {k_up, tau_s, threshold,
        scale_ml_per_kg}.
    metrics, provenance : dict
        Free-form JSON (scores like the paper's; data, software and date of the fit).
    filter_tau_s : tuple of float
        Output-filter time constant per blendshape, seconds (``model.json`` ``output_filter``;
        a bundle without it gets :data:`~effortface.synth.face.DEFAULT_FILTER_TAU_S`).
    rest_anchor : RestAnchor or None
        The map that puts the SVR's output at rest on a neutral face (``model.json``
        ``rest_anchor``; applied by the runtime, not by face.onnx). None for a bundle written before
        it existed: its outputs are used unchanged.
    """

    blendshapes: BlendshapeSet
    scaler_mean: np.ndarray
    scaler_scale: np.ndarray
    nhr_coefficients: NhrParams
    nhr_regression: NhrRegression
    svr_hyperparameters: list[dict[str, float]]
    support_vectors: list[np.ndarray]
    dual_coef: list[np.ndarray]
    intercept: np.ndarray
    physiology: dict[str, Any] = dataclasses.field(default_factory=lambda: default_physiology())
    metrics: dict[str, Any] = dataclasses.field(default_factory=dict)
    provenance: dict[str, Any] = dataclasses.field(default_factory=dict)
    schema_version: int = SCHEMA_VERSION
    feature_names: tuple[str, ...] = FEATURE_NAMES
    feature_units: tuple[str, ...] = FEATURE_UNITS
    filter_tau_s: tuple[float, ...] | None = None
    rest_anchor: RestAnchor | None = None

    def __post_init__(self) -> None:
        if self.filter_tau_s is None:
            self.filter_tau_s = (DEFAULT_FILTER_TAU_S,) * len(self.blendshapes)

    def face_model(self) -> SvrModel:
        """The numpy SVR face model of this bundle."""
        gammas = [h["gamma"] for h in self.svr_hyperparameters]
        return SvrModel(self.support_vectors, self.dual_coef, self.intercept, gammas,
                        self.scaler_mean, self.scaler_scale)

    def epoc_params(self) -> EpocParams:
        """The EPOC recursion constants recorded in the bundle."""
        return EpocParams(**self.physiology["epoc"])


def default_physiology() -> dict[str, Any]:
    """The physiology choices of SCIENCE.md (Tanaka HR_max, 1 s updates, default EPOC)."""
    return {"hr_max_formula": "tanaka", "update_period_s": 1.0,
            "epoc": dataclasses.asdict(EpocParams())}


# --------------------------------------------------------------------------- writing

def _to_json(bundle: ModelBundle) -> dict[str, Any]:
    reg = bundle.nhr_regression
    return {
        "schema_version": bundle.schema_version,
        "blendshapes": bundle.blendshapes.to_dict(),
        "features": [{"name": n, "unit": u} for n, u in zip(bundle.feature_names,
                                                             bundle.feature_units)],
        "scaler": {"mean": np.asarray(bundle.scaler_mean, float).tolist(),
                   "scale": np.asarray(bundle.scaler_scale, float).tolist()},
        "nhr": {"coefficients": {k: float(getattr(bundle.nhr_coefficients, k))
                                 for k in ("t_root", "c_inc", "c_dec")},
                "tl_regression": {k: {"intercept": float(getattr(reg, k)[0]),
                                      "slope": float(getattr(reg, k)[1])}
                                  for k in ("t_root", "c_inc", "c_dec")}},
        "physiology": bundle.physiology,
        "svr": [dict(h, blendshape=n, n_support=int(len(a)))
                for n, h, a in zip(bundle.blendshapes.names, bundle.svr_hyperparameters,
                                   bundle.dual_coef)],
        "output_filter": {"kind": OUTPUT_FILTER_KIND,
                          "time_constant_s": [float(v) for v in bundle.filter_tau_s or ()]},
        **({"rest_anchor": bundle.rest_anchor.to_dict()} if bundle.rest_anchor is not None else {}),
        "metrics": bundle.metrics,
        "provenance": bundle.provenance,
    }


def write_bundle(bundle: ModelBundle, directory: str | os.PathLike[str], *,
                 overwrite: bool = False) -> Path:
    """Write ``model.json`` and ``svr.npz`` into ``directory``.

    Parameters
    ----------
    bundle : ModelBundle
        The model.
    directory : path
        Target folder (created if needed).
    overwrite : bool
        Replace model.json and svr.npz in an existing non-empty folder (other files are kept).

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    FileExistsError
        If the folder exists and is not empty and ``overwrite`` is False.
    """
    directory = Path(directory)
    if directory.is_dir() and any(directory.iterdir()) and not overwrite:
        raise FileExistsError(f"{directory}: model folder exists and is not empty "
                              "(pass overwrite=True to replace it)")
    directory.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_to_json(bundle), indent=2, allow_nan=False)
    atomic_write_text(directory / MODEL_JSON, text)
    arrays = {"intercept": np.asarray(bundle.intercept, float)}
    for name, sv, coef in zip(bundle.blendshapes.names, bundle.support_vectors, bundle.dual_coef):
        arrays[f"support_vectors_{name}"] = np.asarray(sv, float)
        arrays[f"dual_coef_{name}"] = np.asarray(coef, float).ravel()
    # np.savez's stubs want a path or a seekable writer; atomic_write's binary file is one
    atomic_write(directory / SVR_NPZ, lambda f: np.savez(f, **arrays))  # type: ignore[arg-type]  # see above
    return directory


# --------------------------------------------------------------------------- reading

def _get(d: Mapping[str, Any], key: str, where: str, kind: type | tuple[type, ...]) -> Any:
    if not isinstance(d, Mapping) or key not in d:
        raise BundleFormatError(f"{where}: expected field '{key}', found it missing")
    if not isinstance(d[key], kind):
        raise BundleFormatError(f"{where}.{key}: expected {_kind_name(kind)}, "
                                f"found {type(d[key]).__name__} {d[key]!r:.60}")
    return d[key]


def _kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return " or ".join(k.__name__ for k in kinds)


def _number(d: Mapping[str, Any], key: str, where: str, *, positive: bool = False) -> float:
    value = _get(d, key, where, (int, float))
    try:
        number = float(value)
    except OverflowError:  # a JSON integer beyond float range
        number = float("inf")
    if isinstance(value, bool) or not np.isfinite(number) or (positive and number <= 0):
        raise BundleFormatError(f"{where}.{key}: expected a {'positive ' if positive else ''}"
                                f"finite number, found {value!r:.40}")
    return number


def _vector(d: Mapping[str, Any], key: str, where: str, n: int, bound: str) -> np.ndarray:
    values = _get(d, key, where, list)
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError, OverflowError):  # Overflow: an integer beyond float range
        arr = np.empty(0)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise BundleFormatError(f"{where}.{key}: expected {n} finite numbers, found {values!r:.80}")
    for i, value in enumerate(arr):
        try:
            bounds.check(bound, float(value), f"{where}.{key}[{i}]")
        except UserError as exc:
            raise BundleFormatError(str(exc)) from None
    return arr


def _read_json(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise BundleFormatError(f"{path}: expected a model file, found none "
                                "(give a model folder or 'default')")
    doc = read_json(path, "JSON (model.json)", BundleFormatError)
    if not isinstance(doc, dict):
        raise BundleFormatError(f"{path}: expected a JSON object, found {type(doc).__name__}")
    version = _get(doc, "schema_version", str(path), int)
    if isinstance(version, bool) or version != SCHEMA_VERSION:  # True == 1 in Python, not in JSON
        raise BundleFormatError(f"{path}: schema_version: expected {SCHEMA_VERSION}, found {version!r}")
    return doc


def _read_blendshapes(doc: dict[str, Any], where: str) -> BlendshapeSet:
    """The blendshape set: each entry ``{name: str, drives: str, arkit: [str, ...]}``, unique names."""
    items = _get(doc, "blendshapes", where, list)
    for i, item in enumerate(items):
        _check_blendshape(item, f"{where}.blendshapes[{i}]")
    shapes = BlendshapeSet.from_dict(items)
    if not shapes.names or len(set(shapes.names)) != len(shapes.names):
        raise BundleFormatError(f"{where}.blendshapes: expected unique names, found {shapes.names}")
    return shapes


def _check_blendshape(item: Any, where: str) -> None:
    """Raise naming ``where`` unless ``item`` is one well-typed blendshape entry."""
    if not isinstance(item, dict):
        raise BundleFormatError(f"{where}: expected an object {{name, drives, arkit}}, "
                                f"found {type(item).__name__} {item!r:.60}")
    name = _get(item, "name", where, str)
    if not name:
        raise BundleFormatError(f"{where}.name: expected a non-empty name, found ''")
    if "drives" in item:
        _get(item, "drives", where, str)
    arkit = _get(item, "arkit", where, list) if "arkit" in item else []
    bad = [a for a in arkit if not isinstance(a, str) or not a]
    if bad:
        raise BundleFormatError(f"{where}.arkit: expected ARKit blendshape names (strings), "
                                f"found {bad[0]!r:.60}")


def _read_features(doc: dict[str, Any], where: str) -> None:
    feats = _get(doc, "features", where, list)
    names = tuple(f.get("name") if isinstance(f, dict) else f for f in feats)
    if names != FEATURE_NAMES:
        raise BundleFormatError(f"{where}.features: expected {list(FEATURE_NAMES)}, "
                                f"found {list(names)}")


def _read_nhr(doc: dict[str, Any], where: str) -> tuple[NhrParams, NhrRegression]:
    nhr = _get(doc, "nhr", where, dict)
    coef = _get(nhr, "coefficients", f"{where}.nhr", dict)
    reg = _get(nhr, "tl_regression", f"{where}.nhr", dict)
    keys = ("t_root", "c_inc", "c_dec")
    t_root, c_inc, c_dec = (_nhr_value(_number(coef, k, f"{where}.nhr.coefficients"),
                                       f"{where}.nhr.coefficients.{k}") for k in keys)
    params = NhrParams(t_root, c_inc, c_dec)
    lines = [_get(reg, k, f"{where}.nhr.tl_regression", dict) for k in keys]
    pairs = [(_number(d, "intercept", f"{where}.nhr.tl_regression.{k}"),
              _number(d, "slope", f"{where}.nhr.tl_regression.{k}")) for k, d in zip(keys, lines)]
    for k, (a, b) in zip(keys, pairs):
        for tl in TL_CHECK_RANGE:
            _nhr_value(a + b * tl, f"{where}.nhr.tl_regression.{k}", f" at training level {tl:g}",
                       signed=True)
    return params, NhrRegression(pairs[0], pairs[1], pairs[2])


def _nhr_value(value: float, where: str, at: str = "", *, signed: bool = False) -> float:
    """``value`` if it is in (0, NHR_MAX_ABS], else raise naming ``where`` (SCIENCE.md 3).

    The pooled t_root, c_inc and c_dec are positive by their meaning. With ``signed`` (the TL
    regression lines) only the magnitude is bounded: fitted lines extrapolate below 0 at training
    levels beyond the participants' (seen on real fits for t_root and c_inc at TL 10).
    """
    if not (abs(value) <= NHR_MAX_ABS if signed else 0.0 < value <= NHR_MAX_ABS):
        expected = (f"a value from {-NHR_MAX_ABS:g} to {NHR_MAX_ABS:g}" if signed
                    else f"a value above 0 and at most {NHR_MAX_ABS:g}")
        raise BundleFormatError(f"{where}: expected {expected}{at}, found {value:.6g}")
    return value


def _read_physiology(doc: dict[str, Any], where: str) -> dict[str, Any]:
    phys = _get(doc, "physiology", where, dict)
    formula = _get(phys, "hr_max_formula", f"{where}.physiology", str)
    if formula not in HR_MAX_FORMULAS:
        raise BundleFormatError(f"{where}.physiology.hr_max_formula: expected one of "
                                f"{', '.join(HR_MAX_FORMULAS)}, found {formula!r}")
    period = _bounded(phys, "update_period_s", f"{where}.physiology")
    epoc = _get(phys, "epoc", f"{where}.physiology", dict)
    fields = [f.name for f in dataclasses.fields(EpocParams)]
    epoc_vals = {k: _number(epoc, k, f"{where}.physiology.epoc") if k == "threshold"
                 else _bounded(epoc, k, f"{where}.physiology.epoc") for k in fields}
    if not 0.0 <= epoc_vals["threshold"] < 1.0:
        raise BundleFormatError(f"{where}.physiology.epoc.threshold: expected a fraction of VO2max from 0 "
                                f"to below 1, found {epoc_vals['threshold']:g}")
    return {"hr_max_formula": formula, "update_period_s": period, "epoc": epoc_vals}


def _read_rest_anchor(doc: dict[str, Any], where: str, n: int) -> RestAnchor | None:
    """The rest anchor; None for a bundle written before it existed (outputs used unchanged)."""
    if "rest_anchor" not in doc:
        return None
    try:
        return RestAnchor.from_dict(_get(doc, "rest_anchor", where, dict), n, where)
    except UserError as exc:
        raise BundleFormatError(str(exc)) from None


def _read_output_filter(doc: dict[str, Any], where: str, n: int) -> tuple[float, ...]:
    """The output filter's time constants; a bundle written before the filter existed gets the default."""
    if "output_filter" not in doc:
        return (DEFAULT_FILTER_TAU_S,) * n
    spec = _get(doc, "output_filter", where, dict)
    kind = _get(spec, "kind", f"{where}.output_filter", str)
    if kind != OUTPUT_FILTER_KIND:
        raise BundleFormatError(f"{where}.output_filter.kind: expected {OUTPUT_FILTER_KIND!r}, found {kind!r}")
    taus = _get(spec, "time_constant_s", f"{where}.output_filter", list)
    if len(taus) != n or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in taus):
        raise BundleFormatError(f"{where}.output_filter.time_constant_s: expected {n} numbers (one per "
                                f"blendshape), found {taus!r}")
    try:
        return tuple(float(v) for v in check_filter_tau(taus, n, f"{where}.output_filter.time_constant_s"))
    except UserError as exc:
        raise BundleFormatError(str(exc)) from None


def _read_svr_json(doc: dict[str, Any], where: str, names: tuple[str, ...]) -> list[dict[str, float]]:
    items = _get(doc, "svr", where, list)
    if [d.get("blendshape") if isinstance(d, dict) else None for d in items] != list(names):
        raise BundleFormatError(f"{where}.svr: expected one entry per blendshape {list(names)}, "
                                f"found {len(items)} entries")
    return [{k: _bounded(d, k, f"{where}.svr[{i}]") for k in ("C", "gamma", "epsilon")}
            for i, d in enumerate(items)]


def _bounded(d: Mapping[str, Any], key: str, where: str, name: str = "") -> float:
    """A number of the model file checked against the bounds table (effortface.core.bounds)."""
    try:
        return bounds.check(name or key, _number(d, key, where, positive=True), f"{where}.{key}")
    except UserError as exc:
        raise BundleFormatError(str(exc)) from None


def _read_npz(path: Path, names: tuple[str, ...]
              ) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """The SVR arrays of ``svr.npz``: support vectors (n_b, 4), dual coefs (n_b,), intercept (B,)."""
    if not path.is_file():
        raise BundleFormatError(f"{path}: expected the SVR arrays file, found none")
    arrays = load_npz(path, BundleFormatError, "a numpy .npz without pickles")
    wanted = ["intercept"] + [f"{p}_{n}" for n in names for p in ("support_vectors", "dual_coef")]
    missing = [k for k in wanted if k not in arrays]
    if missing:
        raise BundleFormatError(f"{path}: expected arrays {', '.join(missing)}, found "
                                f"{', '.join(sorted(arrays)) or 'none'}")
    bad = [k for k in wanted if arrays[k].dtype.kind not in "fi" or not np.all(np.isfinite(arrays[k]))]
    if bad:
        raise BundleFormatError(f"{path}: {bad[0]}: expected finite numbers, found dtype "
                                f"{arrays[bad[0]].dtype}")
    limit = bounds.BOUNDS["svr_value"]
    huge = [k for k in wanted if arrays[k].size and np.abs(arrays[k]).max() > limit.high]
    if huge:
        raise BundleFormatError(f"{path}: {huge[0]}: expected values within +-{limit.high:g}, found "
                                f"{np.abs(arrays[huge[0]]).max():g}")
    _check_svr_shapes(path, arrays, names)
    return ([arrays[f"support_vectors_{n}"].astype(float) for n in names],
            [arrays[f"dual_coef_{n}"].astype(float) for n in names], arrays["intercept"].astype(float))


def _check_svr_shapes(path: Path, arrays: Mapping[str, np.ndarray], names: tuple[str, ...]) -> None:
    """Raise naming the file and array unless the SVR array shapes agree with each other."""
    n_features = len(FEATURE_NAMES)
    if arrays["intercept"].shape != (len(names),):
        raise BundleFormatError(f"{path}: intercept: expected shape ({len(names)},) (one per "
                                f"blendshape), found {arrays['intercept'].shape}")
    for n in names:
        sv, coef = arrays[f"support_vectors_{n}"], arrays[f"dual_coef_{n}"]
        if sv.ndim != 2 or sv.shape[1] != n_features:
            raise BundleFormatError(f"{path}: support_vectors_{n}: expected shape (n, {n_features}), "
                                    f"found {sv.shape}")
        if coef.shape != (sv.shape[0],):
            raise BundleFormatError(f"{path}: dual_coef_{n}: expected shape ({sv.shape[0]},) (one per "
                                    f"support vector), found {coef.shape}")


def read_bundle(directory: str | os.PathLike[str]) -> ModelBundle:
    """Read and validate a model bundle folder.

    Parameters
    ----------
    directory : path
        A folder with ``model.json`` and ``svr.npz`` (other files are ignored).

    Returns
    -------
    ModelBundle
        The model; its arrays are checked against each other.

    Raises
    ------
    BundleFormatError
        A :class:`UserError` naming the file and the field that is missing or wrong.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise BundleFormatError(f"{directory}: expected a model folder (model.json, svr.npz) or "
                                "'default', found no such folder")
    json_path = directory / MODEL_JSON
    doc = _read_json(json_path)
    where = str(json_path)
    shapes = _read_blendshapes(doc, where)
    _read_features(doc, where)
    scaler = _get(doc, "scaler", where, dict)
    nhr_coef, nhr_reg = _read_nhr(doc, where)
    bundle = ModelBundle(
        blendshapes=shapes, scaler_mean=_vector(scaler, "mean", f"{where}.scaler", 4, "scaler_mean"),
        scaler_scale=_vector(scaler, "scale", f"{where}.scaler", 4, "scaler_scale"),
        nhr_coefficients=nhr_coef, nhr_regression=nhr_reg,
        svr_hyperparameters=_read_svr_json(doc, where, shapes.names),
        support_vectors=[], dual_coef=[], intercept=np.empty(0),
        physiology=_read_physiology(doc, where),
        metrics=_get(doc, "metrics", where, dict), provenance=_get(doc, "provenance", where, dict),
        filter_tau_s=_read_output_filter(doc, where, len(shapes)),
        rest_anchor=_read_rest_anchor(doc, where, len(shapes)))
    bundle.support_vectors, bundle.dual_coef, bundle.intercept = _read_npz(directory / SVR_NPZ,
                                                                           shapes.names)
    try:
        bundle.face_model()
    except UserError as exc:
        raise BundleFormatError(f"{directory / SVR_NPZ}: {exc}") from None
    return bundle
