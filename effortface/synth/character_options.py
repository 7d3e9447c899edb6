"""The character options shared by ``effortface synth`` and ``effortface serve`` (argparse).

Command modules only parse and print; the options and their checks live here so that two commands
take the same ``--age --sex --height --mass --training-level --expressiveness --load-*`` flags.
"""

from __future__ import annotations

import argparse

from effortface.core.errors import UserError
from effortface.synth.runtime import Character, FaceModel


def add_character_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the character options (defaults: a 30-year-old male, 1.78 m, 75 kg, TL 5)."""
    parser.add_argument("--age", type=float, default=30.0, help="years (default 30)")
    parser.add_argument("--sex", default="male", help="male or female (default male)")
    parser.add_argument("--height", type=float, default=1.78, metavar="M", help="metres (default 1.78)")
    parser.add_argument("--mass", type=float, default=75.0, metavar="KG", help="kilograms (default 75)")
    parser.add_argument("--training-level", type=float, default=5.0, metavar="TL",
                        help="0-10 (default 5)")
    parser.add_argument("--expressiveness", default=None, metavar="A,B,C,D",
                        help="one factor per blendshape (default all 1)")
    parser.add_argument("--load-left", type=float, default=0.0, metavar="KG", help="left hand")
    parser.add_argument("--load-right", type=float, default=0.0, metavar="KG", help="right hand")
    parser.add_argument("--load-back", type=float, default=0.0, metavar="KG", help="on the back")


def _expressiveness(text: str | None, n: int) -> tuple[float, ...]:
    if text is None:
        return (1.0,) * n
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--expressiveness: expected {n} comma-separated numbers, found {text!r}") from None


def character_from_args(args: argparse.Namespace, model: FaceModel) -> Character:
    """The :class:`Character` of the parsed options, checked against ``model``'s blendshapes.

    Raises
    ------
    UserError
        ``character options: ...`` naming the bad field.
    """
    try:
        character = Character(age=args.age, sex=args.sex, height_m=args.height, mass_kg=args.mass,
                              training_level=args.training_level,
                              expressiveness=_expressiveness(args.expressiveness, len(model.blendshapes)),
                              load_left_kg=args.load_left, load_right_kg=args.load_right,
                              load_back_kg=args.load_back)
        model.expressiveness(character)
    except UserError as exc:
        raise UserError(f"character options: {exc}") from None
    return character
