"""Who is in the simulated lab and what each session asks of them.

Work magnitudes follow SCIENCE.md section 2 (w in W/kg, the "no transfer" work over 1 s):
standing 0.1, squats 3.4, walking 1.5 m/s 4.2, jumping jacks 8.6, running 3.4 m/s 20.5. Between the
table's points, walking work scales as ``2.8 v`` and running as ``6.0 v`` (v in m/s) (choice).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
from collections.abc import Sequence

import numpy as np

#: W/kg per m/s: walking (1.5 m/s -> 4.2) and running (3.4 m/s -> 20.4)
WALK_W_PER_KG_PER_M_S = 2.8
RUN_W_PER_KG_PER_M_S = 6.0
STAND_W_PER_KG = 0.1
SQUAT_W_PER_KG = 3.4
JUMPING_JACK_W_PER_KG = 8.6
#: effort / work for squats: strength work strains more than its mechanical work says (choice)
STRAIN_FACTOR = 2.5


@dataclasses.dataclass(frozen=True)
class Person:
    """A simulated participant and the hidden traits the stages must recover.

    ``expressiveness`` is the largest weight each blendshape reaches under maximal effort
    (mouth_stretch, mouth_open, eye_squint, brow_lower).
    """

    code: str
    sex: str
    age: float
    height_m: float
    mass_kg: float
    training_level: float
    expressiveness: tuple[float, float, float, float]


PEOPLE: tuple[Person, ...] = (
    Person("P01", "female", 23, 1.66, 58.0, 2.5, (0.75, 0.8, 0.7, 0.65)),
    Person("P02", "male", 31, 1.81, 79.0, 5.0, (0.9, 0.85, 0.95, 0.9)),
    Person("P03", "male", 46, 1.74, 88.0, 0.5, (0.25, 0.3, 0.2, 0.25)),  # neutral under effort
    Person("P04", "female", 38, 1.61, 64.0, 7.5, (1.0, 0.95, 1.0, 1.0)),  # pronounced
    Person("P05", "male", 20, 1.88, 72.0, 6.5, (0.55, 0.6, 0.5, 0.45)),
    Person("P06", "female", 27, 1.70, 61.0, 4.0, (0.35, 0.4, 0.45, 0.3)),
)


@dataclasses.dataclass(frozen=True)
class Phase:
    """One bout of the exercise log: ``[start_s, end_s)``, what was done and its work rate."""

    start_s: float
    end_s: float
    label: str
    w_per_kg: float
    speed_m_s: float | None = None
    load_kg: float = 0.0
    reps: int = 0
    effort_w_per_kg: float | None = None  # metabolic drive when it exceeds the mechanical work

    @property
    def drive_w_per_kg(self) -> float:
        """What the heart and the face respond to: the effort if given, else the work."""
        return self.w_per_kg if self.effort_w_per_kg is None else self.effort_w_per_kg


@dataclasses.dataclass(frozen=True)
class SessionPlan:
    """One session of the lab: who, when, which strap protocol and the phases."""

    index: int
    person: Person
    kind: str  # "cardio" or "strength"
    start: dt.datetime
    protocol: str
    phases: tuple[Phase, ...]

    @property
    def duration_s(self) -> float:
        """Session length (end of the last phase)."""
        return self.phases[-1].end_s

    @property
    def session_id(self) -> str:
        """``<code>_<YYYYmmdd-HHMMSS>_<kind>``."""
        return f"{self.person.code}_{self.start:%Y%m%d-%H%M%S}_{self.kind}"


def _walk(v: float) -> float:
    return WALK_W_PER_KG_PER_M_S * v


def _run(v: float) -> float:
    return RUN_W_PER_KG_PER_M_S * v


def _cardio(bouts: Sequence[tuple[str, float, float]]) -> tuple[Phase, ...]:
    """Phases from ``(gait, speed m/s, duration s)``; gait is rest, walk or run."""
    phases, t = [], 0.0
    for gait, v, dur in bouts:
        w = {"rest": STAND_W_PER_KG, "walk": _walk(v), "run": _run(v)}[gait]
        label = "rest" if gait == "rest" else f"{gait} {v:.1f} m/s"
        phases.append(Phase(t, t + dur, label, w, None if gait == "rest" else v))
        t += dur
    return tuple(phases)


def _strength(bouts: Sequence[tuple[str, float, int, float]], mass_kg: float) -> tuple[Phase, ...]:
    """Phases from ``(exercise, load kg, reps, duration s)``; exercise is rest, squats or jacks."""
    phases, t = [], 0.0
    for what, load, reps, dur in bouts:
        if what == "rest":
            w, effort, label = STAND_W_PER_KG, None, "rest"
        elif what == "squats":
            # a load on the back raises the work per kg of body mass (SCIENCE.md section 2, loads);
            # muscular strain (pressor response) drives heart and face beyond the work itself
            w = SQUAT_W_PER_KG * (mass_kg + load) / mass_kg * (reps / (dur / 2.5))
            effort, label = w * STRAIN_FACTOR * (1.0 + load / mass_kg), "squats"
        else:
            w, effort, label = JUMPING_JACK_W_PER_KG, JUMPING_JACK_W_PER_KG * 1.6, "jumping jacks"
        phases.append(Phase(t, t + dur, label, w, None, load, reps, effort))
        t += dur
    return tuple(phases)


def build_plans() -> tuple[SessionPlan, ...]:
    """The lab's sessions: alternating cardio and strength, low and high bouts with recovery."""
    day = dt.datetime(2026, 1, 12, 9, 30, 0)
    protocols = ("ant", "hxm", "hrmi", "lines", "ant", "hxm")
    cardio_a = [("walk", 1.5, 30), ("run", 2.5, 50), ("walk", 1.2, 40), ("run", 3.4, 45),
                ("rest", 0, 35)]
    cardio_b = [("rest", 0, 20), ("walk", 1.5, 30), ("run", 2.8, 50), ("walk", 1.3, 35),
                ("run", 3.6, 55), ("walk", 1.0, 30), ("run", 3.0, 35), ("rest", 0, 45)]
    cardio_c = [("rest", 0, 20), ("walk", 1.6, 35), ("run", 3.2, 65), ("rest", 0, 40),
                ("run", 3.8, 50), ("rest", 0, 60)]
    plans = []
    for i, person in enumerate(PEOPLE):
        start = day + dt.timedelta(days=i // 2, hours=2 * (i % 2), minutes=7 * i)
        if i % 2 == 0:
            bouts = (cardio_a, cardio_b, cardio_c)[i // 2]
            plans.append(SessionPlan(i, person, "cardio", start, protocols[i], _cardio(bouts)))
        else:
            plans.append(SessionPlan(i, person, "strength", start, protocols[i],
                                     _strength(_strength_bouts(i, person), person.mass_kg)))
    return tuple(plans)


def _strength_bouts(i: int, person: Person) -> list[tuple[str, float, int, float]]:
    """Bodyweight squats, loaded squats and jumping jacks with rests (loads scale with the person)."""
    load = round(0.25 * person.mass_kg / 5) * 5
    bouts: list[tuple[str, float, int, float]] = [("rest", 0, 0, 20), ("squats", 0, 12, 30), ("rest", 0, 0, 30),
             ("squats", load, 12, 35), ("rest", 0, 0, 30), ("jacks", 0, 60, 55), ("rest", 0, 0, 40)]
    if i == 3:  # one longer session with a heavy set
        bouts[-1] = ("rest", 0, 0, 25)
        bouts += [("squats", 2 * load, 10, 25), ("rest", 0, 0, 15), ("jacks", 0, 45, 35),
                  ("rest", 0, 0, 25)]
    return bouts


def work_at(plan: SessionPlan, t_s: np.ndarray, *, drive: bool = False) -> np.ndarray:
    """Work rate (W/kg) of the plan at times ``t_s``, stepwise by phase (the drive if asked)."""
    t = np.asarray(t_s, dtype=float)
    w = np.full(t.shape, STAND_W_PER_KG)
    for ph in plan.phases:
        w[(t >= ph.start_s) & (t < ph.end_s)] = ph.drive_w_per_kg if drive else ph.w_per_kg
    return w
