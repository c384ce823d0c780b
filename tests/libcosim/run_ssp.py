"""Run an SSP system in libcosim (through libcosimpy) with its fixed-step
(Jacobi) algorithm and write the given Real variables at every step as CSV.

    python run_ssp.py SSP_DIR STEP STOP OUT.csv INSTANCE.VARIABLE...

SSP_DIR is an unpacked SSP folder; STEP and STOP are in seconds. A STEP
written `ssp:H` leaves the step to the SSP (OSP's FixedStepAlgorithm
annotation, which must say H); the rows are at multiples of H.
"""

import sys

from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver


def main():
    ssp_dir, step, stop, out = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
    columns = sys.argv[5:]
    from_ssp = step.startswith("ssp:")
    step = float(step.removeprefix("ssp:"))
    step_ns = round(step * 1e9)
    steps = round(stop / step)
    if from_ssp:
        execution = CosimExecution.from_ssp_file(ssp_path=ssp_dir)
    else:
        execution = CosimExecution.from_ssp_file(ssp_path=ssp_dir, step_size=step_ns)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer=observer)
    reads = []
    for column in columns:
        instance, variable = column.split(".", 1)
        index = execution.slave_index_from_instance_name(instance)
        refs = {v.name.decode(): v.reference for v in execution.slave_variables(index)}
        reads.append((index, refs[variable]))

    def row(t):
        values = [observer.last_real_values(i, [vr])[0] for i, vr in reads]
        return ",".join([repr(t)] + [repr(v) for v in values])

    lines = [",".join(["time"] + columns)]
    # The first step initialises the slaves and passes the values at T_0.
    for n in range(steps):
        assert execution.step(), f"libcosim step {n} failed"
        lines.append(row((n + 1) * step))
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
