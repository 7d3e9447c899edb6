"""Export a trained model folder: ``model.json`` + ``svr.npz`` (effortface/synth/bundle.py), ``face.onnx``,
``face_f64.onnx``, ``MODEL_CARD.md``.

- ``face.onnx`` is the engine file: float32, opset 15 (:data:`ONNX_OPSET`), standard operators only
  (:data:`STANDARD_OPS`), so engines without the ``ai.onnx.ml`` domain and limited to float32 and
  opsets 7-15 (Unity Sentis, Unreal NNE) can run it. Input ``features`` (N, 4) = [w_per_kg,
  p_per_kg, nhr, epoc_norm]; output ``normalised_weights`` (N, B), one column per blendshape in the
  bundle's order, before expressiveness and clipping. Its metadata (``metadata_props``) names the
  blendshapes, the feature order and units, and the parity figures (see docs/ENGINE.md).
  ``face_f64.onnx`` is the same graph in float64 (for Python and tools).
- The graph (:func:`face_onnx`): the scaler; the squared distance to every support vector (all
  blendshapes' stacked) from explicit per-feature differences; ``exp(-gamma d)``; each kernel term
  times its dual coefficient; the terms summed per blendshape, then the intercepts. In float32 a
  model with thousands of support vectors and dual coefficients of 10 sums terms whose magnitudes add
  up to thousands into a weight of about 1, so a plain float32 sum loses about 1e-3 (7.5e-4 on an
  earlier sample lab's model). The terms are therefore split first (Rump, Ogita & Oishi 2008, "ExtractScalar"):
  ``hi = (t + M) - M`` rounds each term t to a grid q chosen per blendshape so that every partial sum
  of the ``hi`` parts is exact whatever the summation order, and ``lo = t - hi`` is exact and smaller
  than q / 2, so its float32 sum is nearly exact; the weight is ``sum hi + sum lo``. What remains is
  the rounding of each kernel value (about 3e-5 on that lab's model).
- At export, predictions of scikit-learn, of the numpy runtime loading the written files
  (:class:`effortface.synth.face.SvrModel`) and of onnxruntime are compared on the training features and
  random rows around them (at most :data:`PARITY_MAX_TRAINING_ROWS` training rows, stratified, and
  onnxruntime in chunks: the check's memory does not grow with the table); the export fails (nothing
  is left at the target) if the runtime differs by more than 1e-9 or the float64 graph by more than
  1e-5 (both from scikit-learn). The float32 graph is a separate, stated result: within
  1e-4 of the numpy runtime it is written as ``face.onnx``; over it, the model folder is still
  written without ``face.onnx`` and ``model.json`` ``metrics.engine_export`` and the card give the
  measured error (``effortface train`` then exits 3). The float32 difference is reported in
  ``model.json`` and the graph's metadata.
- The folder is built beside the target and renamed into place, so a failed export never leaves a
  half-written model; an existing target is replaced only with ``force=True``. Never pickle.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import pandas as pd
from onnx import TensorProto, helper, numpy_helper

from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError
from effortface.core.fileio import check_apart, naming
from effortface.core.stops import stops_deferred
from effortface.synth.bundle import ModelBundle, default_physiology, read_bundle, write_bundle
from effortface.synth.face import (FEATURE_NAMES, REST_FEATURES, REST_MAX_NHR, REST_MAX_W_PER_KG, RestAnchor,
                                   rest_anchor)
from effortface.train.face_fit import FaceModelFit
from effortface.train.game_score import MODEL_MEANINGS, headline
from effortface.train.hr_fit import HrModelFit
from effortface.synth.physiology import NhrParams

FACE_ONNX = "face.onnx"
#: the same graph in float64 (the float32 face.onnx is the engine file)
FACE_F64_ONNX = "face_f64.onnx"
MODEL_CARD = "MODEL_CARD.md"
RUNTIME_TOL = 1e-9
ONNX_TOL = 1e-5
#: bound of the float32 face.onnx against the numpy runtime (issue 14); the export fails above it
ONNX_TOL_FLOAT32 = 1e-4
#: Unity Sentis runs opsets 7-15; every operator used here is unchanged since opset 13 or earlier
ONNX_OPSET = 15
#: IR version 8 (ONNX 1.10+): loadable by older onnxruntime builds and by engines
ONNX_IR_VERSION = 8
#: every operator the graph may use (a test checks the exported graph against it)
STANDARD_OPS = frozenset({"Sub", "Div", "Split", "Mul", "Add", "Exp", "MatMul"})


class ExportError(UserError):
    """An export failed its checks (parity, operator set); the message names the file and the gap."""


# --------------------------------------------------------------------------- bundle


def build_bundle(face: FaceModelFit, hr: HrModelFit, blendshapes: BlendshapeSet,
                 metrics: Mapping[str, Any], provenance: Mapping[str, Any],
                 physiology: Mapping[str, Any] | None = None) -> ModelBundle:
    """The :class:`~effortface.synth.bundle.ModelBundle` of a fit.

    Parameters
    ----------
    face : FaceModelFit
        The four SVRs and their scaler.
    hr : HrModelFit
        The heart-rate fits; the runtime uses the training-level regression, and the pooled
        coefficients are kept for reference.
    blendshapes : BlendshapeSet
        Output blendshapes (names must match the face fit's, same order).
    metrics, provenance : mapping
        JSON-ready scores and data/software description.
    physiology : mapping, optional
        Physiology choices (default: :func:`effortface.synth.bundle.default_physiology`).

    Returns
    -------
    ModelBundle
    """
    if tuple(blendshapes.names) != tuple(face.blendshapes):
        raise ExportError(f"blendshapes: expected the face fit's {list(face.blendshapes)}, "
                          f"found {list(blendshapes.names)}")
    svrs = [face.svrs[n] for n in face.blendshapes]
    pooled = hr.pooled
    return ModelBundle(
        blendshapes=blendshapes,
        scaler_mean=np.asarray(face.scaler.mean_, float),
        scaler_scale=np.asarray(face.scaler.scale_, float),
        nhr_coefficients=NhrParams(pooled.t_root_w_per_kg, pooled.c_inc, pooled.c_dec),
        nhr_regression=hr.tl_regression.to_nhr_regression(),
        svr_hyperparameters=[{"C": float(s.C), "gamma": float(s.gamma), "epsilon": float(s.epsilon)}
                             for s in svrs],
        support_vectors=[np.asarray(s.support_vectors_, float) for s in svrs],
        dual_coef=[np.asarray(s.dual_coef_, float).ravel() for s in svrs],
        intercept=np.array([float(np.ravel(s.intercept_)[0]) for s in svrs]),
        physiology=dict(physiology or default_physiology()),
        metrics=dict(metrics), provenance=dict(provenance),
        rest_anchor=fit_rest_anchor(face))


def fit_rest_anchor(face: FaceModelFit) -> RestAnchor:
    """The fit's :class:`~effortface.synth.face.RestAnchor`: its output at rest, and the raters'
    median normalised key over the training seconds at rest (below REST_MAX_W_PER_KG and REST_MAX_NHR)."""
    d = face.data
    at_rest = face.predict_norm(np.array([REST_FEATURES]))[0]
    rest = (d.x[:, 0] < REST_MAX_W_PER_KG) & (d.x[:, 2] <= REST_MAX_NHR)
    levels = [float(np.nanmedian(d.y_norm[rest, b])) if np.isfinite(d.y_norm[rest, b]).any() else float("nan")
              for b in range(d.y_norm.shape[1])]
    return rest_anchor(at_rest, levels)


# --------------------------------------------------------------------------- ONNX


def face_onnx(bundle: ModelBundle, dtype: str = "float64") -> onnx.ModelProto:
    """The face SVRs (scaler included) as an ONNX graph of standard operators.

    Parameters
    ----------
    bundle : ModelBundle
        The model.
    dtype : {"float32", "float64"}
        Tensor type of the input, output and constants.

    Returns
    -------
    onnx.ModelProto
        Checked with ``onnx.checker``.
    """
    np_types: dict[str, type[np.floating]] = {"float32": np.float32, "float64": np.float64}
    np_type = np_types[dtype]
    elem = {"float32": TensorProto.FLOAT, "float64": TensorProto.DOUBLE}[dtype]
    inits = [numpy_helper.from_array(np.asarray(v, dtype=np_type), k)
             for k, v in _onnx_constants(bundle, np_type).items()]
    n_b = len(bundle.support_vectors)
    graph = helper.make_graph(
        _onnx_nodes(len(FEATURE_NAMES)), "effortface_face_svr",
        [helper.make_tensor_value_info("features", elem, ["N", len(FEATURE_NAMES)])],
        [helper.make_tensor_value_info("normalised_weights", elem, ["N", n_b])], inits)
    graph.doc_string = (f"inputs [{', '.join(FEATURE_NAMES)}]; outputs normalised weights of "
                        f"[{', '.join(bundle.blendshapes.names)}], multiply by expressiveness and clip")
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", ONNX_OPSET)],
                              producer_name="effortface", ir_version=ONNX_IR_VERSION)
    onnx.helper.set_model_props(model, onnx_metadata(bundle, dtype))
    onnx.checker.check_model(model)
    return model


#: units of the graph's input columns, in FEATURE_NAMES order
FEATURE_UNITS = ("W/kg", "W/kg", "1 (0-1)", "1 (EPOC / 100 ml/kg)")


def onnx_metadata(bundle: ModelBundle, dtype: str) -> dict[str, str]:
    """``metadata_props`` of the graph: what an engine needs to wire it (docs/ENGINE.md).

    Parameters
    ----------
    bundle : ModelBundle
        The model.
    dtype : str
        The graph's tensor type.

    Returns
    -------
    dict of str
        ``effortface.blendshapes``, ``effortface.feature_names``, ``effortface.feature_units`` (JSON
        lists), ``effortface.output``, ``effortface.dtype``, ``effortface.epoc_scale_ml_per_kg``.
    """
    return {
        "effortface.blendshapes": json.dumps(list(bundle.blendshapes.names)),
        "effortface.feature_names": json.dumps(list(FEATURE_NAMES)),
        "effortface.feature_units": json.dumps(list(FEATURE_UNITS)),
        "effortface.output": "normalised_weights (N, B): multiply column b by the character's "
                             "expressiveness[b], then clip to [0, 1]",
        "effortface.dtype": dtype,
        "effortface.epoc_scale_ml_per_kg": repr(float(bundle.physiology["epoc"]["scale_ml_per_kg"])),
        "effortface.state_update": "w, p, nhr and epoc_norm are computed by the caller; see docs/ENGINE.md",
    }


def _onnx_constants(bundle: ModelBundle, np_type: type[np.floating]) -> dict[str, np.ndarray]:
    """The graph's constants for all blendshapes' support vectors stacked (S of them).

    ``mean``, ``scale`` (F,): the scaler; ``sv_<f>`` (S,): column f of the support vectors;
    ``neg_gamma`` (S,): -gamma of each vector's SVR; ``alpha`` (S,): dual coefficients; ``magic``
    (S,): :func:`_split_constants`; ``owner`` (S, B): 1 where a vector belongs to blendshape b;
    ``intercept`` (B,).
    """
    sv = np.concatenate(bundle.support_vectors)                              # (S, F)
    n_b = len(bundle.support_vectors)
    owner = np.repeat(np.arange(n_b), [len(s) for s in bundle.support_vectors])
    gammas = np.array([h["gamma"] for h in bundle.svr_hyperparameters])
    one_hot = np.zeros((len(sv), n_b))
    one_hot[np.arange(len(sv)), owner] = 1.0
    return {"mean": bundle.scaler_mean, "scale": bundle.scaler_scale,
            **{f"sv_{f}": sv[:, f] for f in range(sv.shape[1])},
            "neg_gamma": -gammas[owner], "alpha": np.concatenate(bundle.dual_coef),
            "magic": _split_constants(bundle.dual_coef, np_type)[owner], "owner": one_hot,
            "intercept": bundle.intercept}


def _split_constants(dual_coef: Sequence[np.ndarray], np_type: type[np.floating]) -> np.ndarray:
    """Per blendshape, the constant M = 1.5 * 2**p * q that rounds a term t to the grid q:
    ``(t + M) - M``, p the mantissa bits of ``np_type``.

    q is the smallest power of two with ``sum |alpha| <= 2**(p - 1) * q`` (the sum floored at 1,
    which only makes q finer than needed for tiny coefficients): every term is at most
    |alpha| (kernel values are at most 1), so every partial sum of the rounded terms is a multiple
    of q below ``2**p * q``, exact in ``np_type``.
    """
    bits = np.finfo(np_type).nmant
    sum_abs = np.array([max(float(np.abs(a).sum()), 1.0) for a in dual_coef])
    q = np.exp2(np.ceil(np.log2(sum_abs)) - (bits - 1))
    return 1.5 * np.exp2(bits) * q


def _onnx_nodes(n_features: int) -> list[onnx.NodeProto]:
    """features -> squared distances -> t = alpha exp(-gamma d) -> t split into hi + lo ->
    per-blendshape sums of hi and of lo -> + intercept."""
    node = helper.make_node
    return _distance_nodes(n_features) + [
        node("Mul", ["dist_sq", "neg_gamma"], ["log_k"]),
        node("Exp", ["log_k"], ["kernel"]),
        node("Mul", ["kernel", "alpha"], ["terms"]),
        node("Add", ["terms", "magic"], ["terms_shifted"]),
        node("Sub", ["terms_shifted", "magic"], ["terms_hi"]),   # t rounded to the grid q
        node("Sub", ["terms", "terms_hi"], ["terms_lo"]),        # exact, |lo| <= q / 2
        node("MatMul", ["terms_hi", "owner"], ["sums_hi"]),      # (N, B), exact
        node("MatMul", ["terms_lo", "owner"], ["sums_lo"]),
        node("Add", ["sums_hi", "sums_lo"], ["sums"]),
        node("Add", ["sums", "intercept"], ["normalised_weights"]),
    ]


def _distance_nodes(n_features: int) -> list[onnx.NodeProto]:
    """features -> z (scaler) -> ``dist_sq`` (N, S) = sum over f of (z_f - sv_f)^2.

    Explicit differences: the expanded form ||z||^2 - 2 z.SV + ||SV||^2 rounds at the scale of the
    norms, not of the distance: 1.8e-4 instead of 4e-5 in float32 on the test of a large model.
    """
    node = helper.make_node
    nodes = [node("Sub", ["features", "mean"], ["centred"]), node("Div", ["centred", "scale"], ["z"]),
             node("Split", ["z"], [f"z_{f}" for f in range(n_features)], axis=1)]    # (N, 1) each
    for f in range(n_features):
        nodes += [node("Sub", [f"z_{f}", f"sv_{f}"], [f"diff_{f}"]),                  # (N, S)
                  node("Mul", [f"diff_{f}", f"diff_{f}"], [f"diff_sq_{f}"])]
    partial = "diff_sq_0"
    for f in range(1, n_features):
        partial_next = "dist_sq" if f == n_features - 1 else f"dist_sq_{f}"
        nodes.append(node("Add", [partial, f"diff_sq_{f}"], [partial_next]))
        partial = partial_next
    return nodes


def run_onnx(path: str | os.PathLike, features: np.ndarray) -> np.ndarray:
    """Predictions of an exported ``face.onnx`` by onnxruntime (input cast to the graph's type)."""
    import onnxruntime as ort  # heavy: only when checking

    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    inp = sess.get_inputs()[0]
    dtype = np.float64 if inp.type == "tensor(double)" else np.float32
    features = np.asarray(features, dtype=dtype)
    step = _chunk_rows(path)
    return np.vstack([sess.run(None, {inp.name: features[i:i + step]})[0].astype(float)
                      for i in range(0, max(len(features), 1), step)])


#: elements of one (rows x support vectors) tensor per onnxruntime call: the graph's explicit
#: differences make several such tensors, so the rows per call shrink as the support vectors grow
#: and the memory of a parity check does not grow with the rows (issue 26)
PARITY_CHUNK_ELEMENTS = 2_000_000


def _chunk_rows(path: str | os.PathLike) -> int:
    """Rows per onnxruntime call of a face graph (:data:`PARITY_CHUNK_ELEMENTS` / support vectors)."""
    alpha = [i for i in onnx.load(str(path)).graph.initializer if i.name == "alpha"]
    n_support = int(np.prod(alpha[0].dims)) if alpha else 1
    return max(64, PARITY_CHUNK_ELEMENTS // max(n_support, 1))


# --------------------------------------------------------------------------- parity


#: training rows a parity check takes at most (evenly spaced, so every participant in proportion,
#: plus each feature's extremes); the check's cost and memory do not grow with the table (issue 26)
PARITY_MAX_TRAINING_ROWS = 20_000


def parity_features(face: FaceModelFit, n_random: int = 500, seed: int = 0,
                    max_rows: int = PARITY_MAX_TRAINING_ROWS) -> np.ndarray:
    """Rows to check: the training features (all, or a stratified sample of ``max_rows``) and
    ``n_random`` random rows spread around them.

    The sample is evenly spaced over the training rows (grouped by participant and time, so each
    participant keeps its share) and always holds the rows where a feature is smallest or largest.
    """
    rng = np.random.default_rng(seed)
    x = face.data.x
    if len(x) > max_rows:
        extremes = np.concatenate([x.argmin(0), x.argmax(0)])
        spaced = np.linspace(0, len(x) - 1, max_rows - len(extremes)).round().astype(int)
        x = x[np.unique(np.concatenate([spaced, extremes]))]
    rand = x.mean(0) + rng.normal(0, 1.5, (n_random, x.shape[1])) * x.std(0)
    return np.vstack([x, np.abs(rand)])


def check_parity(face: FaceModelFit, folder: str | os.PathLike, onnx_tol: float | None = None,
                 keep_float32: bool = False) -> dict[str, float]:
    """Compare scikit-learn with the numpy runtime (files as written) and both ONNX graphs.

    Parameters
    ----------
    face : FaceModelFit
        The scikit-learn models.
    folder : path-like
        The written model folder (``svr.npz``, ``face.onnx``, ``face_f64.onnx``).
    onnx_tol : float, optional
        Bound for the float64 graph against scikit-learn (default :data:`ONNX_TOL`).
    keep_float32 : bool
        Measure the float32 graph but do not raise for it (:func:`float32_refusal` judges it).

    Returns
    -------
    dict
        ``runtime_max_abs_diff`` (runtime - scikit-learn), ``onnx_max_abs_diff`` (float64 graph -
        scikit-learn), ``onnx_f32_vs_runtime_max_abs_diff`` (float32 ``face.onnx`` - runtime),
        ``n_rows``.

    Raises
    ------
    ExportError
        If the runtime differs by more than 1e-9, the float64 graph by more than ``onnx_tol`` or
        (unless ``keep_float32``) the float32 graph by more than :data:`ONNX_TOL_FLOAT32`.
    """
    folder = Path(folder)
    x = parity_features(face)
    ref = _in_chunks(face.predict_norm, x)
    runtime = _in_chunks(read_bundle(folder).face_model().predict, x)
    diffs = {"runtime_max_abs_diff": float(np.max(np.abs(runtime - ref))),
             "onnx_max_abs_diff": float(np.max(np.abs(run_onnx(folder / FACE_F64_ONNX, x) - ref))),
             "onnx_f32_vs_runtime_max_abs_diff":
                 float(np.max(np.abs(run_onnx(folder / FACE_ONNX, x) - runtime))),
             "n_rows": int(len(x))}
    checks = ((folder / "svr.npz", "runtime_max_abs_diff", RUNTIME_TOL, "runtime", "scikit-learn"),
              (folder / FACE_F64_ONNX, "onnx_max_abs_diff", ONNX_TOL if onnx_tol is None else onnx_tol,
               "ONNX", "scikit-learn"),
              (folder / FACE_ONNX, "onnx_f32_vs_runtime_max_abs_diff", ONNX_TOL_FLOAT32, "float32 ONNX",
               "the numpy runtime"))
    for path, key, tol, what, against in checks[:2 if keep_float32 else 3]:
        if not diffs[key] <= tol:
            hint = _float32_hint(face) if path.name == FACE_ONNX else ""
            raise ExportError(f"{path}: expected {what} predictions within {tol:g} of {against}, "
                              f"found {diffs[key]:.3g}{hint}")
    return diffs


def _in_chunks(predict: Any, x: np.ndarray, rows: int = 4096) -> np.ndarray:
    """``predict(x)`` over blocks of ``rows`` rows (its (rows x support vectors) kernel stays small)."""
    return np.vstack([predict(x[i:i + rows]) for i in range(0, max(len(x), 1), rows)])


def float32_refusal(face: FaceModelFit, folder: str | os.PathLike, diffs: Mapping[str, float]) -> str | None:
    """Why the float32 ``face.onnx`` is refused (its measured error over :data:`ONNX_TOL_FLOAT32`),
    or None when it is within the bound."""
    found = diffs["onnx_f32_vs_runtime_max_abs_diff"]
    if found <= ONNX_TOL_FLOAT32:
        return None
    return (f"{Path(folder) / FACE_ONNX}: expected float32 ONNX predictions within {ONNX_TOL_FLOAT32:g} of "
            f"the numpy runtime, found {found:.3g}{_float32_hint(face)}")


def _float32_hint(face: FaceModelFit) -> str:
    """Why a float32 graph can miss its bound, and what to do (for the error message)."""
    sum_abs = max(float(np.abs(s.dual_coef_).sum()) for s in face.svrs.values())
    return (f" (each float32 kernel value carries a rounding error of about 1e-7, and this model's dual "
            f"coefficients add up to {sum_abs:.3g} in one weight; train with a smaller C)")


# --------------------------------------------------------------------------- the folder


def export_model(bundle: ModelBundle, face: FaceModelFit, out_dir: str | os.PathLike, *,
                 force: bool = False, card: str | None = None,
                 inputs: Sequence[str | os.PathLike] = ()) -> Path:
    """Write the model folder: bundle, ``face.onnx`` (float32), ``face_f64.onnx``, parity check,
    ``MODEL_CARD.md``.

    Parameters
    ----------
    bundle : ModelBundle
        From :func:`build_bundle`; its ``metrics["export_parity"]`` is filled in.
    face : FaceModelFit
        The scikit-learn models the bundle came from (for the parity check).
    out_dir : path-like
        Target folder.
    force : bool
        Replace an existing target folder.
    card : str, optional
        Model card text; :func:`model_card` of the bundle by default.
    inputs : sequence of path-like
        What the model was trained from: the folder must lie apart from them
        (:func:`check_model_target`).

    Returns
    -------
    Path
        The model folder.

    Raises
    ------
    UserError
        If ``out_dir`` exists and ``force`` is False (checked again just before the rename: a folder
        that appeared during the fit is never replaced), or is not a folder ``force`` may replace.
    OSError
        A write that failed (a full disk...), naming ``out_dir``; nothing is left behind.
    ExportError
        If the runtime or the float64 graph fails its parity check (the target is left untouched).
        A float32 graph over its bound does not raise: the folder is written without ``face.onnx``
        and ``metrics["engine_export"]`` says why (:func:`engine_export_refusal`).
    """
    out = check_model_target(out_dir, force=force, inputs=inputs)  # again: --out may have appeared meanwhile
    with naming(out):  # a full disk names the model folder, not "file system"
        out.parent.mkdir(parents=True, exist_ok=True)
        _build_and_swap(bundle, face, out, force=force, card=card)
    return out


def _build_and_swap(bundle: ModelBundle, face: FaceModelFit, out: Path, *, force: bool,
                    card: str | None) -> None:
    """Build the model folder in a staging folder beside ``out``, then rename it into place."""
    # a fresh private folder (mode 0700, unpredictable name, created by us): a planted file or link
    # at a guessable name can neither redirect the write nor be deleted in our place
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        write_bundle(bundle, tmp)
        onnx.save(face_onnx(bundle, "float64"), str(tmp / FACE_F64_ONNX))
        onnx.save(face_onnx(bundle, "float32"), str(tmp / FACE_ONNX))
        parity = check_parity(face, tmp, keep_float32=True)
        refusal = float32_refusal(face, out, parity)
        bundle.metrics["export_parity"] = {**parity, "onnx_dtype": "float32", "onnx_opset": ONNX_OPSET,
                                           "float32_within_1e-4": refusal is None}
        bundle.metrics[ENGINE_EXPORT] = engine_export_result(parity, refusal)
        if refusal is None:
            _stamp_parity(tmp / FACE_ONNX, parity)
        else:
            (tmp / FACE_ONNX).unlink()  # an engine file outside its bound is not shipped
        write_bundle(bundle, tmp, overwrite=True)  # again, now with the parity figures
        (tmp / MODEL_CARD).write_text(card or model_card(bundle), encoding="utf-8")
        tmp.chmod(0o777 & ~_umask())  # mkdtemp's 0700 was for the build; the model is an ordinary folder
        with stops_deferred():  # a SIGTERM here waits until the old model is removed or restored
            _swap_into_place(tmp, out, force=force)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


#: key of ``model.json`` metrics stating the float32 engine file's outcome (:func:`engine_export_result`)
ENGINE_EXPORT = "engine_export"


def engine_export_result(parity: Mapping[str, float], refusal: str | None) -> dict[str, Any]:
    """The float32 engine export as a stated result: ``file``, ``status`` ("written" or
    "refused"), ``max_abs_diff_vs_runtime``, ``bound`` and ``reason`` (None when written)."""
    return {"file": FACE_ONNX, "status": "written" if refusal is None else "refused",
            "max_abs_diff_vs_runtime": float(parity["onnx_f32_vs_runtime_max_abs_diff"]),
            "bound": ONNX_TOL_FLOAT32, "reason": refusal}


def engine_export_refusal(metrics: Mapping[str, Any]) -> str | None:
    """Why a model folder has no float32 ``face.onnx`` (from its metrics), or None if it has one."""
    result = metrics.get(ENGINE_EXPORT) or {}
    return result.get("reason") if result.get("status") == "refused" else None


def _engine_line(met: Mapping[str, Any]) -> str:
    """The model card's statement of the float32 engine file."""
    result = met.get(ENGINE_EXPORT)
    if not result:
        return "- engine file face.onnx (float32): not stated (model exported before issue 26)"
    if result["status"] == "written":
        return (f"- engine file face.onnx (float32): written, within {result['bound']:g} of the numpy "
                f"runtime (max difference {result['max_abs_diff_vs_runtime']:.3g})")
    return (f"- engine file face.onnx (float32): **refused**, max difference "
            f"{result['max_abs_diff_vs_runtime']:.3g} over the bound {result['bound']:g}; the model "
            f"(model.json, svr.npz, face_f64.onnx) is complete. {result['reason']}")


def _stamp_parity(path: Path, parity: Mapping[str, float]) -> None:
    """Add the measured parity to an ONNX file's metadata (the graph itself is unchanged)."""
    model = onnx.load(str(path))
    props = {p.key: p.value for p in model.metadata_props}
    props["effortface.parity_max_abs_diff_vs_runtime"] = f"{parity['onnx_f32_vs_runtime_max_abs_diff']:.3g}"
    onnx.helper.set_model_props(model, props)
    onnx.save(model, str(path))


def check_model_target(out_dir: str | os.PathLike, *, force: bool = False,
                       inputs: Sequence[str | os.PathLike] = ()) -> Path:
    """Refuse a model-folder target that would lose data; return it as a Path.

    ``force`` replaces only an existing model folder (one holding ``model.json``) or an empty
    folder, never the current directory (or a folder above it), and never a path that is or holds
    one of ``inputs``.

    Parameters
    ----------
    out_dir : path-like
        The ``--out`` target.
    force : bool
        True when the user asked to replace an existing target.
    inputs : sequence of path-like
        The training inputs (session folders, folders of sessions, the table).

    Returns
    -------
    Path
        ``out_dir`` as a Path.

    Raises
    ------
    UserError
        One line naming ``--out``, what was expected and what was found.
    """
    out = Path(out_dir)
    target = out.resolve()
    cwd = Path.cwd().resolve()
    if target == cwd or target in cwd.parents:
        raise UserError(f"--out {out}: expected a model folder to write, found the current directory"
                        + ("" if target == cwd else " inside it"))
    check_apart("--out", out, inputs, "a model folder")
    if not out.exists() and not out.is_symlink():
        return out
    if not force:
        raise UserError(f"--out {out}: expected a new model folder, found an existing one "
                        "(pass --force to replace it)")
    if out.is_dir() and not out.is_symlink() and ((out / "model.json").is_file() or not any(out.iterdir())):
        return out
    raise UserError(f"--out {out}: expected a model folder (with model.json) to replace, found "
                    f"{_describe(out)}")


def _describe(path: Path) -> str:
    """What an existing non-model path is, for a refusal message."""
    if path.is_symlink():
        return "a symbolic link"
    if not path.is_dir():
        return "a file"
    entries = list(path.iterdir())
    sessions = sum((e / "session.json").is_file() for e in entries)
    if sessions:
        return f"a folder with {sessions} session folder{'s' * (sessions != 1)}"
    return f"a folder with {len(entries)} entr{'ies' if len(entries) != 1 else 'y'} and no model.json"


def _umask() -> int:
    """The process umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _swap_into_place(tmp: Path, out: Path, *, force: bool = True) -> None:
    """Rename the finished folder over the target (the old one removed only after).

    The old folder moves into a fresh private folder first (never to a guessable name). Without
    ``force`` a target that appeared since the start (another program, a second train) is never
    replaced: a :class:`UserError` names it, and the rename itself refuses a folder that appears in
    the last instant (it replaces only an empty one).

    Raises
    ------
    UserError
        Without ``force``, when ``out`` exists.
    """
    if not force and (out.exists() or out.is_symlink()):
        raise UserError(f"--out {out}: expected a new model folder, found one appeared during the training "
                        "(made by another program?); nothing written (pass --force to replace it)")
    trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
    old = trash / out.name
    try:
        if out.exists():
            os.replace(out, old)
        try:
            os.replace(tmp, out)
        except BaseException:
            if old.exists():
                os.replace(old, out)  # the previous model stays where it was
            raise
    finally:
        if out.exists() or not old.exists():  # else the previous model could not be put back: keep it there
            shutil.rmtree(trash, ignore_errors=True)


# --------------------------------------------------------------------------- model card


def _md_table(rows: list[Mapping[str, Any]], columns: list[str]) -> str:
    """A small Markdown table (floats with 3 significant digits)."""
    def fmt(v: Any) -> str:
        """Floats to 3 significant digits."""
        return f"{v:.3g}" if isinstance(v, float) else str(v)
    head = "| " + " | ".join(columns) + " |\n|" + "---|" * len(columns) + "\n"
    return head + "".join("| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |\n" for r in rows)


def _raters_line(prov: dict) -> str:
    """Who labelled the face: humans, or humans + the machine where no human keyed (with its seconds)."""
    raters = prov.get("raters", "humans")
    if raters != "humans+machine":
        return f"{raters} (human key-frames only)"
    counts = prov.get("machine_labelled_seconds", {})
    return ("humans+machine (the machine rater's weights, machine/face_landmarker.csv, only where no human "
            "keyed; machine-labelled seconds: " + ", ".join(f"{b} {n}" for b, n in counts.items()) + ")")


def _origins_lines(prov: dict) -> list[str]:
    """Model-card lines: seconds of rater labels by key origin, and the sessions left out."""
    origins = prov.get("label_origins")
    if not isinstance(origins, dict) or not origins:
        return []
    n = origins.get("seconds", {})
    lines = [f"- rater labels by origin (seconds over complete tracks): typed {n.get('typed', 0)}, machine keys "
             f"edited by a rater {n.get('edited', 0)}; keys accepted from the machine and not edited "
             f"{n.get('machine', 0)} (not human labels: left out"
             + (", the machine track labels those seconds)" if prov.get("raters") == "humans+machine" else ")")]
    lines += [f"- session left out: {s}" for s in origins.get("left_out", [])]
    return lines


def _label_comparison_card(comparison: object) -> list[str]:
    """Model-card lines: held-out scores on human labels, human labels only against human + machine."""
    if comparison is None:
        return []
    head = ["", "Face, human labels only against human + machine labels (both fits scored out of fold on "
                "the held-out participants' human labels only):", ""]
    if isinstance(comparison, str):
        return [*head, f"No comparison: {comparison}."]
    rows = comparison if isinstance(comparison, list) else []
    return [*head, _md_table(rows, ["blendshape", "labels", "r", "rmse_pct_range", "n", "machine_seconds"])]


def _machine_agreement_card(rows: object) -> list[str]:
    """Model-card lines: the machine rater's agreement with the humans on this training data."""
    if not isinstance(rows, list) or not rows:
        return []
    return ["", "The machine rater's agreement with the humans on this training data (machine/face_landmarker.csv "
                "against the human labels under the rater policy, at the seconds where both exist; ICC(A,1) "
                "with its 95 % CI, Pearson r, mean absolute difference in % of the range; the CI treats the seconds "
                "as independent, which neighbouring seconds are not, so it is too narrow; the machine's weights "
                "are calibrated on these humans' key-frames, so this is no independent test):", "",
            _md_table(rows, ["blendshape", "n", "icc_a1", "icc_a1_ci_low", "icc_a1_ci_high", "r", "mad_pct"])]


def model_card(bundle: ModelBundle) -> str:
    """``MODEL_CARD.md``: data, participants, metrics, limitations, intended use."""
    prov, met = bundle.provenance, bundle.metrics
    reg = bundle.nhr_regression
    lines = [
        "# Model card: effortface face-of-effort model", "",
        f"Exported {prov.get('created_utc', _dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds'))} "
        f"by effortface {prov.get('software_version', '?')}.", "",
        "## Intended use",
        "Animate a 3D character's effort expressions (mouth stretch, mouth open, eye squint, brow lower) "
        "from its motion, for games and films, after Boukhalfi et al. 2015. Not a medical or "
        "physiological measurement: heart rate, VO2 and EPOC are internal model states.", "",
        "## Data",
        f"- sources: {', '.join(map(str, prov.get('sources', []))) or 'n/a'}",
        f"- participants: {prov.get('n_participants', '?')} ({', '.join(prov.get('participants', []))}), "
        f"training levels {prov.get('training_levels', '?')}",
        f"- sessions: {prov.get('n_sessions', '?')}; participant-seconds: {prov.get('n_seconds', '?')}; "
        f"face training rows after subsampling: {prov.get('n_face_rows', '?')}",
        f"- face fit: {_face_fit_line(prov)}",
        f"- rater policy: {prov.get('rater_policy', 'n/a')}",
        f"- raters: {_raters_line(prov)}",
        *_origins_lines(prov),
        f"- annotation tracks used: {prov.get('annotation_rule', 'all (model trained before the completeness rule)')}", "",
        "## Model",
        f"- heart rate: t_root = {reg.t_root[0]:.3g} {reg.t_root[1]:+.3g} TL W/kg, "
        f"c_inc = {reg.c_inc[0]:.3g} {reg.c_inc[1]:+.3g} TL, c_dec = {reg.c_dec[0]:.3g} {reg.c_dec[1]:+.3g} TL",
        f"- face: one RBF epsilon-SVR per blendshape on standardised [{', '.join(bundle.feature_names)}]; "
        f"hyper-parameters by {prov.get('cv', 'lopo')} cross-validation: "
        + "; ".join(f"{n}: C={h['C']:g}, gamma={h['gamma']:g}, epsilon={h['epsilon']:g}"
                    for n, h in zip(bundle.blendshapes.names, bundle.svr_hyperparameters)),
        "- output filter: critically damped low-pass 1 / (1 + tau s)^2 on the weights, tau = "
        + ", ".join(f"{n} {t:g} s" for n, t in zip(bundle.blendshapes.names, bundle.filter_tau_s or ()))
        + " (model.json output_filter; the runtime applies it, face.onnx gives the raw weights)",
        *_anchor_lines(bundle), "",
        "## Metrics (held-out participants unless stated)", "",
        "Heart rate (simulated over whole sessions from the first measured value; held out: "
        "per_participant on the participant's other sessions, pooled_threshold and tl_regression on "
        "other participants; per_participant_in_sample is in-sample, as the paper's Fig. 2a figure "
        "r 0.88, RMSE 19 %; paper TL model r 0.87, RMSE 24 %; pooled_threshold is not the paper's "
        "pooled model, an unpruned regression tree):", "",
        _md_table([{"model": k, **v} for k, v in met.get("hr", {}).items()],
                  ["model", "r", "rmse_pct", "hr_rmse_bpm", "n_sessions"]), "",
        *_card_headline(met.get("face_held_out", [])),
        "Face (weights of held-out participants; every row but svr_known_expressiveness uses an "
        "expressiveness estimated without the scored participant's key-frames; svr_known_expressiveness "
        "uses their own, which borrows from the test labels). The paper's face figure is a training "
        "(in-sample) RMSE of 17-26 %. Rows:", "",
        *[f"- {m}: {MODEL_MEANINGS[m]}" for m in dict.fromkeys(r.get("model") for r in met.get("face_held_out", []))
          if m in MODEL_MEANINGS], "",
        _md_table(met.get("face_held_out", []), ["blendshape", "model", "r", "rmse_pct_range", "rmse_pct_unit"]),
        "", "Face in-sample (the final SVRs on their training rows, comparable to the paper's 17-26 %):", "",
        _md_table(met.get("face_in_sample", []), ["blendshape", "model", "r", "rmse_pct_range", "rmse_pct_unit"]),
        *_label_comparison_card(met.get("face_label_comparison")),
        *_machine_agreement_card(met.get("machine_agreement")),
        "", _engine_line(met), f"Export parity: {met.get('export_parity', {})}", "",
        "## Built-in models",
        "`default` (no bundle) is the rule face model with heart rate calibrated against the 2024 "
        "Adult Compendium of Physical Activities through %VO2R = %HRR; `paper-2015` keeps the paper's "
        "coefficients. This bundle's heart rate is the paper's recursion fitted on the lab above "
        "(docs/SCIENCE_NOTES.md).", "",
        "## Limitations",
        "- Trained on few participants; expressiveness is per character and must be supplied "
        "(default 1 = the training participants' normalised scale).",
        "- The EPOC recursion is our documented choice (Firstbeat's function is proprietary).",
        "- Predictions outside the training ranges of work and power are extrapolations.",
        "- The svr rows' hyper-parameters were chosen by the same cross-validation that scores them "
        "(not nested); svr_as_game and svr_nested_measured_nhr choose them on the other participants "
        "only (nested), and the gap between svr and svr_nested_measured_nhr measures that optimism.",
        *hr_warnings(met.get("hr", {})), "",
    ]
    return "\n".join(lines)


def _anchor_lines(bundle: ModelBundle) -> list[str]:
    """The card's statement of the rest anchor (none for a bundle without one)."""
    a = bundle.rest_anchor
    if a is None:
        return []
    names = bundle.blendshapes.names
    return ["- rest anchor: the SVR output at rest ("
            + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, a.at_rest)) + ") maps to a neutral face "
            "(level " + ", ".join(f"{v:g}" for v in a.level) + "); the raters keyed a median of "
            + ", ".join(f"{v:.3f}" for v in a.raters_rest_level)
            + " (normalised) at rest (model.json rest_anchor; the runtime applies it, face.onnx does not)"]


def _card_headline(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The card's lead face score: "as a game uses it" (NHR from work), the measured-NHR one beside it."""
    if not rows:
        return []
    table = pd.DataFrame(rows)
    model, r, rmse = headline(table)
    measured = table[table["model"] == "svr"]
    if model == "svr":  # a bundle trained before the game row existed
        return [f"Held-out face score with measured NHR (svr): mean r {r:.3f}, RMSE {rmse:.1f} % of the range.", ""]
    return [f"**Held-out face score as a game uses it (NHR predicted from work, no measured heart rate): "
            f"mean r {r:.3f}, RMSE {rmse:.1f} % of the range** (svr_as_game).",
            f"With the measured NHR (svr, labelled; a game never has it): mean r {measured['r'].mean():.3f}, "
            f"RMSE {measured['rmse_pct_range'].mean():.1f} % of the range.", ""]


def _face_fit_line(prov: Mapping[str, Any]) -> str:
    """The model card's statement of the face models' kind and the rows they learnt from."""
    info = prov.get("face_fit") or {}
    rows = info.get("n_face_rows", prov.get("n_face_rows", "?"))
    if info.get("method") == "nystroem":
        return (f"Nystroem kernel approximation ({', '.join(map(str, info.get('n_landmarks') or []))} "
                f"landmarks per blendshape, kernel ridge) on {rows} face rows: above "
                f"{info.get('exact_max_rows', '?')} rows exact SVR does not fit")
    if info.get("method") == "exact_svr":
        return f"exact RBF SVR on {rows} face rows (exact up to {info.get('exact_max_rows', '?')} rows)"
    return f"{rows} face rows"


def hr_warnings(hr: Mapping[str, Mapping[str, float]]) -> list[str]:
    """Limitation lines (Markdown bullets) when the training-level heart-rate model generalises
    worse than the pooled one on held-out participants (``hr``: :meth:`HrEvaluation.summary`)."""
    tl, pooled = hr.get("tl_regression"), hr.get("pooled_threshold", hr.get("pooled"))  # "pooled": old bundles
    if not tl or not pooled or tl["rmse_pct"] <= pooled["rmse_pct"]:
        return []
    return [f"- On held-out participants the training-level heart-rate model ({tl['rmse_pct']:.1f} % RMSE) "
            f"did worse than one pooled model ({pooled['rmse_pct']:.1f} %), unlike the paper: the "
            "participants' thresholds may follow their exercises rather than their training level "
            "(e.g. each did a different kind of exercise). Record every participant in every kind."]
