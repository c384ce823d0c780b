"""Model-exchange instances: an FMU's ModelExchange interface driven through
fmpy's FMU2Model (FMI 2.0) or FMU3Model (FMI 3.0) behind the calls the master
makes of a co-simulation slave (doStep, setReal/getReal, input derivatives,
FMU states), its continuous states integrated by fmpy's bundled SUNDIALS CVode
(fmpy.sundials.CVodeSolver: BDF with a dense Newton solver and root finding on
the event indicators, as fmpy.simulation integrates model exchange).

Independent of Tether's own integrators (Runge-Kutta with error control): the
two agree only within their tolerances (docs/validation.md).

A step from t to t + h starts the integrator afresh from (t, x(t)) (CVodeReInit:
order 1, its own initial step, no history), so a step repeated after a rollback
starts from the same point. On the way it handles, in time order:

- time events: the FMU's nextEventTime, the integration stopped there exactly
  (CVode's stop time);
- state events: a root of an event indicator (CVode's root finding);
- step events: fmi2CompletedIntegratorStep asking for event mode, called after
  each integration segment (as fmpy.simulation does);

each with event mode, the event iteration (new discrete states until none are
needed), continuous-time mode, the states and nominals read again, and the
integrator restarted from there. The inputs follow the coupling polynomial
u(t) = u0 + u'(t - t0) + u''(t - t0)^2/2 + ...: set at every time the solver
evaluates the derivatives or the event indicators, and at the step's end.

A saved state is the FMU's (getFMUstate) and the instance's: the time, the
continuous states, their nominals, the next time event.
"""

import math
from ctypes import byref

import numpy as np
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model

from errors import RunError

# The most event iterations at one time (a chattering model), as Tether.
MAX_EVENT_ITERATIONS = 100
# The most internal CVode steps in one integration segment.
MAX_NUM_STEPS = 100_000


def _set_stop_time(cvode_mem, t):
    """CVodeSetStopTime (the library has it; fmpy binds it not): no step past t."""
    from ctypes import c_int, c_void_p

    from fmpy.sundials.libraries import sundials_cvode
    from fmpy.sundials.sundials_types import sunrealtype

    f = sundials_cvode.CVodeSetStopTime
    f.argtypes, f.restype = [c_void_p, sunrealtype], c_int
    if f(cvode_mem, t) != 0:
        raise RunError(f"CVodeSetStopTime({t}) failed")


class Capabilities:
    """What a model-exchange instance offers the master, in the names of a
    co-simulation element: rollback where ModelExchange declares
    canGetAndSetFMUstate; steps of any size and inputs that take polynomials
    (set at every time the model is evaluated); no output derivatives."""

    def __init__(self, me):
        self.modelIdentifier = me.modelIdentifier
        self.canGetAndSetFMUstate = bool(me.canGetAndSetFMUstate)
        self.canHandleVariableCommunicationStepSize = True
        self.canInterpolateInputs = True
        self.providesIntermediateUpdate = True
        self.maxOutputDerivativeOrder = 0


class ModelExchange:
    """One model-exchange instance: the FMU and its integrator."""

    def __init__(self, md, unzipped, name, integrator):
        self.md = md
        self.name = name
        self.fmi3 = md.fmiVersion.startswith("3.")
        me = md.modelExchange
        cls = FMU3Model if self.fmi3 else FMU2Model
        self.model = cls(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=me.modelIdentifier,
                         instanceName=name)
        self.model.instantiate()
        self.integrator = integrator or {}
        self.needs_completed = bool(me.needsCompletedIntegratorStep)
        self.continuous_inputs = {v.valueReference for v in md.modelVariables
                                  if v.causality == "input" and v.variability == "continuous"}
        self.experiment = (None, 0.0, None)
        self.tolerance = None
        self.time = 0.0
        self.initialized = False
        self.x = np.zeros(0)
        self.nominals = np.zeros(0)
        self.next_event = None
        self.solver = None
        self.saved = None
        # The inputs' polynomial: value reference -> [value, derivatives...],
        # from t0 (None: the coming step's start).
        self.polynomials = {}
        self.poly_t0 = None
        self.values_set = {}
        self.events = 0

    @property
    def component(self):
        return self.model.component

    # -- the set-up ----------------------------------------------------------------

    def setupExperiment(self, tolerance=None, startTime=0.0, stopTime=None):
        self.experiment = (tolerance, startTime, stopTime)
        self.tolerance = tolerance
        self.time = startTime
        if not self.fmi3:
            self.model.setupExperiment(tolerance=tolerance, startTime=startTime, stopTime=stopTime)

    def enterInitializationMode(self):
        if self.fmi3:
            tolerance, start, stop = self.experiment
            self.model.enterInitializationMode(tolerance=tolerance, startTime=start, stopTime=stop)
        else:
            self.model.enterInitializationMode()

    def exitInitializationMode(self):
        """Leave initialization mode (the FMU is then in event mode), run the
        event iteration, enter continuous-time mode and read the states."""
        self.model.exitInitializationMode()
        self.nx = self.md.numberOfContinuousStates
        self.nz = self.md.numberOfEventIndicators
        self.x = np.zeros(self.nx)
        self.nominals = np.ones(self.nx)
        self._event_iteration(self.time, initial=True)
        self.initialized = True
        self._make_solver()

    def _make_solver(self):
        from fmpy.sundials import CVodeSolver

        get_dx = self.model.getContinuousStateDerivatives if self.fmi3 else self.model.getDerivatives
        rtol = self.integrator.get("rtol")
        if rtol is None:
            rtol = self.tolerance
        if rtol is None and self.md.defaultExperiment is not None and self.md.defaultExperiment.tolerance:
            rtol = float(self.md.defaultExperiment.tolerance)
        if rtol is None:
            rtol = 1e-6
        self.rtol = rtol
        atol = self.integrator.get("atol")
        self.atol = rtol if atol is None else atol
        self.solver = CVodeSolver(nx=self.nx, nz=self.nz,
                                  get_x=self.model.getContinuousStates,
                                  set_x=self.model.setContinuousStates,
                                  get_dx=get_dx,
                                  get_z=self.model.getEventIndicators,
                                  get_nominals=self.model.getNominalsOfContinuousStates,
                                  set_time=self._set_time,
                                  input=self,
                                  startTime=self.time,
                                  relativeTolerance=rtol,
                                  maxNumSteps=MAX_NUM_STEPS)

    # -- the inputs' polynomial ---------------------------------------------------------

    def apply(self, t):
        """The solver's `input`: the polynomial at t (root function)."""
        self._set_inputs(t)

    def _set_time(self, t):
        """The solver's `set_time`: the time, and the polynomial there."""
        self.model.setTime(t)
        self._set_inputs(t)

    def _set_inputs(self, t):
        if not self.polynomials:
            return
        dt = t - self.poly_t0
        vrs, values = [], []
        for vr, c in self.polynomials.items():
            u, factor = c[0], 1.0
            for j in range(1, len(c)):
                factor *= dt / j
                u += c[j] * factor
            vrs.append(vr)
            values.append(u)
        self._set_real(vrs, values)

    def _set_real(self, vrs, values):
        if self.fmi3:
            self.model.setFloat64(vrs, values)
        else:
            self.model.setReal(vrs, values)

    # -- values --------------------------------------------------------------------

    def getReal(self, vr):
        return self.model.getFloat64(vr) if self.fmi3 else self.model.getReal(vr)

    def setReal(self, vr, values):
        """Continuous inputs at once (a value set ends its polynomial); after the
        initialization any other Real in event mode, when a value changes."""
        for v, x in zip(vr, values):
            self.polynomials.pop(v, None)
            self.values_set[v] = x
        if not self.initialized or all(v in self.continuous_inputs for v in vr):
            self._set_real(vr, values)
        elif list(self.getReal(vr)) != list(values):
            self._in_event_mode(lambda: self._set_real(vr, values))

    def setRealInputDerivatives(self, vr, order, value):
        """The polynomial of each input for the coming step: its value (the last
        set) and its derivatives of the given orders (missing ones 0)."""
        for v, k, d in zip(vr, order, value):
            c = self.polynomials.get(v, [self.values_set[v]])
            c = c + [0.0] * (k + 1 - len(c))
            c[k] = d
            self.polynomials[v] = c
        self.poly_t0 = None

    def getInteger(self, vr):
        return self.model.getInt32(vr) if self.fmi3 else self.model.getInteger(vr)

    def setInteger(self, vr, values):
        set_ = self.model.setInt32 if self.fmi3 else self.model.setInteger
        if not self.initialized:
            set_(vr, values)
        elif list(self.getInteger(vr)) != list(values):
            self._in_event_mode(lambda: set_(vr, values))

    def setBoolean(self, vr, values):
        if not self.initialized:
            self.model.setBoolean(vr, values)
        elif list(self.model.getBoolean(vr)) != list(values):
            self._in_event_mode(lambda: self.model.setBoolean(vr, values))

    def getBoolean(self, vr):
        return self.model.getBoolean(vr)

    def setString(self, vr, values):
        if not self.initialized:
            self.model.setString(vr, values)
        else:
            self._in_event_mode(lambda: self.model.setString(vr, values))

    def getRealOutputDerivatives(self, vr, order):
        raise RunError(f"instance '{self.name}': output derivatives of a model-exchange instance")

    def _in_event_mode(self, set_):
        self.model.enterEventMode()
        set_()
        self._event_iteration(self.time)

    # -- events ----------------------------------------------------------------------

    def _event_iteration(self, t, initial=False):
        """In event mode: new discrete states until none are needed, then
        continuous-time mode; the states, nominals and next time event read."""
        if not initial:
            self.events += 1
        update = self.model.updateDiscreteStates if self.fmi3 else self.model.newDiscreteStates
        values_changed = nominals_changed = initial
        for _ in range(MAX_EVENT_ITERATIONS):
            (needed, terminate, nominals, values, defined, next_time) = update()
            if terminate:
                raise RunError(f"instance '{self.name}' asked to terminate the simulation at t = {t}")
            values_changed |= bool(values)
            nominals_changed |= bool(nominals)
            self.next_event = next_time if defined else None
            if not needed:
                break
        else:
            raise RunError(f"instance '{self.name}': more than {MAX_EVENT_ITERATIONS} event iterations "
                           f"at t = {t}: the model chatters")
        self.model.enterContinuousTimeMode()
        if self.nx and values_changed:
            x = np.zeros(self.nx)
            self.model.getContinuousStates(np.ctypeslib.as_ctypes(x), self.nx)
            self.x = x
        if self.nx and nominals_changed:
            n = np.zeros(self.nx)
            self.model.getNominalsOfContinuousStates(np.ctypeslib.as_ctypes(n), self.nx)
            n[~(np.isfinite(n) & (n > 0))] = 1.0
            self.nominals = n

    # -- the step ----------------------------------------------------------------------

    def doStep(self, currentCommunicationPoint, communicationStepSize):
        """Integrate from (t, x(t)) to t + h, handling every event on the way;
        the FMU is left at t + h with the polynomial's inputs there."""
        t, h = currentCommunicationPoint, communicationStepSize
        if self.polynomials and self.poly_t0 is None:
            self.poly_t0 = t
        end = t + h
        resolution = 100.0 * math.ulp(1.0) * max(abs(end), h)
        max_step = min(self.integrator.get("max_step") or h, h)
        self._set_time(t)
        if self.nx:
            self.model.setContinuousStates(np.ctypeslib.as_ctypes(self.x.copy()), self.nx)
        now = t
        while True:
            te = self.next_event if self.next_event is not None and self.next_event <= end + resolution else None
            if te is not None and te <= now + resolution:
                self._set_time(max(te, now))
                self.model.enterEventMode()
                self._event_iteration(now)
                self._put_states(now)
                continue
            if end - now <= resolution:
                break
            target = end if te is None or end - min(te, end) <= resolution else min(te, end)
            now, event = self._integrate(now, target, max_step)
            if event:
                self.model.enterEventMode()
                self._event_iteration(now)
                self._put_states(now)
        self.time = end
        self._put_states(end)

    def _put_states(self, t):
        """The FMU at (t, x), the inputs' polynomial at t."""
        self._set_time(t)
        if self.nx:
            self.model.setContinuousStates(np.ctypeslib.as_ctypes(self.x.copy()), self.nx)

    def _integrate(self, t0, t1, max_step):
        """CVode afresh from (t0, x) to t1 or the first root of an event
        indicator: the time reached and whether an event is due there."""
        from fmpy.sundials.cvode import (CV_NORMAL, CV_ROOT_RETURN, CVode, CVodeSetMaxStep,
                                         CVodeSVtolerances)
        from fmpy.sundials.sundials_types import realtype

        s = self.solver
        self._put_states(t0)
        s.reset(t0)  # CVodeReInit from the FMU's states
        if self.nx:
            # CVode keeps its own copy of the absolute tolerances: set them anew.
            s.npabstol[:] = self.nominals * self.atol
            if CVodeSVtolerances(s.cvode_mem, self.rtol, s.abstol) != 0:
                raise RunError(f"instance '{self.name}': CVodeSVtolerances failed")
        CVodeSetMaxStep(s.cvode_mem, min(max_step, t1 - t0))
        _set_stop_time(s.cvode_mem, t1)
        tret = realtype(0.0)
        flag = CVode(s.cvode_mem, t1, s.x, byref(tret), CV_NORMAL)
        if flag < 0:
            raise RunError(f"instance '{self.name}': CVode failed at t = {tret.value} (flag {flag}): "
                           f"{s.error_info}")
        state_event, reached = flag == CV_ROOT_RETURN, tret.value
        if self.nx:
            x = np.zeros(self.nx)
            x[:] = np.ctypeslib.as_array(s.px, (self.nx,))
            if not np.all(np.isfinite(x)):
                raise RunError(f"instance '{self.name}': the integrator reached non-finite states "
                               f"at t = {reached}")
            self.x = x
        self._put_states(reached)
        step_event = False
        if self.needs_completed:
            # A rollback may set a state from before this point.
            step_event, terminate = self.model.completedIntegratorStep(
                noSetFMUStatePriorToCurrentPoint=False)
            if terminate:
                raise RunError(f"instance '{self.name}' asked to terminate the simulation at t = {reached}")
        return reached, state_event or step_event

    # -- FMU states ----------------------------------------------------------------------

    def _save(self):
        self.saved = (self.time, self.x.copy(), self.nominals.copy(), self.next_event, self.events)

    def getFMUstate(self):
        self._save()
        return self.model.getFMUState() if self.fmi3 else self.model.getFMUstate()

    def fmi2GetFMUstate(self, component, state):
        self._save()
        if self.fmi3:
            return self.model.fmi3GetFMUState(component, state)
        return self.model.fmi2GetFMUstate(component, state)

    def setFMUstate(self, state):
        if self.fmi3:
            self.model.setFMUState(state)
        else:
            self.model.setFMUstate(state)
        self.time, x, n, self.next_event, self.events = self.saved
        self.x, self.nominals = x.copy(), n.copy()

    def freeFMUstate(self, state):
        if self.fmi3:
            self.model.freeFMUState(state)
        else:
            self.model.freeFMUstate(state)

    def terminate(self):
        self.model.terminate()

    def freeInstance(self):
        self.solver = None
        self.model.freeInstance()
