"""Coupling unknowns and condition rows.

The master solves one condition row per unknown. A row is anything with

    residual                   column of its position level (`<name>.g`), or None
    algebraic                  True if the row is the same on every level (not stabilised)
    levels                     the levels it can evaluate: "position", "velocity", "acceleration"
    reads(level)               the outputs it needs: [(instance, variable, derivative order)]
    value(level, output, u)    its value, with output(instance, variable, order) -> float and
                               u the unknowns at the end of the step being evaluated; level
                               may also be ("stabilised", mu), the explicit method's
                               g'' + 2 g'/mu + g/mu^2

and an unknown is an Unknown: its column, the inputs it drives and its initial
value (None for "consistent").

A `[[constraint]]` is a LinearRow plus an Unknown driving its `drives`
expression; a `[[coupling_variable]]` a VariableRow plus an Unknown; joints
between marker ports (joints.py) add ConditionRows (one per condition, its
multiplier driving nothing or the `multipliers` expressions) and PortRows.
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

    residual = property(lambda self: f"{self.name}.g")
    algebraic = False

    def value(self, level, output, u):
        if isinstance(level, tuple):  # ("stabilised", mu)
            mu = level[1]
            r = self.value("acceleration", output, u)
            r += 2.0 * self.value("velocity", output, u) / mu + self.value("position", output, u) / (mu * mu)
            return r
        return _sum(self.terms[level], output)


def _sum(terms, output):
    total = 0.0
    for t in terms:
        total += t.coefficient * output(t.instance, t.variable, t.order)
    return total


class VariableRow:
    """A `[[coupling_variable]]`: u - value(outputs) = 0 on every level."""

    levels = LEVELS
    algebraic = True
    residual = None

    def __init__(self, name, unknown, value_text):
        self.name = name
        self.unknown = unknown
        self.terms = _parse(name, "value", value_text)

    def reads(self, level):
        return [(t.instance, t.variable, t.order) for t in self.terms]

    def value(self, level, output, u):
        return u[self.unknown] - _sum(self.terms, output)


@dataclass
class Unknown:
    """A coupling unknown: its column, the inputs it drives as
    [(instance, variable, coefficient, derivative order)] and its value at T_0
    (None: "consistent"). `owner` names it in error messages."""

    column: str
    drives: list
    initial: float | None
    owner: str


def drives(owner_name, text, what="drives"):
    terms = _parse(owner_name, what, text)
    return [(t.instance, t.variable, t.coefficient, t.order) for t in terms]


def from_constraint(spec):
    return LinearRow(spec), Unknown(f"{spec.name}.lambda", drives(spec.name, spec.drives), spec.initial,
                                    f"constraint '{spec.name}'")


def _parse(constraint, level, text):
    from errors import RunError

    try:
        return expressions.parse(text)
    except RunError as e:
        raise RunError(f"constraint '{constraint}', {level}: {e}") from None
