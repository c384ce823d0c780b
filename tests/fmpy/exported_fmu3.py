"""fmpy against an FMI 3.0 FMU made by `tether fmu export --fmi 3`
(crates/tether-cli/tests/fmu_export.rs).

usage: exported_fmu3.py FMU OUT.csv

1. fmpy.validate: no problems with the model description (exit 1 otherwise).
2. fmpy.simulate_fmu on the DefaultExperiment's step: every output, written to
   OUT.csv with repr() (round-trips every double).
3. fmpy-driven fmi3GetFMUState / fmi3SetFMUState: a repeated two-step
   fmi3DoStep after setting the input gives the same outputs bit for bit;
   lastSuccessfulTime and the independent variable `time` are t + 2 H.
4. Serialized state: the state of check 3 as bytes, read by a fresh instance
   (made with another parameter value), repeats the step bit for bit; the
   bytes cut short give fmi3Error with the reason logged under
   fmi3DeserializeFMUState.
5. A communication step of 1.5 macro steps: fmi3Error, logged under fmi3DoStep.
6. fmi3InstantiateCoSimulation with a wrong instantiationToken returns NULL,
   the reason reaching the importer's log callback.
7. A function the FMU does not offer (fmi3GetInt32): fmi3Error, logged under
   its name.
8. Intermediate update (providesIntermediateUpdate, the input declared
   intermediateUpdate="true"): with fmpy's intermediate update callback,
   fmi3DoStep over 10 H calls back once per inner step, at its start time
   (intermediateVariableSetRequested true, intermediateVariableGetAllowed and
   canReturnEarly false); a ramp F(t) = A + B·t set in the callback equals
   the same ramp set with fmi3SetFloat64 before steps of H to 1e-11 m (each
   inner step sees the input at its own time), follows the closed form of
   the two joined masses within 1e-3 m (the input is held over each inner
   step H: it lags the ramp by H/2, B·H/(2c) = 5e-4 m), where inputs held
   over the 10 H (no callback) are off by more than 2e-3 m. In the callback
   an output cannot be set nor a value read (fmi3Error, logged).
Prints one line per check; exit 1 on the first that fails.
"""

import shutil
import sys

from fmpy import extract
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

from exported_common import RAMP_A, RAMP_B, fail, ramp_error, validate_and_simulate

fmu, out = sys.argv[1], sys.argv[2]
md, H, names = validate_and_simulate(fmu, out)
if md.fmiVersion != "3.0":
    fail(f"fmiVersion {md.fmiVersion}, expected 3.0")

vr = {v.name: v.valueReference for v in md.modelVariables}
outs = [vr[n] for n in names]
inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"]
parameters = [v.valueReference for v in md.modelVariables if v.causality == "parameter"]
time_vr = [v.valueReference for v in md.modelVariables if v.causality == "independent"][0]
unzipped = extract(fmu)
messages = []


def log(environment, status, category, message):
    messages.append((status, message.decode()))


def instance(name, parameter, token=None, update=None):
    s = FMU3Slave(guid=token or md.instantiationToken, unzipDirectory=unzipped,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    s.instantiate(logMessage=log, intermediateUpdate=update)
    if parameters:
        s.setFloat64(parameters[:1], [parameter])
    s.enterInitializationMode(startTime=float(md.defaultExperiment.startTime))
    s.exitInitializationMode()
    return s


def refused(call, function):
    messages.clear()
    try:
        call()
    except FMICallException as e:
        if e.status != 3:
            fail(f"{function}: status {e.status}, expected 3 (fmi3Error)")
        logged = [m for st, m in messages if st == 3 and m.startswith(function + ":")]
        if not logged:
            fail(f"{function}: no message naming it: {messages}")
        return logged[0]
    fail(f"{function}: accepted")


s = instance("a", 1.5)
t = 0.0
for n in range(100):
    s.doStep(t, H)
    t += H
if inputs:
    s.setFloat64(inputs[:1], [50.0])
state = s.getFMUState()
if not md.coSimulation.canSerializeFMUstate:
    fail("canSerializeFMUState is false")
serialized = s.serializeFMUState(state)
_, _, _, last = s.doStep(t, 2 * H)
first = s.getFloat64(outs)
now = s.getFloat64([time_vr])[0]
if last != now or abs(last - (t + 2 * H)) > 1e-12:
    fail(f"lastSuccessfulTime {last}, time {now}, expected {t + 2 * H}")
s.setFMUState(state)
s.doStep(t, 2 * H)
second = s.getFloat64(outs)
s.freeFMUState(state)
if first != second:
    fail(f"state: the repeated step differs: {first} vs {second}")
print(f"state: repeated step identical: {first}, lastSuccessfulTime {last}")

reason = refused(lambda: s.doStep(t + 2 * H, 1.5 * H), "fmi3DoStep")
print(f"doStep of 1.5 H: fmi3Error, logged: {reason}")
reason = refused(lambda: s.getInt32([0]), "fmi3GetInt32")
print(f"unsupported function: fmi3Error, logged: {reason}")
s.terminate()
s.freeInstance()

fresh = instance("fresh", 3.0)
fresh.doStep(0.0, H)
restored = fresh.deserializeFMUState(serialized)
fresh.setFMUState(restored)
fresh.doStep(t, 2 * H)
third = fresh.getFloat64(outs)
if third != first:
    fail(f"serialized state: the repeated step differs: {first} vs {third}")
print(f"serialized state: {len(serialized)} bytes, repeated step identical in a fresh instance")
reason = refused(lambda: fresh.deserializeFMUState(serialized[:-9]), "fmi3DeserializeFMUState")
if "not a state of this FMU" not in reason:
    fail(f"serialized state cut short: {reason}")
print(f"serialized state cut short: fmi3Error, logged: {reason}")
fresh.freeFMUState(restored)
fresh.terminate()
fresh.freeInstance()

messages.clear()
try:
    instance("wrong", 1.0, token="{00000000-0000-0000-0000-000000000000}")
    fail("a wrong instantiationToken was accepted")
except Exception:
    pass
logged = [m for st, m in messages if st == 3 and m.startswith("fmi3InstantiateCoSimulation:")]
if not logged or "GUID" not in logged[0]:
    fail(f"wrong token: no logged reason: {messages}")
print(f"wrong token: NULL, logged: {logged[0]}")


# 8. Intermediate update: a ramp force set in the callback at each inner step.
if not md.coSimulation.providesIntermediateUpdate:
    fail("intermediate update: providesIntermediateUpdate is false")
with open(f"{unzipped}/modelDescription.xml", encoding="utf-8") as f:
    declared = [line for line in f if 'causality="input"' in line]
if not declared or not all('intermediateUpdate="true"' in line for line in declared):
    fail(f"intermediate update: an input is not declared intermediateUpdate: {declared}")
F, X = inputs[0], vr["x"]
calls = []
current = []
refusals = []


def update(environment, time, set_requested, get_allowed, step_finished, can_return_early,
           early_return_requested, early_return_time):
    calls.append((time, set_requested, get_allowed, can_return_early))
    s = current[0]
    s.setFloat64([F], [RAMP_A + RAMP_B * time])
    if len(calls) == 1:
        # Once: what intermediate update mode refuses.
        for what, call in [("set an output", lambda: s.setFloat64([X], [0.0])),
                           ("read", lambda: s.getFloat64([X]))]:
            messages.clear()
            try:
                call()
                refusals.append(f"{what}: accepted")
            except FMICallException as e:
                logged = [m for st, m in messages if st == 3]
                refusals.append(f"{what}: status {e.status}, logged: {logged}")


def ramp(every, callback):
    s = instance(f"ramp{every}{callback}", 1.0, update=update if callback else None)
    current[:] = [s]
    xs = []
    # Over the FMU's experiment (1 s for the rigid pair, 0.5 s for its SSP).
    for n in range(round(float(md.defaultExperiment.stopTime) / (every * H))):
        t = n * every * H
        s.setFloat64([F], [RAMP_A + RAMP_B * t])
        s.doStep(t, every * H)
        xs.append((t + every * H, s.getFloat64([X])[0]))
    s.terminate()
    s.freeInstance()
    return xs


coarse = ramp(10, True)
steps = round(float(md.defaultExperiment.stopTime) / H)
if len(calls) != steps:
    fail(f"intermediate update: {len(calls)} callbacks, expected one per inner step ({steps})")
expected = [n * H for n in range(steps)]
if max(abs(c[0] - e) for c, e in zip(calls, expected)) > 1e-9 * H:
    fail(f"intermediate update: callback times {[c[0] for c in calls[:12]]}...")
if any(c[1:] != (1, 0, 0) for c in calls):
    fail(f"intermediate update: flags (set, get, early) {set(c[1:] for c in calls)}")
if len(refusals) != 2 or not all("status 3" in r for r in refusals) \
        or "intermediate update mode" not in refusals[1]:
    fail(f"intermediate update: {refusals}")
fine, held = ramp(1, False)[9::10], ramp(10, False)
error, error_held = ramp_error(coarse), ramp_error(held)
same = max(abs(a[1] - b[1]) for a, b in zip(coarse, fine))
if not same <= 1e-11:
    fail(f"intermediate update: steps of 10 H differ from steps of H by {same:.3g} m")
if not error <= 1e-3:
    fail(f"intermediate update: {error:.3g} m from the closed form (tolerance 1e-3)")
if not error_held > 2e-3:
    fail(f"intermediate update: held inputs are only {error_held:.3g} m off: the check cannot tell")
print(f"intermediate update: {len(calls)} callbacks at the inner steps' starts; ramp within "
      f"{error:.3g} m of the closed form (held: {error_held:.3g} m), steps of 10 H and of H "
      f"agree to {same:.3g} m; in the callback an output set and a read are refused")
shutil.rmtree(unzipped, ignore_errors=True)
