"""Linear expressions over FMU variables, as written in the system file
(docs/system-file.md, "Expressions"):

    mass2.x - mass1.x
    -0.5*a.r[1] + 2e-1 * b.p.x - der(c.v) + der(c.x, 2)
    m.'odd name'
"""

import re
from dataclasses import dataclass

from errors import RunError

_NUMBER = re.compile(r"[0-9.]([0-9.eE]|(?<=[eE])[+-])*")
_INSTANCE = re.compile(r"[^\W\d]\w*|_\w*")
_VARIABLE = re.compile(r"[\w.\[\]]+")


@dataclass(frozen=True)
class Term:
    coefficient: float
    instance: str
    variable: str
    order: int  # 0: the value, 1 or 2: an output derivative

    def __str__(self):
        ref = f"{self.instance}.{self.variable}"
        return ref if self.order == 0 else (f"der({ref})" if self.order == 1 else f"der({ref}, {self.order})")


class _Reader:
    def __init__(self, text):
        self.text = text
        self.pos = 0

    def fail(self, reason):
        raise RunError(f"cannot read expression '{self.text}': {reason} at column {self.pos + 1}")

    def skip(self):
        while self.pos < len(self.text) and self.text[self.pos].isspace():
            self.pos += 1

    def rest(self):
        return self.text[self.pos:]

    def accept(self, char):
        self.skip()
        if self.rest().startswith(char):
            self.pos += len(char)
            return True
        return False

    def number(self):
        match = _NUMBER.match(self.text, self.pos)
        try:
            value = float(match.group(0)) if match else None
        except ValueError:
            value = None
        if value is None or value != value or value in (float("inf"), float("-inf")):
            self.fail("expected a number")
        self.pos = match.end()
        return value

    def reference(self):
        self.skip()
        match = _INSTANCE.match(self.text, self.pos)
        if not match:
            self.fail("expected an instance name")
        instance = match.group(0)
        self.pos = match.end()
        if not self.rest().startswith("."):
            self.fail(f"expected '.' and a variable after '{instance}'")
        self.pos += 1
        if self.rest().startswith("'"):
            end = self.text.find("'", self.pos + 1)
            if end < 0:
                self.fail("unterminated quoted variable name")
            variable = self.text[self.pos + 1 : end]
            self.pos = end + 1
            return instance, variable
        match = _VARIABLE.match(self.text, self.pos)
        if not match:
            self.fail("expected a variable name")
        self.pos = match.end()
        return instance, match.group(0)

    def term(self, sign):
        self.skip()
        coefficient = sign
        if self.rest()[:1].isdigit() or self.rest().startswith("."):
            coefficient *= self.number()
            if not self.accept("*"):
                self.fail("expected '*' after a coefficient")
            self.skip()
        if self.rest().startswith("der("):
            self.pos += 4
            instance, variable = self.reference()
            order = 1
            if self.accept(","):
                self.skip()
                at = self.pos
                n = self.number()
                if n not in (1.0, 2.0):
                    self.pos = at
                    self.fail("derivative order must be 1 or 2")
                order = int(n)
            if not self.accept(")"):
                self.fail("expected ')'")
            return Term(coefficient, instance, variable, order)
        instance, variable = self.reference()
        return Term(coefficient, instance, variable, 0)

    def expression(self):
        self.skip()
        if not self.rest():
            self.fail("expected at least one term")
        sign = -1.0 if self.accept("-") else 1.0
        if sign > 0:
            self.accept("+")
        terms = []
        while True:
            terms.append(self.term(sign))
            self.skip()
            if not self.rest():
                return terms
            if self.accept("+"):
                sign = 1.0
            elif self.accept("-"):
                sign = -1.0
            else:
                self.fail("expected '+' or '-'")


def parse(text):
    """The terms of a linear expression, in the order written."""
    return _Reader(text).expression()
