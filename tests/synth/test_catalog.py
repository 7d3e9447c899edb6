"""The exercise catalog against SCIENCE.md's W/kg table and the real clips it was calibrated on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from effortface.synth.catalog import CATALOG_CSV, CatalogError, default_catalog, read_catalog
from effortface.synth.energy import work_and_power
from effortface.synth.exercise_log import PhaseState
from effortface.synth.motion import read_motion
from effortface.synth.segments import Loads, build_body

MASS_KG = 72.0
#: SCIENCE.md section 2 (W/kg), and the condition each reference clip shows
REFERENCE = {
    "rest": (0.1, PhaseState()),
    "treadmill_walk": (4.2, PhaseState(speed_m_s=1.5)),
    "treadmill_run": (20.5, PhaseState(speed_m_s=3.4)),
    "jumping_jacks": (8.6, PhaseState()),  # at the clip's own pace (the catalog's reference pace)
    "squats": (3.4, PhaseState()),
    "hopping": (6.8, PhaseState()),
}


def _loads(back: float = 0.0, left: float = 0.0, right: float = 0.0) -> tuple[tuple[str, float], ...]:
    return (("back_kg", back), ("left_kg", left), ("right_kg", right), ("machine_kg", 0.0))


@pytest.mark.parametrize("exercise", REFERENCE)
def test_catalog_against_the_reference_table(exercise: str) -> None:
    """Within 10 % of SCIENCE.md's table (a faithful implementation lands within 25 %)."""
    expected, state = REFERENCE[exercise]
    assert default_catalog().work_per_kg(exercise, state, MASS_KG) == pytest.approx(expected, rel=0.10)


def test_treadmill_picks_walk_or_run_by_speed() -> None:
    cat = default_catalog()
    assert cat.work_per_kg("treadmill", PhaseState(speed_m_s=1.5), MASS_KG) == \
        cat.work_per_kg("treadmill_walk", PhaseState(speed_m_s=1.5), MASS_KG)
    assert cat.work_per_kg("treadmill", PhaseState(speed_m_s=3.4), MASS_KG) == pytest.approx(20.5, rel=0.1)


def _clip_w(shared_data: Path, clip: str, start_s: float, stop_s: float, loads: Loads = Loads()) -> float:
    motion = read_motion(shared_data / "motion" / clip)
    body = build_body(motion.joint_names, motion.parents, MASS_KG, "male", loads=loads,
                      reference_positions_m=motion.positions_m)
    curves = work_and_power(motion, body)
    keep = (curves.t_s >= start_s) & (curves.t_s < stop_s)
    return float(curves.w_per_kg[keep].mean())


CLIPS = {  # exercise -> clip, steady part (as tests/synth/test_energy.py), logged state, loads
    "walk, 10 kg backpack": ("treadmill_walk", "amp_humanoid_walk.npz", 1.0, np.inf,
                             PhaseState(speed_m_s=1.53, loads_kg=_loads(back=10)), Loads(0, 0, 10)),
    "run": ("treadmill_run", "amp_humanoid_run.npz", 1.0, np.inf, PhaseState(speed_m_s=3.45), Loads()),
    "jumping jacks, 5 kg per hand": ("jumping_jacks", "cmu_13_29_jumping_jacks_120fps.bvh", 1.0, np.inf,
                                     PhaseState(loads_kg=_loads(left=5, right=5)), Loads(5, 5, 0)),
    "squats, 15 kg on the back": ("squats", "cmu_13_29_squats_120fps.bvh", 1.3, 5.8,
                                  PhaseState(loads_kg=_loads(back=15)), Loads(0, 0, 15)),
}


@pytest.mark.parametrize("case", CLIPS)
def test_catalog_against_the_clips_with_loads(shared_data: Path, case: str) -> None:
    """The catalog's estimate (with its load factors) against effortface.synth.energy on the real clip."""
    exercise, clip, start, stop, state, loads = CLIPS[case]
    measured = _clip_w(shared_data, clip, start, stop, loads)
    assert default_catalog().work_per_kg(exercise, state, MASS_KG) == pytest.approx(measured, rel=0.10)


def test_pace_speed_grade_and_power_scale_it() -> None:
    cat = default_catalog()
    slow = cat.work_per_kg("squats", PhaseState(reps_per_min=10), MASS_KG)
    assert cat.work_per_kg("squats", PhaseState(reps_per_min=20), MASS_KG) == pytest.approx(2 * slow)
    assert cat.work_per_kg("squats", PhaseState(cadence_per_min=20, reps_per_min=10), MASS_KG) == \
        pytest.approx(2 * slow)  # a logged cadence wins over the reps' pace
    flat = cat.work_per_kg("treadmill", PhaseState(speed_m_s=1.5), MASS_KG)
    uphill = cat.work_per_kg("treadmill", PhaseState(speed_m_s=1.5, grade_pct=10), MASS_KG)
    assert uphill - flat == pytest.approx(9.81 * 1.5 * 0.10)
    w150 = cat.work_per_kg("cycle_ergometer", PhaseState(power_w=150, cadence_per_min=80), MASS_KG)
    w300 = cat.work_per_kg("cycle_ergometer", PhaseState(power_w=300, cadence_per_min=80), MASS_KG)
    assert w300 - w150 == pytest.approx(150 / MASS_KG)
    light = cat.work_per_kg("strength_machine", PhaseState(rom_m=0.5, loads_kg=(("machine_kg", 20.0),)), MASS_KG)
    heavy = cat.work_per_kg("strength_machine", PhaseState(rom_m=0.5, loads_kg=(("machine_kg", 40.0),)), MASS_KG)
    assert heavy - light == pytest.approx(15 / 60 * 2 * 9.81 * 20 * 0.5 / MASS_KG)


def test_every_entry_estimates_a_plausible_w() -> None:
    cat = default_catalog()
    state = PhaseState(speed_m_s=1.5, power_w=150, cadence_per_min=60, loads_kg=_loads(back=10))
    for exercise in cat.entries:
        assert 0.05 <= cat.work_per_kg(exercise, state, MASS_KG) < 40, exercise
        assert cat[exercise].source.strip(), f"{exercise}: no source"
    required = {"rest", "treadmill_walk", "treadmill_run", "cycle_ergometer", "rowing_ergometer",
                "stair_climber", "elliptical", "jumping_jacks", "squats", "lunges", "push_ups", "burpees",
                "strength_machine", "free_weights"}
    assert required <= set(cat.entries)


def test_unknown_exercise_and_missing_parameter_name_the_catalog() -> None:
    cat = default_catalog()
    with pytest.raises(CatalogError, match=rf"exercise 'zumba': expected an id of the catalog {CATALOG_CSV} \(rest, "):
        cat.work_per_kg("zumba", PhaseState(), MASS_KG)
    with pytest.raises(CatalogError, match=r"exercise 'cycle_ergometer' \(ergometer in .*exercise_catalog.csv\): "
                                           r"expected a power row \(W\) in the exercise log, found none"):
        cat.work_per_kg("cycle_ergometer", PhaseState(), MASS_KG)


def test_a_bad_catalog_file_is_named(tmp_path: Path) -> None:
    text = CATALOG_CSV.read_text(encoding="utf-8").replace("squats,,reps,3.47", "squats,,pilates,3.47")
    (tmp_path / "cat.csv").write_text(text, encoding="utf-8")
    with pytest.raises(CatalogError, match=r"cat.csv: row \d+: model: expected one of constant, .* found 'pilates'"):
        read_catalog(tmp_path / "cat.csv")
