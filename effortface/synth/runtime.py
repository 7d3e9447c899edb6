"""The runtime API (DESIGN.md): what game code and animation tools load. numpy and scipy only.

::

    from effortface.synth.runtime import load_model, Character
    model = load_model("models/default")           # a bundle folder, or "default" (rule model)
    hero = Character(age=30, sex="male", height_m=1.78, mass_kg=75, training_level=5,
                     expressiveness=(1, 1, 1, 1))
    curves = model.synthesize("clip.bvh", hero)     # whole clip: dict of per-frame arrays
    live = model.stream(hero, skeleton)             # game loop: one step per frame
    weights = live.step(joint_positions_m, dt_s)    # (B,) blendshape weights in [0, 1]
    crowd = model.stream_batch(characters, skeleton)
    weights = crowd.step(positions_m, dt_s)         # (N, J, 3) -> (N, B), SVR vectorised over N

Per frame: joint positions -> work w and power p (effortface.synth.energy) -> physiology (NHR once per
simulated second, effortface.synth.physiology) -> face model on [w, p, NHR, EPOC_norm] (effortface.synth.face) ->
x expressiveness. ``synthesize(..., causal=True)`` uses the streaming (causal) energy filter, and
then gives the same curves as stepping a stream over the same frames (tested); the default
zero-phase filter is better for files.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core import bounds
from effortface.core.errors import UserError
from effortface.core.participant import LIMITS, check_limit, check_sex
from effortface.synth.bundle import default_physiology, read_bundle
from effortface.synth.energy import EnergyCrowd, EnergyStream, work_and_power
from effortface.synth.face import (DEFAULT_FILTER_TAU_S, RestAnchor, RuleFaceModel, SvrModel, SvrSurrogate,
                                   WeightFilter, apply_expressiveness, check_filter_tau, filter_weights)
from effortface.synth.motion import Motion, read_motion
from effortface.synth.physiology import (CALIBRATED_REGRESSION, PAPER_REGRESSION, EpocParams, NhrRegression,
                                         PhysiologyParams,
                              PhysiologyState, simulate)
from effortface.synth.segments import BodyModel, Loads, build_body

#: A character's limits are a participant's (:data:`effortface.core.participant.LIMITS`, the one
#: table every stage reads). Training levels: the paper's participants span 0-7.5 (the resting-HR
#: chart's range, clamped above 7.5) and its Fig. 5 animates TL 10; at TL 10 the paper's c_inc is
#: still positive (0.0013), beyond about 13 it would turn negative.
TRAINING_LEVEL_RANGE = LIMITS["training_level"].bounds
AGE_RANGE = LIMITS["age"].bounds
HEIGHT_RANGE_M = LIMITS["height_m"].bounds
MASS_RANGE_KG = LIMITS["mass_kg"].bounds
#: Frames used for bone lengths (a median over frames; more adds time, not accuracy).
REFERENCE_FRAMES = 600
#: Per-frame columns of :meth:`FaceModel.synthesize`, before one column per blendshape.
CURVE_COLUMNS = ("t_s", "w_per_kg", "p_per_kg", "nhr", "hr_bpm", "vo2", "resp_rate", "epoc")


@dataclasses.dataclass(frozen=True)
class Character:
    """A character's body, fitness, loads and expressiveness (validated on creation).

    Parameters
    ----------
    age : float
        Years (10-100).
    sex : {"male", "female"}
        Selects the de Leva table, the resting-HR chart row and the VO2max model ("m"/"f" accepted).
    height_m : float
        Height in metres (0.5-2.6).
    mass_kg : float
        Body mass in kg (15-300): the divisor of w and p.
    training_level : float
        0 (sedentary) to 10, see :data:`TRAINING_LEVEL_RANGE`.
    expressiveness : sequence of float
        One factor >= 0 per blendshape of the model (< 1 softens, > 1 exaggerates).
    load_left_kg, load_right_kg, load_back_kg : float
        Carried loads (>= 0).
    hr_rest_bpm, hr_max_bpm : float, optional
        Measured values (25-120 and 100-240 bpm); they override the charts.

    Raises
    ------
    UserError
        One line naming the bad field, the expected form and the value found.
    """

    age: float = 30
    sex: str = "male"
    height_m: float = 1.78
    mass_kg: float = 75
    training_level: float = 5
    expressiveness: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    load_left_kg: float = 0.0
    load_right_kg: float = 0.0
    load_back_kg: float = 0.0
    hr_rest_bpm: float | None = None
    hr_max_bpm: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "sex", check_sex(self.sex))
        for name in ("age", "height_m", "mass_kg", "training_level"):
            check_limit(name, getattr(self, name))
        object.__setattr__(self, "expressiveness", _expressiveness(self.expressiveness))
        for name in ("load_left_kg", "load_right_kg", "load_back_kg"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or not (math.isfinite(value) and float(value) >= 0):
                raise UserError(f"{name}: expected a load of 0 kg or more, found {value!r}")
            bounds.check("load_kg", value, name)
        for name in ("hr_rest_bpm", "hr_max_bpm"):
            if getattr(self, name) is not None:
                check_limit(name, getattr(self, name))

    def loads(self) -> Loads:
        """The carried loads as :class:`effortface.synth.segments.Loads`."""
        return Loads(self.load_left_kg, self.load_right_kg, self.load_back_kg)


def _expressiveness(values: Any) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise UserError(f"expressiveness: expected a sequence of numbers, found {values!r}") from None
    if not all(math.isfinite(v) and v >= 0 for v in out):
        raise UserError(f"expressiveness: expected numbers >= 0, found {values!r}")
    return out


# --------------------------------------------------------------------------- the model

class FaceModel:
    """A loaded model: NHR regression + physiology choices + face model + blendshape set.

    Use :func:`load_model` to get one.
    """

    def __init__(self, face: SvrModel | RuleFaceModel, blendshapes: BlendshapeSet,
                 nhr_regression: NhrRegression = PAPER_REGRESSION,
                 physiology: dict[str, Any] | None = None, name: str = "default",
                 filter_tau_s: Any = DEFAULT_FILTER_TAU_S, rest_anchor: RestAnchor | None = None) -> None:
        self.face = face
        #: maps the face model's output at rest to a neutral face (None: outputs unchanged)
        self.rest_anchor = rest_anchor
        self.blendshapes = blendshapes
        self.nhr_regression = nhr_regression
        self.physiology = physiology or default_physiology()
        self.name = name
        self.filter_tau_s = check_filter_tau(filter_tau_s, len(blendshapes))

    def filter_taus(self, filter_tau_s: Any = None) -> np.ndarray:
        """Output-filter time constants (B,): the model's, or ``filter_tau_s`` (0 = no filter).

        Raises
        ------
        UserError
            Unless ``filter_tau_s`` is None, one number >= 0 or one per blendshape.
        """
        if filter_tau_s is None:
            return self.filter_tau_s
        return check_filter_tau(filter_tau_s, len(self.blendshapes))

    def anchored(self, normalised: np.ndarray) -> np.ndarray:
        """The face model's normalised outputs through the rest anchor (unchanged without one)."""
        return normalised if self.rest_anchor is None else self.rest_anchor.apply(normalised)

    @property
    def columns(self) -> tuple[str, ...]:
        """Curve names returned by :meth:`synthesize`, in order."""
        return CURVE_COLUMNS + self.blendshapes.names

    def expressiveness(self, character: Character) -> np.ndarray:
        """The character's expressiveness vector, checked against this model's blendshapes."""
        e = character.expressiveness
        if len(e) != len(self.blendshapes):
            raise UserError(f"expressiveness: expected {len(self.blendshapes)} values "
                            f"({', '.join(self.blendshapes.names)}), found {len(e)}")
        return np.asarray(e, dtype=float)

    def physiology_params(self, character: Character) -> PhysiologyParams:
        """Physiology parameters of a character under this model's choices."""
        return PhysiologyParams.from_character(
            character, hr_max_formula=self.physiology["hr_max_formula"],
            regression=self.nhr_regression, epoc=EpocParams(**self.physiology["epoc"]),
            update_period_s=self.physiology["update_period_s"])

    def body(self, character: Character, skeleton: Motion, mapping: Any = None) -> BodyModel:
        """The character's segments on a skeleton (its own bone lengths, the character's mass).

        Bone lengths are medians over at most :data:`REFERENCE_FRAMES` evenly spaced frames.
        """
        step = max(1, skeleton.n_frames // REFERENCE_FRAMES)
        return build_body(skeleton.joint_names, skeleton.parents, character.mass_kg, character.sex,
                          loads=character.loads(), mapping=mapping,
                          reference_positions_m=skeleton.positions_m[::step], source=skeleton.source)

    def synthesize(self, motion: str | os.PathLike[str] | Motion, character: Character, *,
                   mapping: Any = None, causal: bool = False, filter_tau_s: Any = None
                   ) -> dict[str, np.ndarray]:
        """Per-frame curves for a whole clip.

        Parameters
        ----------
        motion : path or Motion
            A ``.bvh`` / ``.npz`` file or a :class:`effortface.synth.motion.Motion`.
        character : Character
            Who moves.
        mapping : dict or path, optional
            A user joint-to-segment mapping (built-in conventions otherwise).
        causal : bool
            Use the streaming (causal) energy filter instead of the zero-phase one, to match
            :meth:`stream` frame for frame.
        filter_tau_s : float or sequence of float, optional
            Output-filter time constant(s) in seconds (:class:`~effortface.synth.face.WeightFilter`;
            default: the model's, from its bundle); 0 gives the raw, unfiltered weights.

        Returns
        -------
        dict of ndarray, each (T,)
            :data:`CURVE_COLUMNS` then one weight curve per blendshape.

        Notes
        -----
        No plausibility gate here (a choice): game code feeds its own characters, children and
        creatures among them, and a refusal inside a game loop helps no one. A file is read with its
        unit and up axis detected (:func:`effortface.synth.motion.read_motion`); to refuse a body
        outside the human ranges as the commands do, call
        :func:`effortface.synth.plausibility.check_plausible` on the clip first.
        """
        e = self.expressiveness(character)
        motion = motion if isinstance(motion, Motion) else read_motion(Path(motion))
        body = self.body(character, motion, mapping)
        energy = work_and_power(motion, body, zero_phase=not causal)
        return self.curves_from_work(motion.t_s, energy.w_per_kg, energy.p_per_kg,
                                     1.0 / motion.fps, character, e, filter_tau_s=filter_tau_s)

    def curves_from_work(self, t_s: Any, w_per_kg: Any, p_per_kg: Any, dt_s: float,
                         character: Character, e: np.ndarray | None = None, *,
                         filter_tau_s: Any = None) -> dict[str, np.ndarray]:
        """Physiology and face curves from work and power curves (e.g. a session's work.csv).

        ``filter_tau_s`` as in :meth:`synthesize` (None: the model's output filter).
        """
        e = self.expressiveness(character) if e is None else e
        taus = self.filter_taus(filter_tau_s)
        phys = simulate(w_per_kg, dt_s, self.physiology_params(character))
        return self.curves_from_physiology(t_s, w_per_kg, p_per_kg, phys, e,
                                           lambda weights: filter_weights(weights, dt_s, taus))

    def curves_from_physiology(self, t_s: Any, w_per_kg: Any, p_per_kg: Any, phys: dict[str, np.ndarray],
                               e: np.ndarray, smooth: Callable[[np.ndarray], np.ndarray]
                               ) -> dict[str, np.ndarray]:
        """The curves of some frames from their work, power and physiology: the face model, the
        expressiveness ``e`` and the output filter ``smooth`` ((T, B) -> (T, B); a whole clip's
        :func:`~effortface.synth.face.filter_weights` or a piece's :meth:`WeightFilter.run`)."""
        features = np.column_stack([w_per_kg, p_per_kg, phys["nhr"], phys["epoc_norm"]])
        normalised = self.anchored(self.face.predict(features))
        weights = smooth(apply_expressiveness(normalised, e))
        curves = {"t_s": np.asarray(t_s, float), "w_per_kg": np.asarray(w_per_kg, float),
                  "p_per_kg": np.asarray(p_per_kg, float)}
        curves.update({k: phys[k] for k in CURVE_COLUMNS[3:]})
        curves.update({n: weights[:, i] for i, n in enumerate(self.blendshapes.names)})
        return curves

    def stream(self, character: Character, skeleton: Motion, *, mapping: Any = None,
               fps: float | None = None, filter_tau_s: Any = None) -> CharacterStream:
        """A live stream for one character on a skeleton.

        Parameters
        ----------
        character : Character
        skeleton : Motion
            Joint names, parents and reference positions (e.g. a rest pose built with
            :func:`effortface.synth.motion.motion_from_positions`); its fps is the stream's nominal rate.
        mapping : dict or path, optional
            A user joint-to-segment mapping.
        fps : float, optional
            Nominal frame rate: the energy filter's cut-off is checked against it (default: the
            skeleton's); the stream follows the ``dt_s`` of every step.
        filter_tau_s : float or sequence of float, optional
            Output-filter time constant(s), seconds, as in :meth:`synthesize`.
        """
        return CharacterStream(self, character, skeleton, mapping=mapping, fps=fps,
                               filter_tau_s=filter_tau_s)

    def stream_batch(self, characters: Sequence[Character], skeleton: Motion, *,
                     mapping: Any = None, fps: float | None = None,
                     single_precision: bool = False, filter_tau_s: Any = None,
                     surrogate: bool = False) -> CrowdStream:
        """A live stream for N characters on one skeleton layout (see :class:`CrowdStream`)."""
        return CrowdStream(self, characters, skeleton, mapping=mapping, fps=fps,
                           single_precision=single_precision, filter_tau_s=filter_tau_s,
                           surrogate=surrogate)


# --------------------------------------------------------------------------- streams

class CharacterStream:
    """One character, one frame at a time (a game loop). Use :meth:`FaceModel.stream`.

    Attributes
    ----------
    last : dict
        The latest values of every curve (:data:`CURVE_COLUMNS` and the blendshape weights).
    """

    def __init__(self, model: FaceModel, character: Character, skeleton: Motion, *,
                 mapping: Any = None, fps: float | None = None, filter_tau_s: Any = None) -> None:
        self.model = model
        self._e = model.expressiveness(character)
        self._filter = WeightFilter(model.filter_taus(filter_tau_s))
        self._energy = EnergyStream(model.body(character, skeleton, mapping), fps or skeleton.fps)
        self._state = PhysiologyState(model.physiology_params(character))
        self.t_s = 0.0
        self._frames = 0
        self.last: dict[str, float] = {}

    def step(self, joint_positions_m: Any, dt_s: float, rotations: Any = None) -> np.ndarray:
        """Advance by one frame: joint positions (J, 3) in metres, Z up, and the time step.

        ``rotations`` (J, 3, 3), the joints' world rotations, are optional (give them on every
        frame or on none): without them spin about a segment's long axis is not seen.

        Returns
        -------
        ndarray, shape (B,)
            Blendshape weights in [0, 1].
        """
        w, p = self._energy.step(np.asarray(joint_positions_m, dtype=float), dt_s, rotations)
        return self.step_work(w, p, dt_s)

    def step_work(self, w_per_kg: float, p_per_kg: float, dt_s: float) -> np.ndarray:
        """Advance by one frame from work and power computed elsewhere (W/kg)."""
        if self._frames:
            self.t_s += float(dt_s)
        self._frames += 1
        phys = self._state.step(w_per_kg, dt_s)
        x = np.array([[w_per_kg, p_per_kg, phys["nhr"], phys["epoc_norm"]]], dtype=float)
        normalised = self.model.anchored(self.model.face.predict(x)[0])
        weights = self._filter.step(apply_expressiveness(normalised, self._e), dt_s)
        self.last = {"t_s": self.t_s, "w_per_kg": float(w_per_kg), "p_per_kg": float(p_per_kg),
                     **{k: float(phys[k]) for k in CURVE_COLUMNS[3:]},
                     **dict(zip(self.model.blendshapes.names, weights.tolist()))}
        return weights


class CrowdStream:
    """N characters stepped together: physiology and the face model are vectorised over N.

    Energies use one causal :class:`~effortface.synth.energy.EnergyCrowd` vectorised over the characters
    (each keeps its own body: mass, bone lengths, loads). Engines that compute work themselves call
    :meth:`step_work`. Two options trade exactness for speed with an SVR face model, whose cost
    grows with its support vectors (2,500 characters x 8,000 support vectors: 20 million kernel
    terms a frame):

    * ``single_precision``: the kernels in float32, each distinct support vector once for all the
      blendshapes that share it (6.5x faster than float64 for a model of 8,996 vectors, 2,300
      distinct: about 3,300 characters at 60 FPS per core from joint positions, median frame); the
      error grows with the dual coefficients (:meth:`effortface.synth.face.SvrModel.predict`:
      6.5e-3 over the training range of a C = 100 model with 9,000 support vectors, 1.1e-3 on a crowd).
    * ``surrogate``: the model's compact surrogate (:class:`effortface.synth.face.SvrSurrogate`,
      fitted once per model in 1-2 s): at most :data:`~effortface.synth.face.SURROGATE_MAX_ERROR`
      (1e-3; 8e-5 on its held-out points for that model) from the exact weights on the training
      range, the exact model outside it. Models too small to gain from one (no surrogate
      within 1/4 of their kernel terms) stay exact.

    Neither is used unless asked: single characters (:meth:`FaceModel.stream`) are always exact.
    """

    def __init__(self, model: FaceModel, characters: Sequence[Character], skeleton: Motion, *,
                 mapping: Any = None, fps: float | None = None,
                 single_precision: bool = False, filter_tau_s: Any = None,
                 surrogate: bool = False) -> None:
        if not characters:
            raise UserError("characters: expected at least one character, found none")
        self.model = model
        self._e = np.array([model.expressiveness(c) for c in characters])
        self._n = len(characters)
        self._filter = WeightFilter(model.filter_taus(filter_tau_s))
        self._energy = EnergyCrowd([model.body(c, skeleton, mapping) for c in characters],
                                   fps or skeleton.fps)
        params = PhysiologyParams.stack([model.physiology_params(c) for c in characters])
        self._state = PhysiologyState(params)
        self._predict_kw = ({"single_precision": True}
                            if single_precision and isinstance(model.face, SvrModel) else {})
        face: SvrModel | SvrSurrogate | RuleFaceModel | None = model.face
        if surrogate and isinstance(model.face, SvrModel):
            face = model.face.surrogate()
        self.face = face or model.face  #: what the step evaluates: the model's face, or its surrogate
        self.last: dict[str, np.ndarray] = {}

    def __len__(self) -> int:
        return self._n

    def step(self, positions_m: Any, dt_s: float) -> np.ndarray:
        """Advance all characters: positions (N, J, 3) in metres -> weights (N, B).

        Everything is vectorised over the characters (no per-character Python): one energy tick
        per 1 / fps of game time (build the crowd with the game's frame rate as ``fps``)."""
        pos = np.asarray(positions_m, dtype=float)
        if pos.ndim != 3 or pos.shape[0] != len(self):
            raise UserError(f"positions_m: expected shape ({len(self)}, J, 3), found {pos.shape}")
        w_per_kg, p_per_kg = self._energy.step(pos, dt_s)
        return self.step_work(w_per_kg, p_per_kg, dt_s)

    def step_work(self, w_per_kg: Any, p_per_kg: Any, dt_s: float) -> np.ndarray:
        """Advance all characters from work and power (N,) computed elsewhere -> weights (N, B)."""
        phys = self._state.step(w_per_kg, dt_s)
        x = np.column_stack([w_per_kg, p_per_kg, phys["nhr"], phys["epoc_norm"]])
        weights = apply_expressiveness(self.model.anchored(self.face.predict(x, **self._predict_kw)), self._e)
        weights = self._filter.step(weights, dt_s)
        self.last = dict(phys, w_per_kg=np.asarray(w_per_kg), p_per_kg=np.asarray(p_per_kg))
        return weights


# --------------------------------------------------------------------------- loading

#: Built-in models by name: the rule face model with the Compendium-calibrated NHR model
#: (``default``) or with the paper's exact coefficients (``paper-2015``); docs/SCIENCE_NOTES.md.
BUILT_IN_MODELS: dict[str, tuple[NhrRegression, str]] = {
    "default": (CALIBRATED_REGRESSION, "default (rule model, Compendium-calibrated heart rate)"),
    "paper-2015": (PAPER_REGRESSION, "paper-2015 (rule model, the paper's heart-rate coefficients)"),
}


def load_model(path: str | os.PathLike[str] | None = "default") -> FaceModel:
    """Load a model bundle folder, or a built-in rule model by name.

    Parameters
    ----------
    path : path, "default", "paper-2015" or None
        A folder with ``model.json`` and ``svr.npz`` (see :mod:`effortface.synth.bundle`), or a
        name of :data:`BUILT_IN_MODELS`: ``"default"`` (also None) calibrates heart rate against
        the 2024 Adult Compendium of Physical Activities; ``"paper-2015"`` keeps the paper's
        coefficients (t_root = 7.13 + 0.42 TL, above walking and jumping jacks in W/kg).

    Returns
    -------
    FaceModel

    Raises
    ------
    UserError
        A missing or malformed bundle (the message names the file and field).
    """
    name = "default" if path is None else str(path)
    if name in BUILT_IN_MODELS:
        regression, label = BUILT_IN_MODELS[name]
        return FaceModel(RuleFaceModel(DEFAULT_SET), DEFAULT_SET, regression, name=label)
    bundle = read_bundle(Path(path))  # type: ignore[arg-type]
    return FaceModel(bundle.face_model(), bundle.blendshapes, bundle.nhr_regression,
                     bundle.physiology, name=str(path), filter_tau_s=bundle.filter_tau_s,
                     rest_anchor=bundle.rest_anchor)


__all__ = ["BUILT_IN_MODELS", "Character", "CharacterStream", "CrowdStream", "FaceModel", "load_model",
           "CURVE_COLUMNS", "AGE_RANGE", "HEIGHT_RANGE_M", "MASS_RANGE_KG", "TRAINING_LEVEL_RANGE"]
