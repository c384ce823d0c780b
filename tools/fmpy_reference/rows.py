"""Coupling unknowns and condition rows.

The master solves one condition row per unknown. A row is anything with

    name                       column prefix (`<name>.g` records its position level)
    levels                     the levels it can evaluate: "position", "velocity", "acceleration"
    reads(level)               the outputs it needs: [(instance, variable, derivative order)]
    value(level, output, u)    its value, with output(instance, variable, order) -> float and
                               u the unknowns at the end of the step being evaluated

and an unknown is anything with `name`, `drives` ([(instance, input variable,
coefficient)]) and `initial` (a number, or None for "consistent").

Today the system file has one kind of each: a `[[constraint]]` is a LinearRow (a
linear combination of outputs per level) plus a Multiplier driving the inputs of
its `drives` expression. Joints between marker ports (docs/marker-ports.md) add
rows that are nonlinear in the marker outputs and may depend on u directly, and
unknowns that drive no input; they plug in here without touching the master.
"""

from dataclasses import dataclass

import expressions

LEVELS = ("position", "velocity", "acceleration")


class LinearRow:
    """A `[[constraint]]`: each level is a signed sum of outputs."""

    def __init__(self, spec):
        self.name = spec.name
        self.terms = {}
        for level in LEVELS:
            text = getattr(spec, level)
            if text is not None:
                self.terms[level] = _parse(spec.name, level, text)
        self.levels = tuple(self.terms)

    def reads(self, level):
        return [(t.instance, t.variable, t.order) for t in self.terms[level]]

    def value(self, level, output, u):
        total = 0.0
        for t in self.terms[level]:
            total += t.coefficient * output(t.instance, t.variable, t.order)
        return total


@dataclass
class Multiplier:
    """The multiplier of a `[[constraint]]`: drives `c * lambda` into each input."""

    name: str
    drives: list
    initial: float | None


def from_constraint(spec):
    terms = _parse(spec.name, "drives", spec.drives)
    drives = [(t.instance, t.variable, t.coefficient, t.order) for t in terms]
    return LinearRow(spec), Multiplier(spec.name, drives, spec.initial)


def _parse(constraint, level, text):
    from errors import RunError

    try:
        return expressions.parse(text)
    except RunError as e:
        raise RunError(f"constraint '{constraint}', {level}: {e}") from None
