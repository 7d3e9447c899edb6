"""The participant record and a person's limits, in one place (stdlib only: the runtime imports it).

Every place that takes a person's body data reads :data:`LIMITS`: the Capture form's spin boxes,
``session.json`` (:class:`Participant`), the training table check
(``effortface.train.dataset.check_participants``) and the runtime's ``Character``. A value inside
the limits is accepted by all of them, a value outside is refused by all of them.

The limits (choice, documented in the guide, docs/guide/capture.md, "Capturing, replaying and recovering"):

============== ================ ===================================================================
field          range            why
============== ================ ===================================================================
age            10-100 years     HR_max = 208 - 0.7 age (Tanaka) and the VO2max regression are adult
                                models; beyond 100 the VO2max regression heads below zero
height_m       0.5-2.6 m        a child to the tallest people measured; catches centimetres (178)
mass_kg        15-300 kg        catches grams and pounds-as-kg typos; the divisor of w and p
training_level 0-10             0 sedentary ... 10; the paper's participants span 0-7.5 (the resting-
                                HR chart, clamped above 7.5) and its Fig. 5 animates TL 10; at TL 10
                                the paper's c_inc is still positive
hr_rest_bpm    25-120 bpm       measured resting HR (optional): athletes to tachycardia
hr_max_bpm     100-240 bpm      measured maximal HR (optional); must be above hr_rest_bpm
============== ================ ===================================================================
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
import types
from collections.abc import Mapping
from typing import Any

from effortface.core.errors import UserError, json_type


@dataclasses.dataclass(frozen=True)
class Limit:
    """The accepted range of one body field.

    Attributes
    ----------
    lo, hi : float
        Smallest and largest accepted value (both included).
    unit : str
        Unit for messages and spin-box suffixes (``"years"``, ``"m"``; ``""`` for none).
    meaning : str
        What the field is, for tool tips and documentation.
    """

    lo: float
    hi: float
    unit: str
    meaning: str

    @property
    def bounds(self) -> tuple[float, float]:
        """``(lo, hi)``."""
        return (self.lo, self.hi)

    def expected(self) -> str:
        """The message's expectation, e.g. ``"a number from 10 to 100 years"``."""
        return f"a number from {self.lo:g} to {self.hi:g}{' ' + self.unit if self.unit else ''}"

    def accepts(self, value: object) -> bool:
        """Whether ``value`` is a finite real number (not a bool) within the limits."""
        return (isinstance(value, numbers.Real) and not isinstance(value, bool)
                and math.isfinite(float(value)) and self.lo <= float(value) <= self.hi)


#: The one limits table (read-only): field name -> :class:`Limit`. See the module docstring.
LIMITS: Mapping[str, Limit] = types.MappingProxyType({
    "age": Limit(10.0, 100.0, "years", "age in years"),
    "height_m": Limit(0.5, 2.6, "m", "body height"),
    "mass_kg": Limit(15.0, 300.0, "kg", "body mass (the divisor of work and power)"),
    "training_level": Limit(0.0, 10.0, "", "training level TL: 0 = sedentary ... 7.5 = athlete "
                                           "(the paper's participants) ... 10"),
    "hr_rest_bpm": Limit(25.0, 120.0, "bpm", "measured resting heart rate (overrides the chart)"),
    "hr_max_bpm": Limit(100.0, 240.0, "bpm", "measured maximal heart rate (overrides the formula)"),
})

#: Sex names, in the order forms offer them.
SEXES = ("female", "male")
#: Accepted spellings (after strip and lower case) -> sex name.
SEX_ALIASES: Mapping[str, str] = types.MappingProxyType(
    {"f": "female", "m": "male", "female": "female", "male": "male"})
#: Participant codes: a capital letter, then capitals / digits / '-', 2-16 characters, with a digit.
CODE_RULE = "a capital letter then capitals, digits or '-' (2-16 characters, at least one digit), e.g. P01"
#: The code pattern (the digit is checked apart); session ids embed it.
CODE_PATTERN = r"[A-Z][A-Z0-9-]{1,15}"
_CODE_RE = re.compile(CODE_PATTERN)  # used with fullmatch: "P01\n" is refused


def check_limit(name: str, value: object, label: str = "") -> float:
    """Return ``value`` as float if :data:`LIMITS` ``[name]`` accepts it, else raise.

    Parameters
    ----------
    name : str
        A key of :data:`LIMITS` (``"age"``, ``"height_m"``...).
    value : object
        The candidate.
    label : str
        Prefix of the message's subject (``"participant "`` gives ``participant age: ...``).

    Returns
    -------
    float

    Raises
    ------
    UserError
        ``<label><name>: expected a number from <lo> to <hi> <unit>, found <value>``.
    """
    limit = LIMITS[name]
    if not limit.accepts(value):
        raise UserError(f"{label}{name}: expected {limit.expected()}, found {value!r}")
    return float(value)  # type: ignore[arg-type]  # accepts() checked it is a real number


def check_sex(value: object, label: str = "") -> str:
    """Return the sex name (``"female"`` or ``"male"``) for ``value`` or an alias (``"F"``, ``"m"``).

    Raises
    ------
    UserError
        ``<label>sex: expected one of female, male, found <value>``.
    """
    sex = SEX_ALIASES.get(str(value).strip().lower()) if isinstance(value, str) else None
    if sex is None:
        raise UserError(f"{label}sex: expected one of {', '.join(SEXES)}, found {value!r}")
    return sex


def check_participant_code(code: str) -> str:
    """Return ``code`` if it is a valid participant code, else raise.

    Parameters
    ----------
    code : str
        Candidate code.

    Raises
    ------
    UserError
        If it does not follow :data:`CODE_RULE` (names such as ``"Jane Doe"`` or ``"jane"`` fail:
        they have spaces, lower case letters or no digit).
    """
    if not isinstance(code, str) or not _CODE_RE.fullmatch(code) or not any(c.isdigit() for c in code):
        raise UserError(f"participant code: expected {CODE_RULE} (codes, never names), found {code!r}")
    return code


@dataclasses.dataclass(frozen=True)
class Participant:
    """Who was recorded: a code (never a name) and the body data the models need.

    Every body field is optional (None: not recorded) and checked against :data:`LIMITS`.

    Attributes
    ----------
    code : str
        Pseudonymous code, see :data:`CODE_RULE` (``P01``, ``LAB2-07``).
    sex : str or None
        ``"female"`` or ``"male"`` (``"f"``/``"m"`` accepted), None if not recorded.
    age : float or None
        Years, 10-100.
    height_m, mass_kg : float or None
        Body height (0.5-2.6 m) and mass (15-300 kg).
    training_level : float or None
        Training level TL, 0 (sedentary) to 10.
    hr_rest_bpm, hr_max_bpm : float or None
        Measured resting (25-120) / maximal (100-240) heart rate; they override the charts.
    """

    code: str
    sex: str | None = None
    age: float | None = None
    height_m: float | None = None
    mass_kg: float | None = None
    training_level: float | None = None
    hr_rest_bpm: float | None = None
    hr_max_bpm: float | None = None

    def __post_init__(self) -> None:
        check_participant_code(self.code)
        if self.sex is not None:
            object.__setattr__(self, "sex", check_sex(self.sex, "participant "))
        for name in LIMITS:
            if getattr(self, name) is not None:
                check_limit(name, getattr(self, name), "participant ")
        if self.hr_rest_bpm is not None and self.hr_max_bpm is not None and self.hr_rest_bpm >= self.hr_max_bpm:
            raise UserError(
                f"participant hr_rest_bpm: expected below hr_max_bpm ({self.hr_max_bpm}), found {self.hr_rest_bpm}"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (optional measured HR keys only when set)."""
        out = dataclasses.asdict(self)
        for key in ("hr_rest_bpm", "hr_max_bpm"):
            if out[key] is None:
                del out[key]
        return out

    @classmethod
    def from_dict(cls, data: object) -> Participant:
        """Build from a ``session.json`` ``participant`` object.

        Raises
        ------
        UserError
            Not an object, unknown keys, no ``code`` or a field out of :data:`LIMITS` (the message
            names the problem).
        """
        if not isinstance(data, dict):
            raise UserError(f"participant: expected a JSON object, found {json_type(data)}")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise UserError(f"participant: expected keys among {sorted(names)}, found {sorted(unknown)}")
        if "code" not in data:
            raise UserError(f"participant: expected the key 'code', found only {sorted(data)}")
        return cls(**data)
