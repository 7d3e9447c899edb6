"""Who is in the simulated lab and what each session asks of them.

Work magnitudes follow SCIENCE.md section 2 (w in W/kg, the "no transfer" work over 1 s):
standing 0.1, squats 3.4, walking 1.5 m/s 4.2, jumping jacks 8.6, running 3.4 m/s 20.5. Between the
table's points, walking work scales as ``2.8 v`` and running as ``6.0 v`` (v in m/s), a treadmill
grade adds ``g v grade`` (choice). These truths are the simulator's own: the catalog the stages use
(``effortface/core/data/exercise_catalog.csv``) was calibrated on clips, not read from here, and the
log gives it only what an operator records (ids, speeds, grades, loads, repetition counts).

Sessions last 10-12 minutes: bouts of several minutes (heart rate reaches its slow component),
strength sets with individual repetition times (a set's pace varies, the log only counts them).
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
#: squats (choice): the centre of mass drops about 0.45 m, down and up both count (no transfer), plus
#: the limbs: 10.5 J/kg per repetition (3.4 W/kg at 19.4 repetitions a minute); a back load travels
#: the whole depth while only about 85 % of the body mass does
SQUAT_J_PER_KG_PER_REP = 10.5
SQUAT_MOVING_FRACTION = 0.85
JUMPING_JACK_W_PER_KG = 8.6
JUMPING_JACK_REF_PER_MIN = 54.0  # the pace of that 8.6 W/kg
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
    """One bout of the exercise log: ``[start_s, end_s)``, what was done and its true work rate.

    ``exercise`` is the catalog id the operator logs; ``rep_times_s`` the true times of the
    repetitions (the operator's hotkey presses, for squats), ``muscle_fraction`` the share of body
    mass in the working muscles (the paper: expression shrinks with it).
    """

    start_s: float
    end_s: float
    exercise: str
    w_per_kg: float
    speed_m_s: float | None = None
    grade_pct: float = 0.0
    load_kg: float = 0.0
    rep_times_s: tuple[float, ...] = ()
    effort_w_per_kg: float | None = None  # metabolic drive when it exceeds the mechanical work
    muscle_fraction: float = 0.5

    @property
    def label(self) -> str:
        """The exercise id (as logged)."""
        return self.exercise

    @property
    def reps(self) -> int:
        """Repetitions done in the set."""
        return len(self.rep_times_s)

    @property
    def drive_w_per_kg(self) -> float:
        """What the heart responds to: the effort if given, else the work."""
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


G_M_PER_S2 = 9.81
#: share of body mass in the working muscles (choice): legs for gait and squats, whole body for jacks
MUSCLE_FRACTION = {"rest": 0.5, "treadmill": 0.35, "squats": 0.3, "jumping_jacks": 0.5}


def _gait_w(v: float, grade_pct: float) -> float:
    """True treadmill work: walking below 2 m/s, running from it, plus the climb ``g v grade``."""
    level = WALK_W_PER_KG_PER_M_S * v if v < 2.0 else RUN_W_PER_KG_PER_M_S * v
    return level + G_M_PER_S2 * v * grade_pct / 100.0


def _cardio(bouts: Sequence[tuple[str, float, float, float]]) -> tuple[Phase, ...]:
    """Phases from ``(exercise, speed m/s, grade %, duration s)``; exercise is rest or treadmill."""
    phases, t = [], 0.0
    for what, v, grade, dur in bouts:
        if what == "rest":
            phases.append(Phase(t, t + dur, "rest", STAND_W_PER_KG, muscle_fraction=MUSCLE_FRACTION["rest"]))
        else:
            phases.append(Phase(t, t + dur, "treadmill", _gait_w(v, grade), v, grade,
                                muscle_fraction=MUSCLE_FRACTION["treadmill"]))
        t += dur
    return tuple(phases)


def _rep_span(dur_s: float) -> float:
    """The time a set's repetitions take (the set less 0.3 s at each end)."""
    return dur_s - 0.6


def _rep_times(start_s: float, dur_s: float, reps: int, rng: np.random.Generator) -> tuple[float, ...]:
    """When each repetition ends: evenly paced, slowing by up to 15 % through the set, +-8 % jitter."""
    slow = np.linspace(1.0, 1.0 + rng.uniform(0.05, 0.15), reps)
    gaps = slow * (1.0 + rng.normal(0.0, 0.08, reps))
    ends = np.cumsum(gaps) / np.sum(gaps) * _rep_span(dur_s)
    return tuple(round(start_s + 0.3 + float(e), 2) for e in ends)


def _strength(bouts: Sequence[tuple[str, float, int, float]], mass_kg: float,
              rng: np.random.Generator) -> tuple[Phase, ...]:
    """Phases from ``(exercise, load kg, reps, duration s)``; exercise is rest, squats or jacks."""
    phases, t = [], 0.0
    for what, load, reps, dur in bouts:
        if what == "rest":
            phases.append(Phase(t, t + dur, "rest", STAND_W_PER_KG, muscle_fraction=MUSCLE_FRACTION["rest"]))
        elif what == "squats":
            # a load on the back raises the work per kg of body mass (SCIENCE.md section 2, loads);
            # muscular strain (pressor response) drives the heart beyond the work itself
            pace_per_s = reps / _rep_span(dur)
            w = SQUAT_J_PER_KG_PER_REP * pace_per_s * (1.0 + load / (SQUAT_MOVING_FRACTION * mass_kg))
            phases.append(Phase(t, t + dur, "squats", w, None, 0.0, load, _rep_times(t, dur, reps, rng),
                                w * SQUAT_DEMAND_PER_W * (1.0 + load / mass_kg), MUSCLE_FRACTION["squats"]))
        else:
            w = JUMPING_JACK_W_PER_KG * reps / (_rep_span(dur) * JUMPING_JACK_REF_PER_MIN / 60.0)
            phases.append(Phase(t, t + dur, "jumping_jacks", w, None, 0.0, 0.0, _rep_times(t, dur, reps, rng),
                                w * JUMPING_JACK_DEMAND_PER_W, MUSCLE_FRACTION["jumping_jacks"]))
        t += dur
    return tuple(phases)


#: the sessions of the first week (index 0-5: the kind alternates with the participant) and of the
#: second week (index 6-11: each participant does the other kind), so every participant has both
FIRST_WEEK = dt.datetime(2026, 1, 12, 9, 30, 0)
SECOND_WEEK = dt.datetime(2026, 1, 19, 14, 0, 0)
#: strap protocol per session index: ANT+, HxM, HRMI and text lines spread over both kinds
PROTOCOLS = ("ant", "hxm", "hrmi", "lines", "ant", "hxm", "hrmi", "ant", "hxm", "hrmi", "lines", "ant")
#: three treadmill protocols ``(exercise, speed m/s, grade %, duration s)``, 10-11 minutes each
CARDIO_BOUTS: tuple[tuple[tuple[str, float, float, float], ...], ...] = (
    (("rest", 0, 0, 60), ("treadmill", 1.5, 0, 90), ("treadmill", 2.5, 0, 120), ("treadmill", 1.2, 0, 60),
     ("treadmill", 3.4, 0, 100), ("rest", 0, 0, 90), ("treadmill", 1.5, 6, 60), ("rest", 0, 0, 60)),
    (("rest", 0, 0, 45), ("treadmill", 1.4, 0, 75), ("treadmill", 2.8, 0, 120), ("treadmill", 1.3, 0, 60),
     ("treadmill", 3.6, 0, 90), ("rest", 0, 0, 75), ("treadmill", 1.6, 8, 75), ("rest", 0, 0, 90)),
    (("rest", 0, 0, 60), ("treadmill", 1.6, 0, 60), ("treadmill", 3.2, 0, 120), ("rest", 0, 0, 80),
     ("treadmill", 3.8, 0, 90), ("rest", 0, 0, 90), ("treadmill", 1.4, 4, 60), ("rest", 0, 0, 75)),
)


def build_plans(seed: int = 2015) -> tuple[SessionPlan, ...]:
    """The lab's 12 sessions: every participant does one cardio and one strength session (10-12
    minutes), each alternating low and high bouts with recovery. ``seed`` draws the repetition times."""
    plans = []
    for i, person in enumerate(PEOPLE):
        first = FIRST_WEEK + dt.timedelta(days=i // 2, hours=2 * (i % 2), minutes=7 * i)
        second = SECOND_WEEK + dt.timedelta(days=i // 2, hours=-2 * (i % 2), minutes=11 * i)
        kinds = ("cardio", "strength") if i % 2 == 0 else ("strength", "cardio")
        for index, kind, start in ((i, kinds[0], first), (i + len(PEOPLE), kinds[1], second)):
            rng = np.random.default_rng([seed, 2000, index])
            phases = (_cardio(CARDIO_BOUTS[i // 2]) if kind == "cardio"
                      else _strength(_strength_bouts(i), person.mass_kg, rng))
            plans.append(SessionPlan(index, person, kind, start, PROTOCOLS[index], phases))
    return tuple(sorted(plans, key=lambda p: p.index))


def _strength_bouts(i: int) -> list[tuple[str, float, int, float]]:
    """Bodyweight squats, loaded squats and jumping jacks with rests (loads scale with the person);
    every other participant starts with the jumping jacks and ends with a heavy set (about 11 min)."""
    load = round(0.25 * PEOPLE[i].mass_kg / 5) * 5
    if i % 2 == 0:
        return [("rest", 0, 0, 60), ("squats", 0, 15, 38), ("rest", 0, 0, 75), ("squats", load, 12, 35),
                ("rest", 0, 0, 90), ("jacks", 0, 55, 60), ("rest", 0, 0, 90), ("squats", load, 12, 36),
                ("rest", 0, 0, 80), ("jacks", 0, 50, 60), ("rest", 0, 0, 90)]
    return [("rest", 0, 0, 60), ("jacks", 0, 50, 55), ("rest", 0, 0, 80), ("squats", load, 12, 35),
            ("rest", 0, 0, 80), ("squats", 2 * load, 10, 28), ("rest", 0, 0, 90), ("jacks", 0, 55, 60),
            ("rest", 0, 0, 80), ("squats", 2 * load, 10, 30), ("rest", 0, 0, 100)]


def phase_at(plan: SessionPlan, t_s: float) -> Phase | None:
    """The phase in progress at ``t_s`` (None after the end)."""
    return next((p for p in plan.phases if p.start_s <= t_s < p.end_s), None)


def work_at(plan: SessionPlan, t_s: np.ndarray, *, drive: bool = False) -> np.ndarray:
    """Work rate (W/kg) of the plan at times ``t_s``, stepwise by phase (the drive if asked)."""
    t = np.asarray(t_s, dtype=float)
    w = np.full(t.shape, STAND_W_PER_KG)
    for ph in plan.phases:
        w[(t >= ph.start_s) & (t < ph.end_s)] = ph.drive_w_per_kg if drive else ph.w_per_kg
    return w


def strain_at(plan: SessionPlan, t_s: np.ndarray) -> np.ndarray:
    """Muscular strain per repetition (0-1 pulses, one per rep's lifting half, about 1 s), scaled
    by the displaced mass over the working muscle mass (the paper's rule, SCIENCE.md section 6)."""
    t = np.asarray(t_s, dtype=float)
    out = np.zeros(t.shape)
    mass = plan.person.mass_kg
    for ph in plan.phases:
        if not ph.rep_times_s:
            continue
        displaced = (0.7 * mass + ph.load_kg) / mass  # the body above the knees plus the load
        amp = min(1.0, 0.12 * displaced / ph.muscle_fraction)
        for end in ph.rep_times_s:
            x = (t - (end - 0.6)) / 0.6
            out += amp * np.where(np.abs(x) < 1.0, np.cos(0.5 * np.pi * x) ** 2, 0.0)
    return np.clip(out, 0.0, 1.0)
