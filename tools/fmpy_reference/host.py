"""FMU instances driven through fmpy's FMU2Slave (FMI 2.0) or FMU3Slave (FMI 3.0),
or through the model-exchange interface with an integrator of the reference's
own (model_exchange.py): start values, coupled inputs (value and input
derivatives), outputs and output derivatives, FMU states."""

import atexit
import os
import re
import shutil
from ctypes import byref
from xml.etree import ElementTree

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from errors import RunError
from model_exchange import Capabilities, ModelExchange

# The type names of a Real variable: FMI 2.0 and FMI 3.0.
REAL = ("Real", "Float64")
_INTEGER = ("Integer", "Enumeration", "Int32")


class FMU3Reference(FMU3Slave):
    """An FMI 3.0 co-simulation FMU under the FMU2Slave calls the reference makes
    (the one place that knows the FMI version). FMI 3.0 has no input derivatives:
    an input declared intermediateUpdate="true" of an FMU that provides
    intermediate update takes its polynomial through the intermediate update
    callback, which sets it to the polynomial's value at each intermediate time the
    FMU asks for inputs (setRealInputDerivatives records the polynomial for the
    coming step)."""

    def instantiate(self, polynomial_inputs=()):
        # Per input with a polynomial: [t0 (None: the coming step's start), value,
        # derivatives...]; the values last set.
        self.polynomial_inputs = list(polynomial_inputs)
        self.polynomials = {}
        self.values_set = {}
        self.callback_failure = None
        if self.polynomial_inputs:
            super().instantiate(intermediateUpdate=self._intermediate_update,
                                requiredIntermediateVariables=self.polynomial_inputs)
        else:
            super().instantiate()

    def _intermediate_update(self, env, time, set_requested, get_allowed, step_finished,
                             can_return_early, early_return_requested, early_return_time):
        try:
            if early_return_requested:
                early_return_requested[0] = False
            if not set_requested or not self.polynomials or self.callback_failure:
                return
            vrs, values = [], []
            for vr, (t0, coefficients) in self.polynomials.items():
                vrs.append(vr)
                values.append(_evaluate(coefficients, time - t0))
            self.setFloat64(vrs, values)
        except Exception as e:  # noqa: BLE001 - reported after the step
            self.callback_failure = e

    def setupExperiment(self, tolerance=None, startTime=0.0, stopTime=None):
        self.experiment = (tolerance, startTime, stopTime)

    def enterInitializationMode(self):
        tolerance, start, stop = self.experiment
        super().enterInitializationMode(tolerance=tolerance, startTime=start, stopTime=stop)

    def getReal(self, vr):
        return self.getFloat64(vr)

    def setReal(self, vr, values):
        self.setFloat64(vr, values)
        # A value set on an input ends its polynomial.
        for v, x in zip(vr, values):
            self.polynomials.pop(v, None)
            self.values_set[v] = x

    def setRealInputDerivatives(self, vr, order, value):
        """The polynomial of each input for the coming step: its value (the last
        set) and its derivatives of the given orders (missing ones 0)."""
        for v, k, d in zip(vr, order, value):
            if v not in self.polynomial_inputs:
                raise RunError(f"input {v} of {self.modelIdentifier} cannot take a polynomial "
                               f"(no intermediate update for it)")
            t0, coefficients = self.polynomials.get(v, (None, [self.values_set[v]]))
            coefficients = coefficients + [0.0] * (k + 1 - len(coefficients))
            coefficients[k] = d
            self.polynomials[v] = (None, coefficients)

    def getInteger(self, vr):
        return self.getInt32(vr)

    def setInteger(self, vr, values):
        self.setInt32(vr, values)

    def getRealOutputDerivatives(self, vr, order):
        return self.getOutputDerivatives(vr, order)

    def getFMUstate(self):
        return self.getFMUState()

    def fmi2GetFMUstate(self, component, state):
        return self._call("fmi3GetFMUState", component, state)

    def setFMUstate(self, state):
        self.setFMUState(state)

    def freeFMUstate(self, state):
        self.freeFMUState(state)

    def doStep(self, currentCommunicationPoint, communicationStepSize):
        for v, (t0, coefficients) in list(self.polynomials.items()):
            if t0 is None:
                self.polynomials[v] = (currentCommunicationPoint, coefficients)
        super().doStep(currentCommunicationPoint, communicationStepSize)
        if self.callback_failure is not None:
            failure, self.callback_failure = self.callback_failure, None
            raise RunError(f"fmi3SetFloat64 in the intermediate update callback failed: {failure}")


def _evaluate(c, dt):
    """u(t0 + dt) from the value and derivatives at t0, in Horner's form
    c0 + dt*(c1 + dt/2*(c2 + ...)), the operations of tether's callback."""
    derivatives = c[1:]
    acc = 0.0
    for j in range(len(derivatives) - 1, -1, -1):
        acc = derivatives[j] if j + 1 == len(derivatives) else derivatives[j] + dt / (j + 2) * acc
    return c[0] + dt * acc


def intermediate_update_inputs(unzipped, md):
    """The value references of the Float64 inputs declared intermediateUpdate="true"
    of an FMI 3.0 FMU that provides intermediate update (fmpy does not read the
    attribute)."""
    if not getattr(md.coSimulation, "providesIntermediateUpdate", False):
        return []
    root = ElementTree.parse(os.path.join(unzipped, "modelDescription.xml")).getroot()
    return [int(e.get("valueReference")) for e in root.iter("Float64")
            if e.get("causality") == "input" and e.get("intermediateUpdate") == "true"
            and e.find("Dimension") is None]


class Needs:
    """What the system's method needs of one instance (Tether's rule, for
    fmi_type = "auto"): rollback (and who needs it), steps of varying size,
    inputs that take polynomials."""

    def __init__(self, rollback=None, variable_steps=False, polynomial_inputs=False):
        self.rollback = rollback
        self.variable_steps = variable_steps
        self.polynomial_inputs = polynomial_inputs

    @staticmethod
    def of(system, name):
        constrained = is_constrained(system, name)
        if system.step_control is not None:
            rollback = "adaptive steps ([step_control])"
        elif system.signal_iterations is not None:
            rollback = "[signals] iterations"
        elif constrained and system.method.kind != "explicit":
            rollback = f"the predictor/corrector method {system.method.kind}"
        else:
            rollback = None
        return Needs(rollback, system.step_control is not None, constrained and system.order > 0)

    def lacking(self, rollback, variable_steps, polynomial_inputs):
        """The first capability short of these needs, with who needs it."""
        if self.rollback and not rollback:
            return "canGetAndSetFMUstate", self.rollback
        if self.variable_steps and not variable_steps:
            return "canHandleVariableCommunicationStepSize", "adaptive steps ([step_control])"
        if self.polynomial_inputs and not polynomial_inputs:
            return "inputs that take polynomials", "coupling polynomials of degree k > 0"
        return None


def is_constrained(system, name):
    """Whether a constraint, joint or coupling variable names instance `name`
    (as `name.` at the start of a word)."""
    prefix = re.compile(r"(?<![\w.])" + re.escape(name) + r"\.")
    texts = []
    for c in system.constraints:
        texts += [c.position, c.velocity, c.acceleration, c.drives]
    for j in system.joints:
        texts += [j.i, j.j]
    for v in system.variables:
        texts += [v.drives, v.value]
    return any(t is not None and prefix.search(t) for t in texts)


def choose(spec, md, needs):
    """Whether the instance runs model exchange, and a note when "auto" chose
    it: as `fmi_type` says; for "auto" co-simulation, unless the FMU offers
    only model exchange, or its co-simulation interface lacks a capability the
    method needs of the instance and its model-exchange interface does not."""
    kind = getattr(spec, "fmi_type", "auto")
    if kind != "auto":
        return kind == "model_exchange", None
    cs, me = md.coSimulation, md.modelExchange
    if me is None:
        return False, None
    if cs is None:
        return True, f"'{spec.name}' runs model exchange: its FMU offers no co-simulation"
    polynomials = bool(cs.canInterpolateInputs or getattr(cs, "providesIntermediateUpdate", False))
    cs_lacks = needs.lacking(cs.canGetAndSetFMUstate, cs.canHandleVariableCommunicationStepSize, polynomials)
    if cs_lacks is None or needs.lacking(me.canGetAndSetFMUstate, True, True) is not None:
        return False, None
    capability, by = cs_lacks
    return True, (f"'{spec.name}' runs model exchange (fmi_type = \"auto\"): its co-simulation "
                  f"interface lacks {capability}, which {by} needs")


_NOT_SETTABLE = {"output", "local", "independent", "calculatedParameter"}


def _article(type_name):
    return "an" if type_name in ("Integer", "Enumeration", "Int32") else "a"


def describe(var):
    causality = {"calculatedParameter": "calculated parameter", "local": "local variable",
                 "independent": "independent variable"}.get(var.causality, var.causality)
    return f"{_article(var.type)} {var.type} {causality}"


class Counters:
    def __init__(self):
        self.do_steps = 0
        self.state_gets = 0
        self.state_sets = 0


class Host:
    """One FMU instance of the system."""

    _unpacked = {}

    def __init__(self, spec, experiment, needs=None):
        """Instantiate for the interface `spec.fmi_type` and `needs` choose
        (choose()), set up the experiment ``(start, stop, tolerance)``, then
        set the start values, as Tether does (FMI 2.0: some FMUs reset their
        parameters in fmi2SetupExperiment)."""
        self.name = spec.name
        path = spec.fmu
        if not os.path.exists(path):
            raise RunError(f"instance '{self.name}': FMU {path} does not exist")
        try:
            md = read_model_description(path)
        except Exception as e:  # fmpy raises several types for unreadable FMUs
            raise RunError(f"instance '{self.name}': cannot read {path}: {_one_line(e)}") from None
        self.model_exchange, self.note = choose(spec, md, needs or Needs())
        if self.model_exchange and md.modelExchange is None:
            raise RunError(f"instance '{self.name}': {path} is not a model-exchange FMU")
        if not self.model_exchange and md.coSimulation is None:
            raise RunError(f"instance '{self.name}': {path} is not a co-simulation FMU")
        self.md = md
        self.cs = Capabilities(md.modelExchange) if self.model_exchange else md.coSimulation
        self.variables = {v.name: v for v in md.modelVariables}
        if os.path.isdir(path):
            unzipped = path
        else:
            key = os.path.realpath(path)
            if key not in Host._unpacked:
                Host._unpacked[key] = extract(path)
                # fmpy's extract() unpacks into a fresh temporary directory and
                # leaves it there; remove it when the run ends.
                atexit.register(shutil.rmtree, Host._unpacked[key], ignore_errors=True)
            unzipped = Host._unpacked[key]
        self.fmi3 = md.fmiVersion.startswith("3.")
        if self.model_exchange:
            # Instantiated for model exchange with its integrator.
            self.fmu = ModelExchange(md, unzipped, self.name, getattr(spec, "integrator", None))
        else:
            slave = FMU3Reference if self.fmi3 else FMU2Slave
            self.fmu = slave(guid=md.guid, unzipDirectory=unzipped,
                             modelIdentifier=self.cs.modelIdentifier, instanceName=self.name)
            if self.fmi3:
                self.polynomial_inputs = intermediate_update_inputs(unzipped, md)
                self.fmu.instantiate(self.polynomial_inputs)
            else:
                self.fmu.instantiate()
        start, stop, tolerance = experiment
        self.fmu.setupExperiment(tolerance=tolerance, startTime=start, stopTime=stop)
        self.recorded = [v for v in md.modelVariables if v.causality == "output" and v.type in REAL]
        self.recorded_vrs = [v.valueReference for v in self.recorded]
        self.recorded_values = [0.0] * len(self.recorded)
        self.inputs = []  # [value reference, [(unknown, coefficient), ...]]
        self.outputs = []  # [(value reference, derivative order)]
        self.values = {}  # (value reference, order) -> latest value read
        self.state = None
        self.initialized = False
        # Gauss-Seidel signals: stepped by the signal sweep before the method's step.
        self.stepped_ahead = False
        self.counters = Counters()
        for name, value in spec.parameters.items():
            self._start_value(name, value)

    def can_interpolate(self):
        """Polynomial inputs at all: FMI 2.0 canInterpolateInputs, FMI 3.0
        providesIntermediateUpdate, model exchange always."""
        if self.model_exchange:
            return True
        if self.fmi3:
            return bool(getattr(self.cs, "providesIntermediateUpdate", False))
        return bool(self.cs.canInterpolateInputs)

    def interpolates(self, vr):
        """Whether input vr takes a polynomial (FMI 3.0: declared
        intermediateUpdate="true")."""
        if self.model_exchange:
            return True
        return self.can_interpolate() and (not self.fmi3 or vr in self.polynomial_inputs)

    def variable(self, name):
        var = self.variables.get(name)
        if var is None:
            raise RunError(f"{self.md.modelName} has no variable '{name}' (instance '{self.name}')")
        return var

    def _start_value(self, name, value):
        var = self.variable(name)

        def fail(reason):
            return RunError(f"instance '{self.name}': cannot set {name} = {value}: {reason}")

        if var.causality in _NOT_SETTABLE or var.variability == "constant":
            raise fail(f"it is {describe(var)} and cannot be set")
        vr = [var.valueReference]
        is_bool = isinstance(value, bool)
        if var.type in REAL and isinstance(value, (int, float)) and not is_bool:
            self.fmu.setReal(vr, [float(value)])
        elif var.type in _INTEGER and isinstance(value, int) and not is_bool:
            if not -(2**31) <= value < 2**31:
                raise fail("out of the 32-bit integer range")
            self.fmu.setInteger(vr, [value])
        elif var.type == "Boolean" and is_bool:
            self.fmu.setBoolean(vr, [value])
        elif var.type == "String" and isinstance(value, str):
            self.fmu.setString(vr, [value])
        else:
            raise fail(f"the variable is {describe(var)}")

    # -- wiring, before the run ------------------------------------------------

    def add_input(self, vr, unknown, coefficient):
        for entry in self.inputs:
            if entry[0] == vr:
                entry[1].append((unknown, coefficient))
                return
        self.inputs.append([vr, [(unknown, coefficient)]])

    def add_output(self, vr, order):
        if (vr, order) not in self.outputs:
            self.outputs.append((vr, order))

    def is_coupled(self):
        return bool(self.inputs)

    def initialize(self):
        self.enter_initialization()
        self.exit_initialization()

    def enter_initialization(self):
        """Enter initialization mode (the experiment was set up at
        instantiation), where inputs can be set and outputs read before the
        first step (a loop's values at T_0)."""
        self.fmu.enterInitializationMode()

    def exit_initialization(self):
        self.fmu.exitInitializationMode()
        self.initialized = True  # fmi2Terminate is allowed from here on

    # -- during the run ---------------------------------------------------------

    def save_state(self):
        """fmi2GetFMUstate, updating one state handle for the whole run."""
        if self.state is None:
            self.state = self.fmu.getFMUstate()
        else:
            self.fmu.fmi2GetFMUstate(self.fmu.component, byref(self.state))
        self.counters.state_gets += 1

    def restore_state(self):
        self.fmu.setFMUstate(self.state)
        self.counters.state_sets += 1

    def apply(self, jets, order):
        """Inputs from the unknowns' polynomials: input = sum of c * u_m(t).
        With order k > 0, derivatives 1..k go through fmi2SetRealInputDerivatives."""
        if not self.inputs:
            return
        vrs, values, d1, d2 = [], [], [], []
        for vr, terms in self.inputs:
            value = first = second = 0.0
            for m, c in terms:
                value += c * jets[m].value
                first += c * jets[m].d1
                second += c * jets[m].d2
            vrs.append(vr)
            values.append(value)
            d1.append(first)
            d2.append(second)
        self.fmu.setReal(vrs, values)
        if order >= 1:
            self.fmu.setRealInputDerivatives(vrs, [1] * len(vrs), d1)
        if order >= 2:
            self.fmu.setRealInputDerivatives(vrs, [2] * len(vrs), d2)

    def do_step(self, t, h):
        self.counters.do_steps += 1
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def read(self):
        """Read every output some constraint row uses into `values`."""
        plain = [o for o in self.outputs if o[1] == 0]
        if plain:
            for (vr, _), x in zip(plain, self.fmu.getReal([vr for vr, _ in plain])):
                self.values[(vr, 0)] = x
        for vr, order in self.outputs:
            if order > 0:
                self.values[(vr, order)] = self.fmu.getRealOutputDerivatives([vr], [order])[0]

    def read_recorded(self):
        if self.recorded_vrs:
            self.recorded_values = self.fmu.getReal(self.recorded_vrs)

    def close(self):
        try:
            if self.state is not None:
                self.fmu.freeFMUstate(self.state)
            if self.initialized:
                self.fmu.terminate()
        except Exception:
            pass  # the run's own error, if any, is the one to report
        finally:
            self.fmu.freeInstance()


def _one_line(e):
    return " ".join(str(e).split())
