"""FMI 3.0 FMUs through the Python package: `tether.run`, `tether.Simulation`
and the `System` builder take FMI 3.0 instances as `tether run` does. The kit
builds each workspace FMU as FMI 2.0 (`oscillator.fmu`) and FMI 3.0
(`oscillator-fmi3.fmu`) from the same model code; with inputs held over the
step (k = 0) both give the same numbers bit for bit, alone and mixed in one
system (crates/tether-cli/tests/fmi3_kit.rs shows the same for `tether run`)."""
import numpy as np
import pytest

import tether
from conftest import same_bits
from test_remote import LINK, MASS


@pytest.fixture(scope="module")
def oscillator_fmi3(oscillator_fmu):
    path = oscillator_fmu.with_name("oscillator-fmi3.fmu")
    if not path.exists():
        pytest.fail(f"{path} is missing: run `cargo xtask fmus`")
    return path


def pair(mass1, mass2):
    return (
        tether.System("two-mass oscillator")
        .experiment(stop=0.5, step=1e-3)
        .method("baumgarte", beta=2e-3, gamma=1e-6)
        .coupling(order=0)
        .add_instance("mass1", mass1, {"m": 1.0, **MASS})
        .add_instance("mass2", mass2, {"m": 2.0, **MASS})
        .add_constraint("link", **LINK, initial="consistent")
    )


def table(result):
    return result.to_numpy().view(np.float64).reshape(len(result), -1)


@pytest.mark.parametrize("fmi3_instances", ["both", "mass2"])
def test_run_with_fmi3_instances_equals_fmi2_bit_for_bit(oscillator_fmu, oscillator_fmi3,
                                                         fmi3_instances):
    mass1 = oscillator_fmi3 if fmi3_instances == "both" else oscillator_fmu
    fmi3 = tether.run(pair(mass1, oscillator_fmi3))
    fmi2 = tether.run(pair(oscillator_fmu, oscillator_fmu))
    assert fmi3.complete and fmi3.columns == fmi2.columns
    assert fmi3.stats["macro_steps"] == 500
    assert same_bits(table(fmi3), table(fmi2))


def test_a_stepped_simulation_of_fmi3_instances_equals_a_whole_fmi2_run(oscillator_fmu,
                                                                        oscillator_fmi3):
    whole = tether.run(pair(oscillator_fmu, oscillator_fmu))
    sim = tether.Simulation(pair(oscillator_fmi3, oscillator_fmi3))
    assert sim.run_until(0.25) == pytest.approx(0.25)
    assert sim.outputs["mass2.x"] == whole["mass2.x"][250]
    assert sim.unknowns[0] == whole["link.lambda"][250]
    result = sim.run()
    assert result.complete
    assert same_bits(table(result), table(whole))



def test_integers_beyond_2_to_the_53_are_named_where_the_floats_round_them(fmi3_reference):
    """The results are floats: an Int64 output beyond 2^53 (the Reference
    Feedthrough passes its input through) is rounded there, and a UserWarning
    names the column (`tether run`'s CSV writes it exactly)."""
    fmu = fmi3_reference("Feedthrough")
    big = 2**53 + 1
    with pytest.warns(UserWarning, match=r"Int64_output.*rounded"):
        result = tether.simulate(fmu, stop=0.1, step=0.1, parameters={"Int64_input": big})
    assert result["Int64_output"][0] == float(big)
    small = tether.simulate(fmu, stop=0.1, step=0.1, parameters={"Int64_input": 2**53})
    assert small["Int64_output"][0] == 2.0**53
