"""Gyroscope CSV files as phones and IMU loggers export them: `read_gyro_csv`, `write_gyro_csv`."""

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import integrators as it
import liepoisson as lp

EPS = np.finfo(np.float64).eps
BODY = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
PHYPHOX = '"Time (s)","Gyroscope x (rad/s)","Gyroscope y (rad/s)","Gyroscope z (rad/s)","Absolute (rad/s)"\n'


def write(tmp_path, text, name="gyro.csv", encoding="utf-8"):
    path = tmp_path / name
    path.write_text(text, encoding=encoding)
    return path


def observations(lengths=(5, 3), seed=0):
    rng = np.random.default_rng(seed)
    times = [np.cumsum(rng.uniform(0.005, 0.02, n)) - 0.01 for n in lengths]  # each from its own clock
    return it.BodyObservations(BODY, times, velocities=[rng.normal(size=(n, 3)) for n in lengths])


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def assert_same(read, data):
    assert read.n_trajectories == data.n_trajectories
    for t, v, t0, v0 in zip(read.times, read.velocities, data.times, data.velocities):
        np.testing.assert_array_equal(bits(t), bits(t0))  # exact, to the sign of a zero
        np.testing.assert_array_equal(bits(v), bits(v0))


def test_round_trip_is_exact(tmp_path):
    data = observations()
    path = tmp_path / "out" / "flights.csv"
    it.write_gyro_csv(path, data)
    assert os.listdir(path.parent) == ["flights.csv"]  # no temporary left behind
    assert path.read_text().splitlines()[0] == "time (s),gyro_x (rad/s),gyro_y (rad/s),gyro_z (rad/s),event"
    read = it.read_gyro_csv(path, BODY)
    assert_same(read, data)
    assert read.configurations is None
    assert read.metadata["file"] == "flights.csv"
    assert read.metadata["units"] == "rad/s"
    assert read.metadata["segments"] == [[float(t[0]), float(t[-1])] for t in data.times]
    assert read.metadata["lines"] == [[2, 6], [7, 9]]


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def flights(draw):
    out_t, out_v = [], []
    for _ in range(draw(st.integers(1, 3))):
        t = sorted(draw(st.sets(finite, min_size=2, max_size=6)))
        out_t.append(np.array(t))
        out_v.append(np.array(draw(st.lists(st.tuples(finite, finite, finite), min_size=len(t), max_size=len(t)))))
    return out_t, out_v


@settings(max_examples=50, deadline=None)
@given(flights())
def test_round_trip_is_exact_for_any_floats(tmp_path_factory, data):
    data = it.BodyObservations(BODY, data[0], velocities=data[1])
    path = tmp_path_factory.mktemp("hypothesis") / "any.csv"
    it.write_gyro_csv(path, data)
    assert_same(it.read_gyro_csv(path, BODY), data)


def test_degrees_per_second_are_converted_by_hand(tmp_path):
    path = write(tmp_path, "t,gyro_x [deg/s],gyro_y [deg/s],gyro_z [deg/s]\n0,90,-180,1.5\n0.01,360,0,-45\n")
    read = it.read_gyro_csv(path, BODY)
    expected = [[math.pi / 2, -math.pi, 1.5 * math.pi / 180], [2 * math.pi, 0.0, -math.pi / 4]]
    np.testing.assert_allclose(read.velocities[0], expected, rtol=EPS, atol=0)  # one rounding of x * (pi/180)
    np.testing.assert_array_equal(read.times[0], [0.0, 0.01])
    assert read.metadata["units"] == "deg/s"


def test_degrees_round_trip_to_a_rounding(tmp_path):
    data = observations()
    it.write_gyro_csv(tmp_path / "deg.csv", data, units="deg/s")
    assert "gyro_x (deg/s)" in (tmp_path / "deg.csv").read_text()
    read = it.read_gyro_csv(tmp_path / "deg.csv", BODY)
    for v, v0 in zip(read.velocities, data.velocities):
        np.testing.assert_allclose(v, v0, rtol=4 * EPS, atol=0)  # x / (pi/180) * (pi/180): two roundings and one of repr


def test_phyphox_export_with_a_byte_order_mark_and_quoted_header(tmp_path):
    rows = "0.0,0.1,0.2,0.3,0.374\n0.01,0.4,0.5,0.6,0.877\n0.02,0.7,0.8,0.9,1.39\n"
    path = write(tmp_path, PHYPHOX + rows, encoding="utf-8-sig")
    assert path.read_bytes().startswith(b"\xef\xbb\xbf")
    read = it.read_gyro_csv(path, BODY)
    np.testing.assert_array_equal(read.velocities[0], [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6], [0.7, 0.8, 0.9]])
    np.testing.assert_array_equal(read.times[0], [0.0, 0.01, 0.02])
    assert read.metadata["time"] == "Time (s)"
    assert read.metadata["rates"] == ["Gyroscope x (rad/s)", "Gyroscope y (rad/s)", "Gyroscope z (rad/s)"]


def test_semicolons_and_tabs_with_dot_decimals_are_read(tmp_path):
    for delimiter in (";", "\t"):
        text = PHYPHOX.replace(",", delimiter) + f"0.0{delimiter}1{delimiter}2{delimiter}3{delimiter}4\n" \
            f"0.5{delimiter}5{delimiter}6{delimiter}7{delimiter}8\n"
        read = it.read_gyro_csv(write(tmp_path, text), BODY)
        np.testing.assert_array_equal(read.velocities[0], [[1.0, 2.0, 3.0], [5.0, 6.0, 7.0]])


def test_columns_are_found_by_name_in_any_order(tmp_path):
    # Sensor Logger: `time` in nanoseconds, `seconds_elapsed` in seconds, axes z, y, x
    path = write(tmp_path, "time,seconds_elapsed,z,y,x\n1700000000000000000,0.0,3,2,1\n1700000000010000000,0.01,6,5,4\n")
    read = it.read_gyro_csv(path, BODY, units="rad/s")
    np.testing.assert_array_equal(read.times[0], [0.0, 0.01])
    np.testing.assert_array_equal(read.velocities[0], [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])


def test_explicit_columns_and_units(tmp_path):
    path = write(tmp_path, "clock,a (deg/s),b (deg/s),c (deg/s)\n0,1,2,3\n1,4,5,6\n")
    read = it.read_gyro_csv(path, BODY, time="clock", rates=("c", "b", "a"), units="rad/s")  # units= overrides
    np.testing.assert_array_equal(read.velocities[0], [[3.0, 2.0, 1.0], [6.0, 5.0, 4.0]])
    read = it.read_gyro_csv(write(tmp_path, "t,wx,wy,wz\n0,1,2,3\n1,4,5,6\n"), BODY, units="deg/s")
    np.testing.assert_allclose(read.velocities[0][0], [math.pi / 180, 2 * math.pi / 180, 3 * math.pi / 180], rtol=EPS)


EVENTS = ("t,wx (rad/s),wy (rad/s),wz (rad/s),event\n"
          "0.0,9,9,9,\n"
          "0.1,1,0,0,start\n"
          "0.2,2,0,0,\n"
          "0.3,3,0,0,STOP\n"
          "0.4,9,9,9,\n"
          "0.5,4,0,0, Start \n"
          "0.6,5,0,0,stop\n")


def test_segments_by_events(tmp_path):
    read = it.read_gyro_csv(write(tmp_path, EVENTS), BODY)
    assert read.n_trajectories == 2
    np.testing.assert_array_equal(read.times[0], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(read.times[1], [0.5, 0.6])
    np.testing.assert_array_equal(read.velocities[1][:, 0], [4.0, 5.0])
    assert read.metadata["segments"] == [[0.1, 0.3], [0.5, 0.6]]
    assert read.metadata["lines"] == [[3, 5], [7, 8]]
    renamed = write(tmp_path, EVENTS.replace("event", "flight"), "renamed.csv")
    assert it.read_gyro_csv(renamed, BODY, events="flight").n_trajectories == 2
    assert it.read_gyro_csv(renamed, BODY).n_trajectories == 1  # no event column: the whole file
    adjacent = write(tmp_path, HEADER[:-1] + ",event\n0,1,2,3,start\n0.1,1,2,3,stop\n0,1,2,3,start\n0.1,1,2,3,stop\n",
                     "adjacent.csv")  # the clock restarts between flights: allowed with events
    np.testing.assert_array_equal(it.read_gyro_csv(adjacent, BODY).times, [[0.0, 0.1], [0.0, 0.1]])


def test_segments_by_time_windows(tmp_path):
    read = it.read_gyro_csv(write(tmp_path, EVENTS), BODY, segments=[(0.05, 0.25), (0.4, 0.6)])
    np.testing.assert_array_equal(read.times[0], [0.1, 0.2])
    np.testing.assert_array_equal(read.times[1], [0.4, 0.5, 0.6])  # the event column is not used
    assert read.metadata["segments"] == [[0.05, 0.25], [0.4, 0.6]]
    assert read.metadata["lines"] == [[3, 4], [6, 8]]


HEADER = "t,wx (rad/s),wy (rad/s),wz (rad/s)\n"
BAD_FILES = {
    "comma decimal": ("t;wx (rad/s);wy (rad/s);wz (rad/s)\n0,0;0,123;1,5;2\n0,01;1;2;3\n",
                      r"line 2, column 't': '0,0' has a comma as decimal separator; re-export .* dot"),
    "comma decimal, comma delimiter": (HEADER + "0,0,0,123,1,5,2\n", r"line 2: 7 fields; the header has 4 .*comma decimal"),
    "quoted comma decimal": (HEADER + '"0,5",1,2,3\n1,1,2,3\n', r"'0,5' has a comma as decimal separator"),
    "repeated time": (HEADER + "0,1,2,3\n0.1,1,2,3\n0.1,1,2,3\n", r"line 4, column 't': time 0.1 repeats 0.1 on line 3"),
    "decreasing time": (HEADER + "0,1,2,3\n0.2,1,2,3\n0.1,1,2,3\n", r"line 4, .*time 0.1 is before 0.2"),
    "nan": (HEADER + "0,1,2,3\n0.1,nan,2,3\n", r"line 3, column 'wx \(rad/s\)' is 'nan'; values must be finite"),
    "infinite time": (HEADER + "0,1,2,3\ninf,1,2,3\n", r"line 3, column 't' is 'inf'"),
    "empty field": (HEADER + "0,1,2,3\n0.1,1,,3\n", r"line 3, column 'wy \(rad/s\)' is empty"),
    "text": (HEADER + "0,1,2,3\n0.1,1,two,3\n", r"line 3, column 'wy \(rad/s\)': 'two' is not a number"),
    "short row": (HEADER + "0,1,2,3\n0.1,1,2\n", r"line 3: 3 fields; the header has 4"),
    "no time column": ("clock,wx (rad/s),wy (rad/s),wz (rad/s)\n0,1,2,3\n", r"no time column.*pass time="),
    "two time columns": ("t,time,wx (rad/s),wy (rad/s),wz (rad/s)\n0,0,1,2,3\n", r"several time columns.*pass time="),
    "time in ms": ("time (ms),wx (rad/s),wy (rad/s),wz (rad/s)\n0,1,2,3\n", r"'time \(ms\)' is in 'ms'; expected seconds"),
    "no rate columns": ("t,ax,ay,az\n0,1,2,3\n", r"no gyroscope rate columns.*pass rates="),
    "two sets of rates": ("t,wx,wy,wz,gyro_x,gyro_y,gyro_z\n0,1,2,3,1,2,3\n", r"more than one set of gyroscope"),
    "no units": ("t,wx,wy,wz\n0,1,2,3\n1,1,2,3\n", r"units .* are missing, unknown or differ.*pass units="),
    "unknown units": ("t,wx (rpm),wy (rpm),wz (rpm)\n0,1,2,3\n1,1,2,3\n", r"read \['rpm', 'rpm', 'rpm'\].*pass units="),
    "mixed units": ("t,wx (rad/s),wy (deg/s),wz (rad/s)\n0,1,2,3\n1,1,2,3\n", r"differ.*pass units="),
    "empty": ("", r"is empty"),
    "blank lines": ("\n  \n\n", r"is empty"),
    "header only": (HEADER, r"has a header and no rows"),
    "one column": ("hello world\nfoo\n", r"one column"),
    "json": ('{"t": [0, 1], "wx": [1, 2]}\n', r"no time column"),
    "start without stop": (HEADER[:-1] + ",event\n0,1,2,3,start\n0.1,1,2,3,\n", r"line 2, column 'event': 'start' with no"),
    "stop without start": (HEADER[:-1] + ",event\n0,1,2,3,\n0.1,1,2,3,stop\n", r"line 3, .*'stop' without a 'start'"),
    "start twice": (HEADER[:-1] + ",event\n0,1,2,3,start\n0.1,1,2,3,start\n", r"line 3, .*'start' again"),
    "unknown event": (HEADER[:-1] + ",event\n0,1,2,3,jump\n0.1,1,2,3,\n", r"'jump'; expected 'start', 'stop'"),
    "repeated time in a segment": (HEADER[:-1] + ",event\n0,1,2,3,start\n0,1,2,3,stop\n",
                                   r"line 3, column 't': time 0.0 repeats"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_files_are_refused_naming_the_file_and_the_problem(tmp_path, name):
    text, match = BAD_FILES[name]
    path = write(tmp_path, text)
    with pytest.raises(ValueError, match=match) as err:
        it.read_gyro_csv(path, BODY)
    assert str(path) in str(err.value)


def test_binary_and_foreign_encodings_are_refused(tmp_path):
    binary = tmp_path / "data.bin"
    binary.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ValueError, match=r"data.bin' holds binary data"):
        it.read_gyro_csv(binary, BODY)
    utf16 = write(tmp_path, HEADER + "0,1,2,3\n", "utf16.csv", encoding="utf-16")
    with pytest.raises(ValueError, match=r"utf16.csv' holds binary data .*UTF-16"):
        it.read_gyro_csv(utf16, BODY)
    latin = tmp_path / "latin.csv"
    latin.write_bytes("t,wx (°/s),wy (°/s),wz (°/s)\n0,1,2,3\n".encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin.csv' is not UTF-8 text"):
        it.read_gyro_csv(latin, BODY)


def test_degree_sign_and_other_spellings_of_units(tmp_path):
    path = write(tmp_path, "t,wx (°/s),wy (deg s^-1),wz (dps)\n0,180,180,180\n1,0,0,0\n")
    np.testing.assert_allclose(it.read_gyro_csv(path, BODY).velocities[0][0], [math.pi] * 3, rtol=EPS)


def test_bad_windows_and_arguments(tmp_path):
    path = write(tmp_path, EVENTS)
    with pytest.raises(ValueError, match=r"segment 1 \(t from 0.42 to 0.48\) holds 0 row"):
        it.read_gyro_csv(path, BODY, segments=[(0.0, 0.3), (0.42, 0.48)])
    with pytest.raises(ValueError, match=r"segment 0 \(t from 0.15 to 0.25\) holds 1 row"):
        it.read_gyro_csv(path, BODY, segments=[(0.15, 0.25)])
    with pytest.raises(ValueError, match=r"segments\[0\] must be a window \(t0, t1\) with finite t0 < t1"):
        it.read_gyro_csv(path, BODY, segments=[(0.3, 0.1)])
    with pytest.raises(TypeError, match=r"segments\[0\] must be a time window"):
        it.read_gyro_csv(path, BODY, segments=[0.3])
    with pytest.raises(TypeError, match=r"segments must be a non-empty list"):
        it.read_gyro_csv(path, BODY, segments=[])
    with pytest.raises(ValueError, match=r"segments= .* or events= .*, not both"):
        it.read_gyro_csv(path, BODY, segments=[(0, 1)], events="event")
    with pytest.raises(ValueError, match=r"has no column 'flight' \(events=\)"):
        it.read_gyro_csv(path, BODY, events="flight")
    with pytest.raises(ValueError, match=r"has no column 'q' \(rates=\)"):
        it.read_gyro_csv(path, BODY, rates=("q", "wy (rad/s)", "wz (rad/s)"))
    with pytest.raises(TypeError, match=r"rates must name three columns"):
        it.read_gyro_csv(path, BODY, rates="wx")
    with pytest.raises(ValueError, match=r"units must be one of \['rad/s', 'deg/s'\]; got 'rpm'"):
        it.read_gyro_csv(path, BODY, units="rpm")
    # windows need one clock across the file
    reset = write(tmp_path, HEADER + "0,1,2,3\n0.1,1,2,3\n0,1,2,3\n0.1,1,2,3\n", "reset.csv")
    with pytest.raises(ValueError, match=r"line 4, column 't': time 0.0 is before 0.1"):
        it.read_gyro_csv(reset, BODY, segments=[(0, 1)])


def test_systems_without_angular_velocities_are_refused(tmp_path):
    path = write(tmp_path, EVENTS)
    with pytest.raises(TypeError, match=r"system must be a rotating body"):
        it.read_gyro_csv(path, lp.systems.Kirchhoff())
    with pytest.raises(TypeError, match=r"system must be a Lie-Poisson system"):
        it.read_gyro_csv(path, "RigidBody")


def test_write_refuses_bad_data_and_keeps_an_existing_file(tmp_path):
    path = write(tmp_path, "precious\n")
    with pytest.raises(ValueError, match=r"units must be one of"):
        it.write_gyro_csv(path, observations(), units="rpm")
    with pytest.raises(TypeError, match=r"data must be integrators.BodyObservations"):
        it.write_gyro_csv(path, np.zeros((3, 3)))
    attitudes = it.BodyObservations(BODY, [0.0, 1.0], configurations=[[0, 0, 0, 1.0], [0, 0, 0, 1.0]])
    with pytest.raises(ValueError, match=r"data must hold the angular velocities"):
        it.write_gyro_csv(path, attitudes)
    assert path.read_text() == "precious\n"
    assert os.listdir(tmp_path) == ["gyro.csv"]
