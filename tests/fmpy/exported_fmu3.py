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
Prints one line per check; exit 1 on the first that fails.
"""

import shutil
import sys

from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu


def fail(message):
    print(message)
    sys.exit(1)


fmu, out = sys.argv[1], sys.argv[2]
problems = validate_fmu(fmu)
if problems:
    fail("validate: " + "; ".join(problems))
print("validate: no problems")

md = read_model_description(fmu)
if md.fmiVersion != "3.0":
    fail(f"fmiVersion {md.fmiVersion}, expected 3.0")
H = float(md.defaultExperiment.stepSize)
names = [v.name for v in md.modelVariables if v.causality == "output"]
result = simulate_fmu(fmu, output_interval=H, output=names)
with open(out, "w") as f:
    f.write(",".join(["time"] + names) + "\n")
    for row in result:
        f.write(",".join(repr(float(x)) for x in row) + "\n")
print(f"simulate_fmu: {len(result)} rows")

vr = {v.name: v.valueReference for v in md.modelVariables}
outs = [vr[n] for n in names]
inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"]
parameters = [v.valueReference for v in md.modelVariables if v.causality == "parameter"]
time_vr = [v.valueReference for v in md.modelVariables if v.causality == "independent"][0]
unzipped = extract(fmu)
messages = []


def log(environment, status, category, message):
    messages.append((status, message.decode()))


def instance(name, parameter, token=None):
    s = FMU3Slave(guid=token or md.instantiationToken, unzipDirectory=unzipped,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    s.instantiate(logMessage=log)
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
shutil.rmtree(unzipped, ignore_errors=True)
