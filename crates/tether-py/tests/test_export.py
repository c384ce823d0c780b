"""tether.export_fmu (docs/fmu-export.md): the rigid pair of
examples/rigid_pair_export.toml exported from Python — from its path and from
a tether.System, as FMI 2.0 and as FMI 3.0 — with the runtime library shipped
in the package. fmpy validates the FMU, and its simulate_fmu on the system's
grid gives tether.run's numbers of the same system bit for bit, also with a
member isolated (the FMU then carries the package's host program). An SSP
(examples/rigid_pair_ssp as .ssp, .ssd and folder) exports with its root
connectors as the interface, read by the loader of `tether run`; fmpy runs it
as `tether run`, tether.run, tether.run_many and tether.Simulation of the
same SSP, bit for bit."""

import pytest
import tether
from conftest import cli, need_tool, read_csv, same_bits


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


@pytest.fixture(scope="module")
def pair_ssp(tmp_path_factory, root, oscillator_fmu):
    """examples/rigid_pair_ssp as an .ssp archive, its SSD in an unpacked
    folder and the SSD file itself (the FMU in resources/, as in
    crates/tether-cli/tests/fmu_export.rs)."""
    import zipfile

    base = tmp_path_factory.mktemp("ssp")
    folder = base / "folder"
    (folder / "resources").mkdir(parents=True)
    ssd = (root / "examples" / "rigid_pair_ssp" / "SystemStructure.ssd").read_text()
    ssd = ssd.replace("../../target/fmus/oscillator.fmu", "resources/oscillator.fmu")
    (folder / "SystemStructure.ssd").write_text(ssd)
    (folder / "resources" / "oscillator.fmu").write_bytes(oscillator_fmu.read_bytes())
    archive = base / "rigid_pair.ssp"
    with zipfile.ZipFile(archive, "w") as z:
        z.write(folder / "SystemStructure.ssd", "SystemStructure.ssd")
        z.write(folder / "resources" / "oscillator.fmu", "resources/oscillator.fmu")
    return {"ssp": archive, "folder": folder, "ssd": folder / "SystemStructure.ssd"}


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("given", ["ssp", "ssd", "folder"])
def test_an_ssp_exports_with_its_root_connectors_and_runs_in_fmpy_as_tether_run(
    tmp_path, pair_ssp, tether_bin, given, fmi
):
    fmpy = need_tool("fmpy")
    validation = need_tool("fmpy.validation")
    system = pair_ssp[given]
    fmu = tmp_path / "rigid_pair_ssp.fmu"
    assert tether.export_fmu(system, fmu, fmi=fmi) == str(fmu)
    assert validation.validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    assert md.coSimulation.modelIdentifier == "rigid_pair_ssp"
    causality = {v.name: v.causality for v in md.modelVariables if v.name != "time"}
    assert causality == {"m1": "parameter", "F": "input", "x": "output", "v": "output",
                         "a": "output"}
    names = ["x", "v", "a"]
    theirs = fmpy.simulate_fmu(str(fmu), output_interval=1e-3, output=names)
    # `tether run` of the same SSP, and tether.run and tether.Simulation of it.
    csv = tmp_path / "run.csv"
    proc = cli(tether_bin, "run", str(system), "--out", str(csv))
    assert proc.returncode == 0, proc.stderr
    header, rows, _ = read_csv(csv)
    ours = tether.run(system)
    (many,) = tether.run_many(system, [{}])
    sim = tether.Simulation(system)
    sim.run()
    stepped = sim.result()
    assert len(theirs) == len(rows) == len(ours) == len(stepped) == 501
    assert theirs["time"].tobytes() == ours.time.tobytes()
    for name in names:
        column = f"mass1.{name}"
        cli_column = rows[:, header.index(column)]
        assert same_bits(theirs[name], cli_column), name
        assert same_bits(ours[column], cli_column), name
        assert same_bits(stepped[column], cli_column), name
        assert same_bits(many[column], cli_column), name


def test_an_ssp_without_its_fmu_gets_one_clear_line(tmp_path, pair_ssp):
    folder = tmp_path / "broken"
    folder.mkdir()
    (folder / "SystemStructure.ssd").write_text(pair_ssp["ssd"].read_text())
    with pytest.raises(tether.TetherError, match=r"oscillator\.fmu"):
        tether.export_fmu(folder, tmp_path / "x.fmu")
    with pytest.raises(tether.TetherError, match=r"oscillator\.fmu"):
        tether.run(folder)
