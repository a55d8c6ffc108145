"""IOData of several outputs: construction, the views of all outputs, the transformations, the
readers, and the clear error of every single-output path that receives them."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import arxid
from arxid.exceptions import DataError
from subspace_systems import add_noise, as_data, binary_inputs, random_system


def rates(n: int = 200) -> arxid.IOData:
    rng = np.random.default_rng(3)
    y = rng.normal(size=(n, 3))
    u = rng.normal(size=(n, 4))
    return arxid.IOData(
        y,
        u,
        ts=0.01,
        output_name=["p", "q", "r"],
        output_unit="rad/s",
        input_names=["m1", "m2", "m3", "m4"],
        extra={"vbat": np.linspace(16, 15, n)},
    )


def test_outputs_are_the_columns_with_their_names_and_units():
    d = rates()
    assert d.n_outputs == 3 and d.output_names == ("p", "q", "r")
    assert d.output_units == ("rad/s",) * 3
    assert d.outputs.shape == (200, 3) and not d.outputs.flags.writeable
    q = d.output("q")
    assert q.n_outputs == 1 and q.output_name == "q" and q.output_unit == "rad/s"
    np.testing.assert_array_equal(q.y, d.outputs[:, 1])
    np.testing.assert_array_equal(q.u, d.u)
    assert q.input_names == d.input_names and list(q.extra) == ["vbat"]
    np.testing.assert_array_equal(d.signal("r"), d.outputs[:, 2])
    assert d.unit("p") == "rad/s" and d.signal_names[:3] == ("p", "q", "r")


def test_single_output_data_keep_their_meaning():
    d = arxid.IOData(np.arange(5.0), np.ones(5), ts=0.1, output_name="roll", output_unit="deg/s")
    assert d.output_names == ("roll",) and d.n_outputs == 1 and d.output_units == ("deg/s",)
    assert d.y.shape == (5,) and d.outputs.shape == (5, 1)
    assert d.output("roll").y is not None
    one = arxid.IOData(np.arange(5.0)[:, None], np.ones(5), ts=0.1, output_name=["roll"])
    assert one.output_name == "roll" and one.y.shape == (5,)


@pytest.mark.parametrize("field", ["y", "output_name", "output_unit"])
def test_reading_a_single_output_field_of_several_outputs_names_what_to_do(field):
    with pytest.raises(DataError, match=r"3 outputs \(p, q, r\).*data\.output\('p'\).*arxid\.ssest"):
        getattr(rates(), field)


def test_single_output_paths_refuse_several_outputs_with_the_advice():
    d = rates()
    with pytest.raises(DataError, match=r"data\.output\('p'\)"):
        arxid.arx(d, 2, 2, 1)
    with pytest.raises(DataError, match=r"data\.output\('p'\)"):
        arxid.sweep(d)
    with pytest.raises(DataError, match=r"data\.output\('p'\)"):
        d.signal("y")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"output_name": "p"}, r"3 columns but one output name"),
        ({"output_name": ["p", "q"]}, r"2 output names given for 3 output columns"),
        ({"output_name": ["p", "q", "r"], "output_unit": ["a", "b"]}, r"2 output units given for 3 outputs"),
        ({"output_name": ["p", "q", "m1"], "input_names": ["m1"]}, r"unique.*m1"),
        ({"output_name": [1, 2, 3]}, r"output_name must be a string"),
    ],
)
def test_wrong_output_names_are_data_errors(kwargs, message):
    with pytest.raises(DataError, match=message):
        arxid.IOData(np.zeros((10, 3)), np.zeros(10), ts=1.0, **kwargs)


def test_transformations_keep_every_output():
    d = rates()
    part = d[50:150]
    np.testing.assert_array_equal(part.outputs, d.outputs[50:150])
    assert part.output_names == d.output_names
    est, val = d.split(0.5)
    assert est.n_samples == val.n_samples == 100 and val.n_outputs == 3
    both = arxid.IOData.merge([est, val])
    np.testing.assert_array_equal(both.outputs, d.outputs)
    assert both.experiment_starts == (0, 100)
    centred = both.detrend()
    np.testing.assert_allclose(centred.outputs[:100].mean(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(centred.outputs[100:].mean(axis=0), 0, atol=1e-12)
    other = d.with_signals(u=np.zeros((200, 1)))
    assert other.output_names == ("p", "q", "r") and other.n_inputs == 1
    assert pickle.loads(pickle.dumps(d)).output_names == d.output_names
    assert "outputs: p [rad/s], q [rad/s], r [rad/s]" in repr(d)


def test_merging_data_of_other_outputs_is_refused():
    d = rates()
    with pytest.raises(DataError, match="same output"):
        arxid.IOData.merge([d, d.output("p")])


def test_from_csv_and_from_pandas_read_several_outputs(tmp_path):
    d = rates()
    path = tmp_path / "rates.csv"
    table = np.column_stack([d.outputs, d.u])
    np.savetxt(path, table, delimiter=",", header="p[rad/s],q[rad/s],r[rad/s],m1,m2,m3,m4", comments="")
    read = arxid.IOData.from_csv(path, output=["p", "q", "r"], inputs=["m1", "m2", "m3", "m4"], ts=0.01)
    assert read.output_names == ("p", "q", "r") and read.output_units == ("rad/s",) * 3
    np.testing.assert_allclose(read.outputs, d.outputs, rtol=1e-15)
    single = arxid.IOData.from_csv(path, output="q", inputs=["m1"], ts=0.01)
    np.testing.assert_allclose(single.y, d.outputs[:, 1], rtol=1e-15)
    pd = pytest.importorskip("pandas")
    frame = d.to_pandas()
    assert list(frame.columns[:4]) == ["time", "p", "q", "r"]
    back = arxid.IOData.from_pandas(frame, output=["r", "p"], inputs=["m1", "m2"], time="time")
    np.testing.assert_array_equal(back.outputs, d.outputs[:, [2, 0]])
    assert isinstance(frame, pd.DataFrame)


def test_ssest_takes_data_of_several_outputs_as_a_list_of_one_per_output():
    rng = np.random.default_rng(11)
    system = random_system(rng, 4, 2, 3)
    u = binary_inputs(rng, 3000, 2)
    y = add_noise(rng, system.simulate(u), 30)
    together = arxid.IOData(y, u, ts=0.01, output_name=["y1", "y2", "y3"])
    one = arxid.ssest(together, order=4)
    per_output = arxid.ssest(as_data(y, u), order=4)
    assert one.output_names == ("y1", "y2", "y3")
    np.testing.assert_allclose(np.sort_complex(one.poles), np.sort_complex(per_output.poles), atol=1e-12)
    np.testing.assert_allclose(one.fit_percent(together), per_output.fit_percent(as_data(y, u)), atol=1e-9)


@pytest.mark.realdata
def test_a_betaflight_log_read_with_three_gyro_outputs(shared_data):
    """The three gyro axes of a real log against four motor commands: each output is the one a
    single-output read gives, and a state-space model predicts them one step ahead."""
    path = shared_data / "betaflight-blackbox" / "LOG00037.BFL"
    gyro, motors = [f"gyroADC[{i}]" for i in range(3)], [f"motor[{i}]" for i in range(4)]
    rates = arxid.IOData.from_blackbox(path, output=gyro, inputs=motors)
    assert rates.output_names == ("gyroADC_0", "gyroADC_1", "gyroADC_2")
    assert rates.output_units == ("deg/s",) * 3
    pitch = arxid.IOData.from_blackbox(path, output=gyro[1], inputs=motors)
    np.testing.assert_array_equal(rates.output("gyroADC_1").y, pitch.y)
    est, val = rates.detrend().split(0.7)
    fits = arxid.ssest(est).fit_percent(val, k=1)
    assert np.all(fits > 60), fits


def test_a_model_refuses_its_outputs_in_another_order():
    rng = np.random.default_rng(4)
    system = random_system(rng, 2, 1, 2)
    u = binary_inputs(rng, 1500, 1)
    data = arxid.IOData(system.simulate(u), u, ts=0.01, output_name=["a", "b"])
    model = arxid.ssest(data, order=2)
    with pytest.raises(DataError, match=r"another order than the model's \['a', 'b'\]"):
        model.predict(data.with_outputs(data.outputs[:, ::-1], ["b", "a"]))
    np.testing.assert_allclose(model.fit_percent(data), 100.0, atol=1e-6)
