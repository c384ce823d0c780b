"""fmpy against an FMU made by `tether fmu export` (crates/tether-cli/tests/fmu_export.rs).

usage: exported_fmu.py FMU OUT.csv

1. fmpy.validate: no problems with the model description (exit 1 otherwise).
2. fmpy.simulate_fmu on the DefaultExperiment's step: every output, written to
   OUT.csv with repr() (round-trips every double).
3. fmpy-driven fmi2GetFMUstate / fmi2SetFMUstate: a repeated two-step
   fmi2DoStep after setting the input gives the same outputs bit for bit.
4. A communication step of 1.5 macro steps is refused with fmi2Error.
5. Two instances in one process do not share state: instance A stepped
   alone and interleaved with instance B (another parameter value) gives the
   same outputs bit for bit.
6. fmi2Instantiate with a wrong GUID returns NULL, the reason reaching the
   logger the importer gave.
7. A member's error (mass1 with m = -1 through the exported parameter)
   fails fmi2ExitInitializationMode with fmi2Error, and the member's own
   message reaches the importer's logger of that instance.
8. Serialized state (canSerializeFMUstate true): the state of check 3 as
   bytes, read into a fresh state by a fresh instance (made with another
   parameter value: the exported values are part of the state), repeats the
   two-step fmi2DoStep of check 3 bit for bit; the bytes cut short, with one
   byte changed, or empty give fmi2Error with the reason logged.
9. ModelStructure: the acceleration a and the multiplier lambda depend
   directly on the input F (Outputs and InitialUnknowns), the position x and
   velocity v do not.
10. Direct feedthrough: a set F shows in a and lambda when they are read, in
   initialization mode and between steps: the change in a is ΔF/(m1 + m2),
   in lambda m2·ΔF/(m1 + m2) (the rigid pair's closed form), to 1e-12;
   x and v do not change; the step after a read is the step without it, bit
   for bit (set F, read a, set F back, step).
11. Input interpolation: F(t) = A + B·t driven by fmi2SetReal and
   fmi2SetRealInputDerivatives (order 1) over communication steps of 10 H
   follows the closed form of the two joined masses under the ramp force
   within 5e-5 m (the coupling's own error at H = 1e-3: the unforced pair is
   1.9e-5 m off its closed form; amplitude 4.5 m), where held inputs are off
   by more than 1e-3 m; and it equals the same ramp driven every H to 1e-11 m
   (each inner step sees the input at its own time; the two differ only in
   rounding of A + B·t). A derivative of order 3, or of an output, is
   refused with fmi2Error.
Prints one line per check; exit 1 on the first that fails.
"""

import shutil
import sys

from fmpy import extract
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from exported_common import RAMP_A, RAMP_B, fail, ramp_error, validate_and_simulate

fmu, out = sys.argv[1], sys.argv[2]
md, H, names = validate_and_simulate(fmu, out)

vr = {v.name: v.valueReference for v in md.modelVariables}
outs = [vr[n] for n in names]
inputs = [v.valueReference for v in md.modelVariables if v.causality == "input"]
parameters = [v.valueReference for v in md.modelVariables if v.causality == "parameter"]
unzipped = extract(fmu)


def instance(name, parameter):
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    s.instantiate()
    s.setupExperiment(startTime=float(md.defaultExperiment.startTime))
    if parameters:
        s.setReal(parameters[:1], [parameter])
    s.enterInitializationMode()
    s.exitInitializationMode()
    return s


s = instance("a", 1.5)
t = 0.0
for n in range(100):
    s.doStep(t, H)
    t += H
if inputs:
    s.setReal(inputs[:1], [50.0])
state = s.getFMUstate()
if not md.coSimulation.canSerializeFMUstate:
    fail("canSerializeFMUstate is false")
serialized = s.serializeFMUstate(state)
s.doStep(t, 2 * H)
first = s.getReal(outs)
s.setFMUstate(state)
s.doStep(t, 2 * H)
second = s.getReal(outs)
s.freeFMUstate(state)
if first != second:
    fail(f"state: the repeated step differs: {first} vs {second}")
print(f"state: repeated step identical: {first}")

try:
    s.doStep(t + 2 * H, 1.5 * H)
    fail("doStep of 1.5 H was accepted")
except FMICallException as e:
    if e.status != 3:
        fail(f"doStep of 1.5 H: status {e.status}, expected 3 (fmi2Error)")
print("doStep of 1.5 H: fmi2Error")
s.terminate()
s.freeInstance()

alone = instance("alone", 1.5)
rows_alone = []
for n in range(50):
    alone.doStep(n * H, H)
    rows_alone.append(alone.getReal(outs))
alone.terminate()
alone.freeInstance()
a, b = instance("a", 1.5), instance("b", 3.0)
rows_a, rows_b = [], []
for n in range(50):
    a.doStep(n * H, H)
    b.doStep(n * H, H)
    rows_a.append(a.getReal(outs))
    rows_b.append(b.getReal(outs))
for s in (a, b):
    s.terminate()
    s.freeInstance()
if rows_a != rows_alone:
    fail("two instances: instance a differs from the same instance stepped alone")
if rows_a == rows_b:
    fail("two instances: a and b (other parameter) give the same outputs")
print("two instances: independent")

from ctypes import byref  # noqa: E402

from fmpy import calloc, free  # noqa: E402
from fmpy.fmi2 import (  # noqa: E402
    fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy  # noqa: E402

messages = []


def logger(component, name, status, category, message):
    messages.append((name.decode(), status, message.decode()))


callbacks = fmi2CallbackFunctions()
callbacks.logger = fmi2CallbackLoggerTYPE(logger)
callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
addLoggerProxy(byref(callbacks))
wrong = FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=unzipped,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="wrong")
try:
    wrong.instantiate(callbacks=callbacks)
    fail("a wrong GUID was accepted")
except Exception:
    pass
if not any(n == "wrong" and st == 3 and "GUID" in m for n, st, m in messages):
    fail(f"wrong GUID: no logged reason: {messages}")
print(f"wrong GUID: NULL, logged: {messages[-1][2]}")

messages.clear()
negative = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                     modelIdentifier=md.coSimulation.modelIdentifier, instanceName="negative")
negative.instantiate(callbacks=callbacks)
negative.setupExperiment(startTime=0.0)
negative.setReal(parameters[:1], [-1.0])
negative.enterInitializationMode()
try:
    negative.exitInitializationMode()
    fail("m = -1 was accepted")
except FMICallException as e:
    if e.status != 3:
        fail(f"m = -1: status {e.status}, expected 3 (fmi2Error)")
member = [m for n, st, m in messages if n == "negative" and st == 3 and m.startswith("fmu::mass1")]
if not member:
    fail(f"m = -1: the member's message was not forwarded: {messages}")
print(f"member error: fmi2Error, forwarded: {member[0]}")
negative.freeInstance()

messages.clear()
fresh = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="fresh")
fresh.instantiate(callbacks=callbacks)
fresh.setupExperiment(startTime=float(md.defaultExperiment.startTime))
if parameters:
    fresh.setReal(parameters[:1], [3.0])
fresh.enterInitializationMode()
fresh.exitInitializationMode()
fresh.doStep(0.0, H)
restored = fresh.deSerializeFMUstate(serialized)
fresh.setFMUstate(restored)
fresh.doStep(t, 2 * H)
third = fresh.getReal(outs)
if third != first:
    fail(f"serialized state: the repeated step differs: {first} vs {third}")
print(f"serialized state: {len(serialized)} bytes, repeated step identical in a fresh instance")
changed = bytearray(serialized)
changed[len(changed) // 2] ^= 0x40
for what, bad in [("cut short", serialized[:-9]), ("one byte changed", bytes(changed)),
                  ("empty", b"")]:
    messages.clear()
    try:
        fresh.deSerializeFMUstate(bad)
        fail(f"serialized state {what} was accepted")
    except FMICallException as e:
        if e.status != 3:
            fail(f"serialized state {what}: status {e.status}, expected 3 (fmi2Error)")
    reason = [m for n, st, m in messages if n == "fresh" and st == 3]
    if not reason or "not a state of this FMU" not in reason[0]:
        fail(f"serialized state {what}: no logged reason: {messages}")
    print(f"serialized state {what}: fmi2Error, logged: {reason[0]}")
fresh.doStep(t + 2 * H, H)
fresh.freeFMUstate(restored)
fresh.terminate()
fresh.freeInstance()
# 9. The true ModelStructure.
# (An FMU without lambda, the SSP export, checks the others.)
outputs_deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.outputs}
expected = {"x": [], "v": [], "a": ["F"], "lambda": ["F"]}
if outputs_deps != {k: d for k, d in expected.items() if k in vr}:
    fail(f"dependencies: Outputs {outputs_deps}")
initial_deps = {u.variable.name: sorted(d.name for d in u.dependencies)
                for u in md.initialUnknowns}
expected = {"x": ["m1"], "v": ["m1"], "a": ["F", "m1"], "lambda": ["F", "m1"]}
if initial_deps != {k: d for k, d in expected.items() if k in vr}:
    fail(f"dependencies: InitialUnknowns {initial_deps}")
if not md.coSimulation.canInterpolateInputs:
    fail("canInterpolateInputs is false")
print("dependencies: a and lambda on F, x and v on none")

# 10. Direct feedthrough: a newly set F shows when a dependent output is read.
M1, M2 = 1.5, 2.0
F, A, LAMBDA, X, V = vr["F"], vr["a"], vr.get("lambda"), vr["x"], vr["v"]
READ = [r for r in [A, LAMBDA, X, V] if r is not None]


def check_change(what, before, after, dF):
    # lambda acts on mass 2 with the sign of its drives term: its magnitude.
    for name, ref, d in [("a", A, dF / (M1 + M2)), ("lambda", LAMBDA, M2 * dF / (M1 + M2))]:
        if ref is None:
            continue
        change = after[ref] - before[ref]
        off = abs(change - d) if name == "a" else abs(abs(change) - abs(d))
        if off > 1e-12:
            fail(f"{what}: {name} changed by {change!r}, expected {d!r} (off by {off:.3g})")
    for name, ref in [("x", X), ("v", V)]:
        if after[ref] != before[ref]:
            fail(f"{what}: {name} changed with F: {before[ref]} -> {after[ref]}")


def read(s):
    return dict(zip(READ, s.getReal(READ)))


s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="feedthrough")
s.instantiate()
s.setupExperiment(startTime=0.0)
s.setReal(parameters[:1], [M1])
s.enterInitializationMode()
before = read(s)
s.setReal([F], [70.0])
check_change("initialization mode", before, read(s), 70.0)
s.exitInitializationMode()
t = 0.0
for n in range(100):
    s.doStep(t, H)
    t += H
s.setReal([F], [30.0])
first = read(s)
s.setReal([F], [80.0])
second = read(s)
check_change("between steps", first, second, 50.0)
deviation = abs((second[A] - first[A]) - 50.0 / (M1 + M2))
s.setReal([F], [0.0])
state = s.getFMUstate()
s.doStep(t, 2 * H)
plain = s.getReal(outs)
s.setFMUstate(state)
s.setReal([F], [80.0])
read(s)
s.setReal([F], [0.0])
s.doStep(t, 2 * H)
after_read = s.getReal(outs)
if after_read != plain:
    fail(f"feedthrough: the step after a read differs: {plain} vs {after_read}")
s.setFMUstate(state)
s.setReal([F], [80.0])
s.doStep(t, 2 * H)
held = s.getReal(outs)
s.setFMUstate(state)
s.setReal([F], [80.0])
read(s)
s.doStep(t, 2 * H)
if s.getReal(outs) != held:
    fail("feedthrough: reading a before a step with F = 80 changed the step")
s.freeFMUstate(state)
s.terminate()
s.freeInstance()
print(f"feedthrough: a and lambda follow F at once (|Δa - ΔF/(m1+m2)| = {deviation:.2g}), "
      "the step after a read identical")


# 11. Input interpolation: a ramp force through fmi2SetRealInputDerivatives.


def ramp(every, derivatives):
    s = instance(f"ramp{every}{derivatives}", 1.0)
    xs = []
    # Over the FMU's experiment (1 s for the rigid pair, 0.5 s for its SSP).
    for n in range(round(float(md.defaultExperiment.stopTime) / (every * H))):
        t = n * every * H
        s.setReal([F], [RAMP_A + RAMP_B * t])
        if derivatives:
            s.setRealInputDerivatives([F], [1], [RAMP_B])
        s.doStep(t, every * H)
        xs.append((t + every * H, s.getReal([X])[0]))
    s.terminate()
    s.freeInstance()
    return xs


coarse, fine, held = ramp(10, True), ramp(1, True)[9::10], ramp(10, False)
error, error_held = ramp_error(coarse), ramp_error(held)
same = max(abs(a[1] - b[1]) for a, b in zip(coarse, fine))
if not error <= 5e-5:
    fail(f"interpolation: {error:.3g} m from the closed form (tolerance 5e-5)")
if not error_held > 1e-3:
    fail(f"interpolation: held inputs are only {error_held:.3g} m off: the check cannot tell")
if not same <= 1e-11:
    fail(f"interpolation: steps of 10 H differ from steps of H by {same:.3g} m")
s = instance("order3", 1.0)
for what, refs, order in [("order 3", [F], 3), ("an output", [X], 1)]:
    try:
        s.setRealInputDerivatives(refs, [order], [1.0])
        fail(f"interpolation: a derivative of {what} was accepted")
    except FMICallException as e:
        if e.status != 3:
            fail(f"interpolation: a derivative of {what}: status {e.status}, expected 3")
s.terminate()
s.freeInstance()
print(f"interpolation: ramp within {error:.3g} m of the closed form (held: {error_held:.3g} m), "
      f"steps of 10 H and of H agree to {same:.3g} m")
shutil.rmtree(unzipped, ignore_errors=True)
