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
#: metabolic demand per mechanical W/kg (choice): squats cost more than their "no transfer" work
#: says (isometric holding, pressor response; a load adds to it), jumping jacks somewhat more;
#: walking and running are the reference (1)
SQUAT_DEMAND_PER_W = 1.8
JUMPING_JACK_DEMAND_PER_W = 1.2


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
            effort, label = w * SQUAT_DEMAND_PER_W * (1.0 + load / mass_kg), "squats"
        else:
            w, effort, label = JUMPING_JACK_W_PER_KG, JUMPING_JACK_W_PER_KG * JUMPING_JACK_DEMAND_PER_W, "jumping jacks"
        phases.append(Phase(t, t + dur, label, w, None, load, reps, effort))
        t += dur
    return tuple(phases)


#: the sessions of the first week (index 0-5: the kind alternates with the participant) and of the
#: second week (index 6-11: each participant does the other kind), so every participant has both
FIRST_WEEK = dt.datetime(2026, 1, 12, 9, 30, 0)
SECOND_WEEK = dt.datetime(2026, 1, 19, 14, 0, 0)
#: strap protocol per session index: ANT+, HxM, HRMI and text lines spread over both kinds
PROTOCOLS = ("ant", "hxm", "hrmi", "lines", "ant", "hxm", "hrmi", "ant", "hxm", "hrmi", "lines", "ant")
CARDIO_BOUTS: tuple[tuple[tuple[str, float, float], ...], ...] = (
    (("walk", 1.5, 25), ("run", 2.5, 45), ("walk", 1.2, 35), ("run", 3.4, 45), ("rest", 0, 50)),
    (("rest", 0, 15), ("walk", 1.5, 25), ("run", 2.8, 45), ("walk", 1.3, 30), ("run", 3.6, 45),
     ("rest", 0, 45)),
    (("rest", 0, 15), ("walk", 1.6, 25), ("run", 3.2, 50), ("rest", 0, 35), ("run", 3.8, 40),
     ("rest", 0, 45)),
)


def build_plans() -> tuple[SessionPlan, ...]:
    """The lab's 12 sessions: every participant does one cardio and one strength session, each
    alternating low and high bouts with recovery (about 3.5 min)."""
    plans = []
    for i, person in enumerate(PEOPLE):
        first = FIRST_WEEK + dt.timedelta(days=i // 2, hours=2 * (i % 2), minutes=7 * i)
        second = SECOND_WEEK + dt.timedelta(days=i // 2, hours=-2 * (i % 2), minutes=11 * i)
        kinds = ("cardio", "strength") if i % 2 == 0 else ("strength", "cardio")
        for index, kind, start in ((i, kinds[0], first), (i + len(PEOPLE), kinds[1], second)):
            phases = (_cardio(CARDIO_BOUTS[i // 2]) if kind == "cardio"
                      else _strength(_strength_bouts(i), person.mass_kg))
            plans.append(SessionPlan(index, person, kind, start, PROTOCOLS[index], phases))
    return tuple(sorted(plans, key=lambda p: p.index))


def _strength_bouts(i: int) -> list[tuple[str, float, int, float]]:
    """Bodyweight squats, loaded squats and jumping jacks with rests (loads scale with the person);
    every other participant starts with the jumping jacks and ends with a heavy set."""
    load = round(0.25 * PEOPLE[i].mass_kg / 5) * 5
    if i % 2 == 0:
        return [("rest", 0, 0, 15), ("squats", 0, 12, 30), ("rest", 0, 0, 25), ("squats", load, 12, 35),
                ("rest", 0, 0, 25), ("jacks", 0, 50, 45), ("rest", 0, 0, 40)]
    return [("rest", 0, 0, 15), ("jacks", 0, 45, 40), ("rest", 0, 0, 30), ("squats", load, 12, 35),
            ("rest", 0, 0, 25), ("squats", 2 * load, 10, 25), ("rest", 0, 0, 45)]


def work_at(plan: SessionPlan, t_s: np.ndarray, *, drive: bool = False) -> np.ndarray:
    """Work rate (W/kg) of the plan at times ``t_s``, stepwise by phase (the drive if asked)."""
    t = np.asarray(t_s, dtype=float)
    w = np.full(t.shape, STAND_W_PER_KG)
    for ph in plan.phases:
        w[(t >= ph.start_s) & (t < ph.end_s)] = ph.drive_w_per_kg if drive else ph.w_per_kg
    return w
