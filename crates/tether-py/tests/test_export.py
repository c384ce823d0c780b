"""tether.export_fmu (docs/fmu-export.md): the rigid pair of
examples/rigid_pair_export.toml exported from Python — from its path and from
a tether.System, as FMI 2.0 and as FMI 3.0 — with the runtime library shipped
in the package. fmpy validates the FMU, and its simulate_fmu on the system's
grid gives tether.run's numbers of the same system bit for bit, also with a
member isolated (the FMU then carries the package's host program)."""

import pytest
import tether
from conftest import need_tool


@pytest.fixture(scope="module")
def pair_toml(root, oscillator_fmu):
    return root / "examples" / "rigid_pair_export.toml"


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("given", ["path", "system"])
def test_the_exported_pair_validates_and_runs_in_fmpy_as_tether_run(tmp_path, pair_toml, given, fmi):
    fmpy = need_tool("fmpy")
    validation = need_tool("fmpy.validation")
    system = pair_toml if given == "path" else tether.System.from_file(pair_toml)
    fmu = tmp_path / "rigid_pair.fmu"
    assert tether.export_fmu(system, fmu, fmi=fmi) == str(fmu)
    assert validation.validate_fmu(str(fmu)) == []
    assert fmpy.read_model_description(str(fmu)).fmiVersion == f"{fmi}.0"
    names = ["x", "v", "a", "lambda"]
    theirs = fmpy.simulate_fmu(str(fmu), output_interval=1e-3, output=names)
    ours = tether.run(pair_toml)
    assert len(theirs) == len(ours) == 1001
    assert theirs["time"].tobytes() == ours.time.tobytes()
    for name, column in zip(names, ["mass1.x", "mass1.v", "mass1.a", "link.lambda"]):
        assert theirs[name].tobytes() == ours[column].tobytes(), name


def test_a_system_without_an_export_table_gets_one_clear_line(tmp_path, oscillator_toml):
    with pytest.raises(tether.TetherError, match=r"no \[export\] table"):
        tether.export_fmu(oscillator_toml, tmp_path / "x.fmu")


def test_an_fmi_version_other_than_2_or_3_gets_one_clear_line(tmp_path, pair_toml):
    with pytest.raises(tether.TetherError, match=r"FMI version 4: an exported FMU is FMI 2"):
        tether.export_fmu(pair_toml, tmp_path / "x.fmu", fmi=4)


def test_an_isolated_member_runs_from_the_exported_fmu_with_the_packages_host(tmp_path, pair_toml):
    fmpy = need_tool("fmpy")
    system = tether.System.from_file(pair_toml)
    system.instances[1]["isolation"] = "process"
    fmu = tmp_path / "isolated_pair.fmu"
    tether.export_fmu(system, fmu)
    names = ["x", "v", "a", "lambda"]
    theirs = fmpy.simulate_fmu(str(fmu), output_interval=1e-3, output=names)
    ours = tether.run(pair_toml)
    assert len(theirs) == len(ours) == 1001
    for name, column in zip(names, ["mass1.x", "mass1.v", "mass1.a", "link.lambda"]):
        assert theirs[name].tobytes() == ours[column].tobytes(), name
