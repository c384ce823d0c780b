"""OSP's quarter truck driven by FMPy the way libcosim's fixed-step algorithm
drives it (Jacobi: step both, then pass chassis.velocity -> wheel.in_vel and
wheel.out_spring_damper_f -> chassis.force), with the fmi2DoStep time
arguments of one master or the other, writing every output after every step:

    python quarter_truck_fmpy.py FMU_DIR H STOP TIMES OUT.csv COLUMN...

TIMES is `libcosim`: t_n = (n * H_ns) / 1e9 and h = t_{n+1} - t_n, from
libcosim's integer nanoseconds (its to_double_time_point and
to_double_duration); or `tether`: t_n = n * H and h = H.
"""

import sys

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


def instance(path, name, mass):
    md = read_model_description(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    refs = {v.name: v.valueReference for v in md.modelVariables}
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.setReal([refs["mass"]], [mass])
    fmu.setString([refs["solverType"]], ["Euler"])
    fmu.setReal([refs["timeStep"]], [1e-5])
    fmu.enterInitializationMode()
    return fmu, refs


def main():
    fmu_dir, h, stop, times, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4], sys.argv[5]
    columns = sys.argv[6:]
    chassis = instance(f"{fmu_dir}/Chassis.fmu", "chassis", 400.0)
    wheel = instance(f"{fmu_dir}/Wheel.fmu", "wheel", 40.0)
    by_name = {"chassis": chassis, "wheel": wheel}

    def get(name, variable):
        fmu, refs = by_name[name]
        return fmu.getReal([refs[variable]])[0]

    def transfer():
        velocity, force = get("chassis", "velocity"), get("wheel", "out_spring_damper_f")
        wheel[0].setReal([wheel[1]["in_vel"]], [velocity])
        chassis[0].setReal([chassis[1]["force"]], [force])

    transfer()
    for fmu, _ in (chassis, wheel):
        fmu.exitInitializationMode()
    transfer()
    h_ns = round(h * 1e9)
    lines = [",".join(["time"] + columns)]
    for n in range(round(stop / h)):
        if times == "libcosim":
            t, t_next = (n * h_ns) / 1e9, ((n + 1) * h_ns) / 1e9
            step = t_next - t
        else:
            t, step, t_next = n * h, h, (n + 1) * h
        for fmu, _ in (chassis, wheel):
            fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
        transfer()
        values = [get(*c.split(".", 1)) for c in columns]
        lines.append(",".join([repr(t_next)] + [repr(v) for v in values]))
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
