"""String outputs and String connections through the Python package: the
Reference FMU Feedthrough (FMI 3.0, its ``String_output`` is its
``String_input``) sends text to a second instance. ``tether.run``'s result
has object fields holding the texts in its structured array, ``result[name]``
an object array of ``str``, ``to_pandas`` a column of ``str``; the numbers
stay float64 fields, and a stepped ``Simulation`` gives the same table.
crates/tether-cli/tests/string_signals.rs shows the same for ``tether run``."""
import numpy as np
import pytest

import tether
from conftest import need_tool

TEXT = 'a, "quoted" text'


def chain(fmu):
    return (
        tether.System("texts")
        .experiment(stop=0.03, step=0.01)
        .add_instance("src", fmu, {"String_input": TEXT})
        .add_instance("dst", fmu)
        .add_connection("src.String_output", "dst.String_input")
    )


def test_a_result_holds_string_outputs_as_object_fields(fmi3_reference):
    result = tether.run(chain(fmi3_reference("Feedthrough")))
    assert result.complete and len(result) == 4
    table = result.to_numpy()
    assert table.dtype["dst.String_output"] == np.dtype(object)
    assert table.dtype["dst.Float64_continuous_output"] == np.dtype("f8")
    assert list(table["dst.String_output"]) == [TEXT] * 4
    column = result["src.String_output"]
    assert column.dtype == np.dtype(object) and list(column) == [TEXT] * 4
    assert list(result.time) == pytest.approx([0.0, 0.01, 0.02, 0.03])
    # The String columns come last among an instance's outputs.
    src = [c for c in result.columns if c.startswith("src.")]
    assert src[-1] == "src.String_output"


def test_to_pandas_gives_a_column_of_str(fmi3_reference):
    need_tool("pandas")
    frame = tether.run(chain(fmi3_reference("Feedthrough"))).to_pandas()
    assert list(frame["dst.String_output"]) == [TEXT] * 4
    assert all(isinstance(v, str) for v in frame["dst.String_output"])
    assert frame["dst.Int32_output"].dtype == np.float64


def test_a_stepped_simulation_has_the_same_texts(fmi3_reference):
    system = chain(fmi3_reference("Feedthrough"))
    whole = tether.run(system)
    sim = tether.Simulation(system)
    result = sim.run()
    assert list(result["dst.String_output"]) == list(whole["dst.String_output"])
    assert list(result.columns) == list(whole.columns)


def test_gain_on_a_string_connection_is_refused_naming_it(fmi3_reference):
    fmu = fmi3_reference("Feedthrough")
    system = (
        tether.System("texts")
        .experiment(stop=0.03, step=0.01)
        .add_instance("src", fmu)
        .add_instance("dst", fmu)
        .add_connection("src.String_output", "dst.String_input", gain=2.0)
    )
    with pytest.raises(tether.TetherError, match=r"src\.String_output → dst\.String_input: "
                       r"gain and offset apply to Real connections only"):
        tether.run(system)
