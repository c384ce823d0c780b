"""The system file (docs/system-file.md), read with tomllib and checked the way
`tether run` checks it: unknown keys are errors, values must have the right type
and range, relative `fmu` paths are resolved against the file's folder."""

import decimal
import math
import os
import re
import tomllib
from dataclasses import dataclass, field

from errors import RunError

# The integrator methods of a model-exchange instance a system file may name
# (Tether's); the reference integrates with CVode whichever is named.
METHODS = ("bdf", "esdirk", "rk45", "dop853")


@dataclass
class Method:
    kind: str  # "baumgarte" | "weighted" | "explicit"
    beta: float = 0.0
    gamma: float = 0.0
    a: float = 0.0
    b: float = 0.0
    mu: float = 0.0

    def needs_velocity(self):
        return {"baumgarte": self.beta > 0, "weighted": self.a > 0, "explicit": True}[self.kind]

    def needs_acceleration(self):
        return {"baumgarte": self.gamma > 0, "weighted": self.b > 0, "explicit": True}[self.kind]

    def index(self):
        if self.kind == "explicit":
            return 1
        return 1 if self.needs_acceleration() else (2 if self.needs_velocity() else 3)

    def describe(self):
        if self.kind == "baumgarte":
            return f"baumgarte (index {self.index()}, beta = {self.beta:e}, gamma = {self.gamma:e})"
        if self.kind == "weighted":
            return f"weighted (index {self.index()}, a = {self.a}, b = {self.b})"
        return f"explicit (mu = {self.mu:e})"


@dataclass
class Instance:
    name: str
    fmu: str
    parameters: dict = field(default_factory=dict)
    # "auto" | "co_simulation" | "model_exchange" (`fmi_type`, any accepted spelling).
    fmi_type: str = "auto"
    # `integrator = { method, rtol, atol, max_step }` of a model-exchange instance.
    integrator: dict = field(default_factory=dict)


# Every spelling of `fmi_type`: Tether's and fmpy's.
FMI_TYPES = {"auto": "auto", "any": "auto", "co_simulation": "co_simulation", "CoSimulation": "co_simulation",
             "model_exchange": "model_exchange", "ModelExchange": "model_exchange",
             "model-exchange": "model_exchange"}


def _integrator(name, raw):
    t = _Table(f"instance '{name}': integrator", raw)
    method = t.take("method", "string", None)
    if method is not None and method not in METHODS:
        raise RunError(f"instance '{name}': integrator: method = \"{method}\": unknown "
                       f"(known: {', '.join(METHODS)})")
    settings = {"method": method}
    for key in ("rtol", "atol", "max_step"):
        v = t.take(key, "number", None)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise RunError(f"instance '{name}': integrator: {key} = {_number(v)}: expected a finite number > 0")
        settings[key] = v
    t.done()
    return settings


@dataclass
class Constraint:
    name: str
    position: str
    velocity: str | None
    acceleration: str | None
    drives: str
    initial: float | None  # None: "consistent"


@dataclass
class JointSpec:
    name: str
    kind: str
    i: str
    j: str
    plane: str | None = None
    axis_i: tuple | None = None
    ref_i: tuple | None = None
    axis_j: tuple | None = None
    ref_j: tuple | None = None
    offset_i: tuple | None = None
    offset_j: tuple | None = None
    multipliers: list | None = None
    initial: list | None = None  # None: "consistent"


@dataclass
class ConnectionSpec:
    """A `[[connection]]`: `from` output to `to` input, as gain*y + offset."""

    frm: str
    to: str
    gain: float | None = None
    offset: float | None = None


@dataclass
class VariableSpec:
    name: str
    drives: str
    value: str
    initial: float | None  # None: "consistent"


# Tether's default `[coupling] residual_limit`.
RESIDUAL_LIMIT = 1.0


@dataclass
class System:
    name: str | None
    start: float
    stop: float
    step: float
    tolerance: float | None
    method: Method
    order: int = 0
    epsilon: float = 1e-5
    max_condition: float = 1e12
    divergence_factor: float = 1e6
    # `[coupling] residual_limit`: a larger |g| at an accepted point fails the
    # run (None: "off"); Tether's default (docs/system-file.md).
    residual_limit: float | None = RESIDUAL_LIMIT
    iterations: int = 1
    iteration_tol: float = 1e-10
    jacobian: str = "every_step"
    jacobian_max_age: int = 20
    step_control: dict | None = None  # rtol, atol, h_min, h_max, h_initial (None: default)
    instances: list = field(default_factory=list)
    constraints: list = field(default_factory=list)
    joints: list = field(default_factory=list)
    variables: list = field(default_factory=list)
    connections: list = field(default_factory=list)
    # `[signals]`: "jacobi" or "gauss_seidel"; the loops' relative tolerance.
    scheme: str = "jacobi"
    signal_tolerance: float = 1e-10
    # `[signals] iterations`, `solver` ("fixed_point" or "newton"), `strict`.
    signal_iterations: int = None
    signal_solver: str = "fixed_point"
    signal_strict: bool = False

    def macro_steps(self):
        """(stop - start)/step rounded half away from zero, at least 1."""
        x = (self.stop - self.start) / self.step
        n = math.floor(x)
        if x - n >= 0.5:
            n += 1
        return max(int(n), 1)


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class _Table:
    """A TOML table whose keys are consumed; leftovers are unknown keys."""

    def __init__(self, where, table):
        if not isinstance(table, dict):
            raise RunError(f"{where}: expected a table")
        self.where = where
        self.table = dict(table)

    def take(self, key, kind, default=..., required=False):
        if key not in self.table:
            if required or default is ...:
                raise RunError(f"{self.where}: missing key `{key}`")
            return default
        value = self.table.pop(key)
        if kind == "number":
            if not _is_number(value):
                raise RunError(f"{self.where}: `{key}` must be a number, found {value!r}")
            return float(value)
        if kind == "integer":
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise RunError(f"{self.where}: `{key}` must be a non-negative integer, found {value!r}")
            return value
        if kind == "string":
            if not isinstance(value, str):
                raise RunError(f"{self.where}: `{key}` must be a string, found {value!r}")
            return value
        return value

    def done(self):
        if self.table:
            key = sorted(self.table)[0]
            raise RunError(f"{self.where}: unknown key `{key}`")


# The weights an explicit index gives when none are written (docs/system-file.md).
DEFAULT_WEIGHTS = {
    ("baumgarte", 1): (2e-3, 1e-6), ("baumgarte", 2): (2e-3, 0.0), ("baumgarte", 3): (0.0, 0.0),
    ("weighted", 1): (1.0, 1.0), ("weighted", 2): (1.0, 0.0), ("weighted", 3): (0.0, 0.0),
}
WEIGHT_NAMES = {"baumgarte": ("beta", "gamma"), "weighted": ("a", "b")}


def _number(x):
    """A float as Rust prints it: 1 not 1.0, 0.000001 not 1e-06."""
    if not math.isfinite(x):
        return {math.inf: "inf", -math.inf: "-inf"}.get(x, "NaN")
    if x == int(x):
        return str(int(x))
    return format(decimal.Decimal(repr(x)), "f")


def at_index(kind, index, given, flags=False):
    """The (velocity, acceleration) weights of method 1 or 2: without an index, those
    given or 0; with one, those not given take its defaults and a given one must fit
    it. `given` holds floats or None."""
    if index is None:
        return tuple(0.0 if w is None else w for w in given)

    def key(name, value):
        return f"--{name} {value}" if flags else f"{name} = {value}"

    if index not in (1, 2, 3):
        raise RunError(f"{key('index', index)}: expected 1, 2 or 3")
    v, a = WEIGHT_NAMES[kind]
    means = {3: f"{v} = {a} = 0", 2: f"{v} > 0 and {a} = 0", 1: f"{v} > 0 and {a} > 0"}[index]
    chosen = list(DEFAULT_WEIGHTS[(kind, index)])
    for level, w in enumerate(given):
        if w is None:
            continue
        used = index <= 2 - level
        if not (w > 0 if used else w == 0):
            raise RunError(f"{key('index', index)} contradicts {key(WEIGHT_NAMES[kind][level], _number(w))}: "
                           f"index {index} means {means}")
        chosen[level] = w
    return tuple(chosen)


def _method(raw):
    if raw is None:
        return Method("baumgarte")
    t = _Table("[method]", raw)
    kind = t.take("kind", "string", required=True)
    if kind in ("baumgarte", "weighted"):
        index = t.take("index", "integer", None)
        given = tuple(t.take(name, "number", None) for name in WEIGHT_NAMES[kind])
        w = at_index(kind, index, given)
        m = Method(kind, beta=w[0], gamma=w[1]) if kind == "baumgarte" else Method(kind, a=w[0], b=w[1])
    elif kind == "explicit":
        m = Method(kind, mu=t.take("mu", "number", required=True))
    else:
        raise RunError(f"[method]: unknown kind `{kind}`, expected baumgarte, weighted or explicit")
    t.done()
    return m


def read(path):
    """Read and check a system file; FMU paths come back resolved."""
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except OSError as e:
        raise RunError(f"system file {path}: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise RunError(f"system file {path}: {e}") from None
    try:
        system = _from_document(doc)
    except RunError as e:
        raise RunError(f"system file {path}: {e}") from None
    base = os.path.dirname(path)
    for inst in system.instances:
        if not os.path.isabs(inst.fmu):
            inst.fmu = os.path.join(base, inst.fmu)
    return system


def _from_document(doc):
    top = _Table("top level", doc)
    name = top.take("name", "string", None)
    exp = _Table("[experiment]", top.take("experiment", "table", required=True))
    system = System(
        name=name,
        start=exp.take("start", "number", 0.0),
        stop=exp.take("stop", "number", required=True),
        step=exp.take("step", "number", required=True),
        tolerance=exp.take("tolerance", "number", None),
        method=_method(top.take("method", "table", None)),
    )
    exp.done()
    coupling = _Table("[coupling]", top.take("coupling", "table", {}))
    system.order = coupling.take("order", "integer", 0)
    system.epsilon = coupling.take("epsilon", "number", 1e-5)
    system.max_condition = coupling.take("max_condition", "number", 1e12)
    system.divergence_factor = coupling.take("divergence_factor", "number", 1e6)
    limit = coupling.take("residual_limit", "any", RESIDUAL_LIMIT)
    if limit == "off":
        system.residual_limit = None
    elif _is_number(limit) and math.isfinite(limit) and limit > 0:
        system.residual_limit = float(limit)
    else:
        raise RunError(f"[coupling]: `residual_limit` must be a finite number > 0 or \"off\", found {limit!r}")
    system.iterations = coupling.take("iterations", "integer", 1)
    system.iteration_tol = coupling.take("iteration_tol", "number", 1e-10)
    system.jacobian = coupling.take("jacobian", "string", "every_step")
    system.jacobian_max_age = coupling.take("jacobian_max_age", "integer", 20)
    coupling.done()
    if "step_control" in top.table:
        control = _Table("[step_control]", top.take("step_control", "table"))
        system.step_control = {key: control.take(key, "number", default)
                               for key, default in [("rtol", 1e-4), ("atol", 1e-6), ("h_min", None),
                                                    ("h_max", None), ("h_initial", None)]}
        control.done()
    for i, raw in enumerate(top.take("instance", "array", required=True)):
        t = _Table(f"[[instance]] {i + 1}", raw)
        inst = Instance(t.take("name", "string", required=True), t.take("fmu", "string", required=True))
        params = t.take("parameters", "table", {})
        if not isinstance(params, dict):
            raise RunError(f"instance '{inst.name}': `parameters` must be a table")
        for key, value in params.items():
            if not isinstance(value, (bool, int, float, str)):
                raise RunError(f"instance '{inst.name}': parameter `{key}` must be a number, boolean or string")
        inst.parameters = params
        fmi_type = t.take("fmi_type", "string", "auto")
        if fmi_type not in FMI_TYPES:
            raise RunError(f"instance '{inst.name}': fmi_type = \"{fmi_type}\": expected \"auto\", "
                           f"\"co_simulation\" or \"model_exchange\"")
        inst.fmi_type = FMI_TYPES[fmi_type]
        integrator = t.take("integrator", "table", None)
        if integrator is not None:
            inst.integrator = _integrator(inst.name, integrator)
            if inst.fmi_type == "co_simulation":
                raise RunError(f"instance '{inst.name}': integrator: applies to model exchange, "
                               f"and fmi_type is \"co_simulation\"")
        t.done()
        system.instances.append(inst)
    for i, raw in enumerate(top.take("constraint", "array", [])):
        t = _Table(f"[[constraint]] {i + 1}", raw)
        initial = t.take("initial", "raw", "consistent")
        if _is_number(initial):
            initial = float(initial)
        elif initial == "consistent":
            initial = None
        else:
            raise RunError(f"initial must be a number or \"consistent\", found {initial!r}")
        system.constraints.append(
            Constraint(
                name=t.take("name", "string", required=True),
                position=t.take("position", "string", required=True),
                velocity=t.take("velocity", "string", None),
                acceleration=t.take("acceleration", "string", None),
                drives=t.take("drives", "string", required=True),
                initial=initial,
            )
        )
        t.done()
    for i, raw in enumerate(top.take("joint", "array", [])):
        t = _Table(f"[[joint]] {i + 1}", raw)
        joint = JointSpec(t.take("name", "string", required=True), t.take("kind", "string", required=True),
                          t.take("i", "string", required=True), t.take("j", "string", required=True),
                          plane=t.take("plane", "string", None))
        for key in ("axis_i", "ref_i", "axis_j", "ref_j", "offset_i", "offset_j"):
            value = t.take(key, "raw", None)
            if value is not None:
                if not isinstance(value, list) or len(value) != 3 or not all(_is_number(x) for x in value):
                    raise RunError(f"joint '{joint.name}': `{key}` must be three numbers, found {value!r}")
                if not all(math.isfinite(x) for x in value):
                    raise RunError(f"joint '{joint.name}': `{key}` must be finite, found {value!r}")
                setattr(joint, key, tuple(float(x) for x in value))
        multipliers = t.take("multipliers", "raw", None)
        if multipliers is not None:
            if not isinstance(multipliers, list) or not all(isinstance(x, str) for x in multipliers):
                raise RunError(f"joint '{joint.name}': `multipliers` must be a list of expressions")
            joint.multipliers = multipliers
        initial = t.take("initial", "raw", "consistent")
        if isinstance(initial, list) and all(_is_number(x) for x in initial):
            joint.initial = [float(x) for x in initial]
        elif initial != "consistent":
            raise RunError(f"initial must be a list of numbers or \"consistent\", found {initial!r}")
        t.done()
        system.joints.append(joint)
    for i, raw in enumerate(top.take("coupling_variable", "array", [])):
        t = _Table(f"[[coupling_variable]] {i + 1}", raw)
        initial = t.take("initial", "raw", "consistent")
        if _is_number(initial):
            initial = float(initial)
        elif initial == "consistent":
            initial = None
        else:
            raise RunError(f"initial must be a number or \"consistent\", found {initial!r}")
        system.variables.append(VariableSpec(t.take("name", "string", required=True),
                                             t.take("drives", "string", required=True),
                                             t.take("value", "string", required=True), initial))
        t.done()
    for i, raw in enumerate(top.take("connection", "array", [])):
        t = _Table(f"[[connection]] {i + 1}", raw)
        system.connections.append(ConnectionSpec(t.take("from", "string", required=True),
                                                 t.take("to", "string", required=True),
                                                 t.take("gain", "number", None), t.take("offset", "number", None)))
        t.done()
    raw_signals = top.take("signals", "table", {})
    signals = _Table("[signals]", raw_signals)
    system.scheme = signals.take("scheme", "string", "jacobi")
    if system.scheme not in ("jacobi", "gauss_seidel"):
        raise RunError(f"[signals]: unknown scheme `{system.scheme}`, expected jacobi or gauss_seidel")
    system.signal_tolerance = signals.take("tolerance", "number", 1e-10)
    # Iterated steps: at most `iterations` repetitions (fixed point) or
    # Newton updates per macro step; None runs each step once.
    system.signal_iterations = signals.take("iterations", "integer", None)
    solver = signals.take("solver", "string", None)
    if solver not in (None, "fixed_point", "newton"):
        raise RunError(f"[signals]: unknown solver `{solver}`, expected fixed_point or newton")
    if solver == "newton" and "scheme" in raw_signals:
        raise RunError("[signals] scheme does not apply with solver = \"newton\": Newton updates every "
                       "connection's value at once; remove the scheme key")
    system.signal_solver = solver or "fixed_point"
    strict = signals.take("strict", "boolean", False)
    if not isinstance(strict, bool):
        raise RunError(f"[signals]: `strict` must be true or false, found {strict!r}")
    system.signal_strict = strict
    n = system.signal_iterations
    if n == 0:
        raise RunError("[signals] iterations = 0: give the most repetitions of a macro step (at least 1), "
                       "or leave the key out to run each step once")
    if n is not None and not system.connections:
        raise RunError("[signals] iterations: the system has no [[connection]] whose values could be iterated")
    if n is None and (solver is not None or strict):
        raise RunError(f"[signals] {'strict' if strict else 'solver'} needs iterations = N (the most "
                       f"repetitions or Newton updates per macro step)")
    signals.done()
    # [export] declares the interface of `tether fmu export`: nothing to run.
    top.take("export", "table", None)
    top.done()
    return system


_NAME = re.compile(r"[^\W\d]\w*|_\w*")


def check(system):
    """What can be checked without the FMUs (after command-line overrides)."""

    def invalid(name, value, expected):
        return RunError(f"invalid {name} = {value}: expected {expected}")

    finite = math.isfinite
    if system.signal_iterations is not None and system.step_control is not None:
        raise RunError("[signals] iterations: not available with [step_control] (adaptive steps); use a "
                       "fixed macro step")
    if not finite(system.start):
        raise invalid("start", system.start, "a finite start time")
    if not finite(system.step) or system.step <= 0:
        raise invalid("step", system.step, "a finite macro-step size > 0")
    if not finite(system.stop) or system.stop <= system.start:
        raise invalid("stop", system.stop, "a finite stop time after the start time")
    if system.tolerance is not None and (not finite(system.tolerance) or system.tolerance <= 0):
        raise invalid("tolerance", system.tolerance, "a finite tolerance > 0")
    m = system.method
    params = {"baumgarte": [("beta", m.beta), ("gamma", m.gamma)], "weighted": [("a", m.a), ("b", m.b)]}
    for pname, value in params.get(m.kind, []):
        if not finite(value) or value < 0:
            raise invalid(pname, value, f"a finite number >= 0 for method {m.kind}")
    if m.kind == "explicit" and (not finite(m.mu) or m.mu <= 0):
        raise invalid("mu", m.mu, "a finite number > 0 for method explicit")
    if m.kind == "baumgarte" and m.gamma > 0 and m.beta == 0:
        raise invalid("beta", m.beta, "beta > 0 when gamma > 0 (index 1 needs both)")
    if m.kind == "weighted" and m.b > 0 and m.a == 0:
        raise invalid("a", m.a, "a > 0 when b > 0 (index 1 needs both)")
    if system.order > 2:
        raise invalid("order", system.order, "a polynomial degree k of 0, 1 or 2")
    if not finite(system.epsilon) or not 0 < system.epsilon < 1:
        raise invalid("epsilon", system.epsilon, "a finite increment in (0, 1)")
    if not finite(system.max_condition) or system.max_condition <= 1:
        raise invalid("max_condition", system.max_condition, "a finite number > 1")
    if not finite(system.divergence_factor) or system.divergence_factor <= 1:
        raise invalid("divergence_factor", system.divergence_factor, "a finite number > 1")
    if not 1 <= system.iterations <= 1000:
        raise invalid("iterations", system.iterations, "a number of corrections per step from 1 to 1000")
    if not finite(system.iteration_tol) or system.iteration_tol <= 0:
        raise invalid("iteration_tol", system.iteration_tol, "a finite number > 0")
    if system.jacobian not in ("every_step", "reuse"):
        raise RunError(f"unknown jacobian mode '{system.jacobian}': expected every_step or reuse")
    if system.jacobian_max_age < 1:
        raise invalid("jacobian_max_age", 0, "at least 1 step")
    if system.step_control is not None:
        c = system.step_control
        for key in ("rtol", "atol"):
            if not finite(c[key]) or c[key] < 0:
                raise invalid(f"step_control.{key}", c[key], "a finite tolerance >= 0")
        if c["rtol"] == 0 and c["atol"] == 0:
            raise invalid("step_control.rtol", 0, "rtol > 0 or atol > 0")
        if m.kind == "explicit":
            raise RunError("invalid step_control: the explicit method has no error estimate")
    if m.kind == "explicit" and system.order != 0:
        raise invalid("order", system.order, "0: the explicit method holds the multipliers constant over a step")
    if not system.instances:
        raise RunError("no [[instance]] given")
    seen = set()
    names = [i.name for i in system.instances] + [c.name for c in system.constraints]
    names += [j.name for j in system.joints] + [v.name for v in system.variables]
    for name in names:
        if not _NAME.fullmatch(name):
            raise RunError(f"name '{name}' must start with a letter and contain only letters, digits and '_'")
        if name in seen:
            raise RunError(f"name '{name}' is used twice")
        seen.add(name)
    if not finite(system.signal_tolerance) or system.signal_tolerance <= 0:
        raise invalid("[signals] tolerance", system.signal_tolerance, "a finite relative tolerance > 0")
    for c in system.connections:
        for what, v in (("gain", c.gain), ("offset", c.offset)):
            if v is not None and not finite(v):
                raise invalid(f"{what} of the connection to {c.to}", v, "a finite number")
    for c in system.constraints:
        if c.initial is not None and not finite(c.initial):
            raise invalid(f"{c.name}.initial", c.initial, "a finite number")
