"""Test vectors of the physiology state update an engine computes itself (docs/ENGINE.md).

An engine running ``face.onnx`` computes the four features per frame: w and p (W/kg) from its own
motion, and NHR and EPOC from the per-second recursion of :mod:`effortface.synth.physiology`. This
module writes that recursion's inputs and outputs for a few characters and work patterns to
``docs/engine_state_vectors.json``, which the C-like pseudocode of docs/ENGINE.md reproduces (a test
checks both the runtime and a line-by-line transcription of the pseudocode against the file).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.fileio import atomic_write_text, refuse_overwrite
from effortface.synth.physiology import PhysiologyParams, PhysiologyState
from effortface.synth.runtime import Character, FaceModel, load_model

#: the file shipped beside docs/ENGINE.md
VECTORS_NAME = "engine_state_vectors.json"
#: characters of the vectors (training levels and sexes spread out)
CHARACTERS = (Character(age=25, sex="female", height_m=1.65, mass_kg=58, training_level=7),
              Character(age=52, sex="male", height_m=1.80, mass_kg=92, training_level=1))


def work_pattern(n_frames: int = 480, dt_s: float = 1 / 6) -> tuple[np.ndarray, np.ndarray]:
    """A test work curve: rest, hard effort, recovery, with a jittery frame time.

    Returns
    -------
    w_per_kg, dt_s : ndarray, shape (n_frames,)
    """
    t_s = np.arange(n_frames) * dt_s
    w_per_kg = np.where((t_s > 2) & (t_s < 30), 35.0, 0.8) + 2.0 * np.sin(t_s)
    jitter = 1.0 + 0.2 * np.sin(np.arange(n_frames) * 1.7)
    return w_per_kg, dt_s * jitter


def params_dict(params: PhysiologyParams) -> dict[str, float]:
    """The per-character constants of the recursion, by the names of the pseudocode."""
    return {"hr_rest_bpm": float(params.hr_rest_bpm), "hr_max_bpm": float(params.hr_max_bpm),
            "vo2max": float(params.vo2max), "vo2_rest": float(params.vo2_rest),
            "t_root": float(params.nhr.t_root), "c_inc": float(params.nhr.c_inc),
            "c_dec": float(params.nhr.c_dec), "k_up": float(params.epoc.k_up),
            "tau_s": float(params.epoc.tau_s), "threshold": float(params.epoc.threshold),
            "epoc_scale_ml_per_kg": float(params.epoc.scale_ml_per_kg),
            "update_period_s": float(params.update_period_s)}


def state_vectors(model: FaceModel | None = None) -> dict[str, Any]:
    """Inputs and expected outputs of the state update for :data:`CHARACTERS`.

    Parameters
    ----------
    model : FaceModel, optional
        Whose physiology choices to use (default: the built-in ``paper-2015`` model, whose heart-rate
        update is the paper's recursion that docs/ENGINE.md writes out and that trained bundles use;
        the Compendium-calibrated ``default`` adds a state-dependent threshold, see
        docs/SCIENCE_NOTES.md section 4).

    Returns
    -------
    dict
        JSON-ready: ``cases`` with ``character``, ``params``, ``w_per_kg``, ``dt_s`` and the
        expected ``nhr``, ``epoc``, ``hr_bpm``, ``epoc_norm`` after each frame.
    """
    model = model or load_model("paper-2015")
    w_per_kg, dt_s = work_pattern()
    cases = []
    for character in CHARACTERS:
        params = model.physiology_params(character)
        state = PhysiologyState(params)
        rows = [state.step(w, dt) for w, dt in zip(w_per_kg, dt_s)]
        cases.append({
            "character": {k: getattr(character, k) for k in
                          ("age", "sex", "height_m", "mass_kg", "training_level")},
            "params": params_dict(params),
            "w_per_kg": w_per_kg.tolist(), "dt_s": dt_s.tolist(),
            **{k: [float(r[k]) for r in rows] for k in ("nhr", "epoc", "hr_bpm", "epoc_norm")}})
    return {"format": "effortface engine state vectors 1",
            "doc": "docs/ENGINE.md: per frame, step(state, params, w_per_kg, dt_s); compare after each frame",
            "tolerance": 1e-9, "cases": cases}


def write_vectors(path: str | os.PathLike, *, force: bool = False) -> Path:
    """Write :func:`state_vectors` as JSON (atomically; an existing file only with ``force``)."""
    target = refuse_overwrite(path, overwrite=force, what="vectors file", hint=" (use force=True)")
    return atomic_write_text(target, json.dumps(state_vectors()) + "\n")
