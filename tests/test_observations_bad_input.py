"""Bad input on observations (issue 40): each is refused by the library with an error naming the
argument or the file, what was expected and what was given, or handled correctly."""

import re

import h5py
import numpy as np
import pytest

import integrators as it
import liepoisson as lp

BODY = lp.systems.RigidBody(inertia=(2.0, 1.0, 2 / 3))
T = np.array([0.0, 0.1, 0.25, 0.3])
Y = np.random.default_rng(0).normal(size=(4, 3))


# -- construction ----------------------------------------------------------------------------------
def test_ragged_states_name_the_short_row():
    with pytest.raises(ValueError, match=r"states is ragged: .*\(n_observations, 3\) but states\[1\] has 2 "
                                         r"component\(s\) and states\[0\] 3"):
        it.Observations(BODY, [0, 0.1, 0.2], [[1, 2, 3], [1, 2], [3, 4, 5]])
    # Ragged within one trajectory of a list of trajectories: that trajectory and row are named.
    with pytest.raises(ValueError, match=r"states\[1\] is ragged: states\[1\]\[1\] has shape \(2,\) and "
                                         r"states\[1\]\[0\] shape \(3,\)"):
        it.Observations(BODY, [T[:2], T[:2], T], [Y[:2], [[1, 2, 3], [1, 2]], Y])


def test_times_none_is_required_not_nan():
    with pytest.raises(TypeError, match=r"times is required: a real array or a list of arrays; got None"):
        it.Observations(BODY, None, Y)
    with pytest.raises(TypeError, match=r"times\[1\] is required.*got None"):
        it.Observations(BODY, [T[:3], None], [Y[:3], Y])
    with pytest.raises(TypeError, match=r"states is required.*got None"):
        it.Observations(BODY, T, None)


@pytest.mark.parametrize("states", [Y, np.zeros((1, 0, 3))], ids=["four states", "no state"])
def test_an_empty_trajectory_needs_two_times(states):
    with pytest.raises(ValueError, match=r"(times\[0\] has 0 time\(s\); a trajectory needs at least 2 observation "
                                         r"times.*got 0)|(trajectory 0 has 0 observation\(s\); a trajectory needs "
                                         r"at least two)"):
        it.Observations(BODY, np.zeros(0), states)


def test_an_empty_time_array_is_shared_like_any_1d_one():
    # times=zeros(0) is one (empty) time array shared by the trajectories, not "0 trajectories".
    with pytest.raises(ValueError, match=r"times\[0\] has 0 time\(s\)") as info:
        it.Observations(BODY, np.zeros(0), Y)
    assert "trajectories" not in str(info.value)


@pytest.mark.parametrize(
    ("times", "states", "match"),
    [
        (T, Y + 1e-3j, r"states must be real; got complex values \(states\[0, 0\] = "),
        (T + 0j, Y.astype(complex), r"states must be real"),  # zero imaginary part: still refused
        (T + 1j, Y, r"times must be real; got complex values \(times\[0\] = 1j\)"),
        ([T[:3], T + 1j], [Y[:3], Y], r"times\[1\] must be real"),
    ],
)
def test_complex_values_are_refused_not_truncated(times, states, match):
    with pytest.raises(TypeError, match=match):
        it.Observations(BODY, times, states)


def test_text_times_are_refused():
    with pytest.raises(TypeError, match=r"times must hold real numbers; got text values such as '0'"):
        it.Observations(BODY, ["0", "0.1", "0.25", "0.3"], Y)


# -- observe's noise level -----------------------------------------------------------------------
def test_noise_level_is_a_real_number_not_text_nor_a_bool():
    for noise in ("0.01", True, np.bool_(False), b"0", None, [0.01]):
        with pytest.raises(TypeError, match=r"noise must be a number >= 0 .*got " + re.escape(type(noise).__name__)):
            it.observe(BODY, np.ones(3), T, noise=noise)
    # Numbers of any real type (Python, NumPy scalar, 0-d array) are the same level.
    a = it.observe(BODY, np.ones(3), T, noise=0.01, seed=1)
    for noise in (np.float64(0.01), np.array(0.01)):
        b = it.observe(BODY, np.ones(3), T, noise=noise, seed=1)
        np.testing.assert_array_equal(a.states[0], b.states[0])
    assert it.observe(BODY, np.ones(3), T, noise=0).metadata["noise"] == 0.0


# -- files ---------------------------------------------------------------------------------------
@pytest.fixture
def saved(tmp_path):
    obs = it.Observations(BODY, [T, T[:3]], [Y, Y[:3]], metadata={"run": 1})
    path = tmp_path / "o.h5"
    obs.save(path)
    return obs, path


@pytest.mark.parametrize(
    ("attribute", "value", "match"),
    [
        ("format_version", "one", r"the attribute format_version is 'one'; expected an integer \(1"),
        ("format_version", 1.5, r"the attribute format_version is 1.5; expected an integer"),
        ("metadata", "{run: 1", r"the attribute metadata is not JSON \(.*\); got '\{run: 1'"),
        ("system_params", "inertia=(1, 2, 3)", r"the attribute system_params is not JSON"),
    ],
)
def test_hdf5_attributes_that_are_not_what_they_should_be(saved, attribute, value, match):
    _, path = saved
    with h5py.File(path, "a") as f:
        f.attrs[attribute] = value
    with pytest.raises(ValueError, match=re.escape(repr(str(path))) + ": " + match):
        it.Observations.load(path)


def test_trajectories_file_with_a_text_format_version_names_the_file(tmp_path):
    path = tmp_path / "t.h5"
    it.Trajectories(np.ones((1, 3, 3)), 0.1, BODY).save(path)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = "one"
    with pytest.raises(ValueError, match=re.escape(repr(str(path))) + r": the attribute format_version is 'one'"):
        it.Trajectories.load(path)


@pytest.mark.parametrize(
    ("column", "value", "match"),
    [
        ("trajectory", np.array(["a"] * 7),
         r"the array 'trajectory' must hold trajectory labels \(integers\); got text values such as 'a'"),
        ("t", np.array(["0"] * 7), r"the array 't' must hold real numbers; got text values"),
        ("states", np.ones((7, 3)) * 1j, r"the array 'states' must hold real numbers; got complex values"),
    ],
)
def test_npz_arrays_of_the_wrong_kind_name_the_file_and_array(saved, tmp_path, column, value, match):
    obs, _ = saved
    label, t, y = obs._long()
    arrays = {"trajectory": label, "t": t, "states": y}
    arrays[column] = value
    path = tmp_path / "o.npz"
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match=re.escape(repr(str(path))) + ": " + match):
        it.Observations.load(path, system=BODY)


def test_from_columns_with_text_labels():
    with pytest.raises(TypeError, match=r"the data: trajectory must hold real numbers; got text values"):
        it.Observations.from_columns(BODY, ["a"] * 4, T, Y)


def test_csv_with_a_byte_order_mark_loads_as_without(saved, tmp_path):
    obs, _ = saved
    label, t, y = obs._long()
    text = "trajectory,t,y0,y1,y2\n" + "".join(
        f"{j},{s!r},{a!r},{b!r},{c!r}\n" for j, s, (a, b, c) in zip(label.tolist(), t.tolist(), y.tolist()))
    plain, marked = tmp_path / "plain.csv", tmp_path / "marked.csv"
    plain.write_text(text, encoding="utf-8")
    marked.write_text(text, encoding="utf-8-sig")  # as a spreadsheet writes it
    assert marked.read_bytes().startswith(b"\xef\xbb\xbf")
    a, b = it.Observations.load(plain, system=BODY), it.Observations.load(marked, system=BODY)
    assert len(a) == len(b) == 2
    for u, v in zip(a.times + a.states, b.times + b.states):
        np.testing.assert_array_equal(u, v)


# -- the system a fit is given -------------------------------------------------------------------
def _on_a_leaf(n_trajectories: int, seed: int = 0) -> np.ndarray:
    """States `(n_trajectories, 4, 3)` of norm 1: each trajectory on one Casimir leaf of so(3)."""
    y = np.random.default_rng(seed).normal(size=(n_trajectories, len(T), 3))
    return y / np.linalg.norm(y, axis=-1, keepdims=True)


def test_a_fit_with_another_poisson_structure_is_refused_naming_both():
    import learn

    guess = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
    uv = np.random.default_rng(1).normal(size=(3, 4, 2))
    on_leaves = np.concatenate([uv, 0.5 + np.sum(uv**2, axis=-1, keepdims=True)], axis=-1)  # Casimir r - u^2 - v^2
    pendulum = it.Observations(lp.systems.ExtendedPendulum(), T, on_leaves)
    match = (r"the model's system RigidBody\(inertia=\[1.0, 2.0, 3.0\]\) has another Poisson structure than the "
             r"observations, which are of ExtendedPendulum\(\): their Poisson tensors differ")
    with pytest.raises(ValueError, match=match):
        learn.fit_splitting(guess, pendulum, iterations=1, progress=False)
    with pytest.raises(ValueError, match=match):
        learn.fit(learn.LPNet(guess, hidden=(4,)), pendulum, optimiser=learn.Adam(1), progress=False)
    # Rigid-body data and a guess body of other inertia: the same bracket and Casimir, another
    # Hamiltonian (what fitting learns): accepted, the problem of learn.fit / fit_splitting builds.
    rigid = it.Observations(BODY, T, _on_a_leaf(3))
    problem = learn.TrajectoryLoss().problem(learn.GLPNet(guess, 3), rigid, h=None, validation_fraction=0.0, seed=0,
                                             normalise=False)
    assert problem.description.n_train == rigid.n_observations


@pytest.mark.parametrize(
    "system",
    [
        lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0)),
        lp.systems.DoubleBracket(BODY, 0.1),  # damped: the same bracket and Casimir
        lp.systems.LiePoissonSystem(lp.so3(), lambda m, xp: m[0] ** 2 + m[2], name="so(3) quartic"),
    ],
    ids=["other inertia", "damped", "so(3) of another Hamiltonian"],
)
def test_a_system_of_the_same_structure_is_accepted(system):
    assert it.Observations(BODY, T, _on_a_leaf(2)).check_system(system) is system


def test_systems_of_one_algebra_with_other_hamiltonians_are_the_same_structure():
    top = it.Observations(lp.systems.HeavyTop(), T, np.random.default_rng(2).normal(size=(2, 4, 6)))
    kirchhoff = lp.systems.Kirchhoff()  # se(3) as well
    assert top.check_system(kirchhoff) is kirchhoff


@pytest.mark.parametrize(
    ("algebra", "match"),
    [
        (lp.LieAlgebra(lp.so3().structure_constants, "so3 spatial", sign=+1),
         r"their Poisson tensors differ: at y = \[1.0, 0.0, 0.0\], B\[1, 2\] is -1 for RigidBody.* and 1 for Lie"),
        (lp.LieAlgebra(lp.so3().structure_constants, "so3 bare", casimirs=()),
         r"their brackets agree but RigidBody.* declares 1 Casimir\(s\) and LiePoissonSystem.* 0"),
    ],
    ids=["other sign", "no Casimir"],
)
def test_a_system_of_another_structure_is_refused(algebra, match):
    other = lp.systems.LiePoissonSystem(algebra, lambda m, xp: m[0] ** 2)
    with pytest.raises(ValueError, match=r"system LiePoissonSystem.* has another Poisson structure than the "
                                         r"observations, which are of RigidBody.*: " + match):
        it.Observations(BODY, T, _on_a_leaf(2)).check_system(other)


def test_a_fixed_step_map_is_refused_on_observations_at_uneven_steps():
    # The MLP baseline's step ignores h: trained on intervals of 0.05 and 0.3 alike it would learn
    # neither; learn.fit refuses before any training.
    import learn

    body = lp.systems.RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0))
    uneven = it.Observations(body, [[0.0, 0.05, 0.35, 0.45]], [np.tile([0.3, -0.2, 0.9], (4, 1))])
    with pytest.raises(ValueError, match=r"data has uneven steps, from 0\.05 to 0\.3; MLPBaseline"):
        learn.fit(learn.MLPBaseline(body, hidden=(4,), key=0), uneven, optimiser=learn.Adam(1),
                  loss=learn.TrajectoryLoss(window=1, latent=False), validation_fraction=0.0, progress=False)
