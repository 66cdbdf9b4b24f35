"""Defects found by trying the library as a new user would (issue 27): each error says what is
wrong with the user's input in the user's terms, never a bare `KeyError` or a flat index."""

import h5py
import numpy as np
import pytest

import integrators
import learn
import liepoisson as lp

H = 0.1


@pytest.fixture(scope="module")
def system():
    return lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))


@pytest.fixture(scope="module")
def data(system):
    y0s = np.array([[1.0, 0.2, -0.3], [0.1, 1.0, 0.5], [-0.4, 0.3, 1.0]])
    return integrators.ground_truth(system, y0s, h=H, n_steps=5, progress=False)


def _model(system):
    return learn.LPNet(system, hidden=(4,), key=0)


def _copy(data):
    return integrators.Trajectories(data.states, data.h, data.system)


# -- a saved model given as a checkpoint to resume from -----------------------------------------


def test_saved_model_as_checkpoint_says_how_to_start_from_it(system, data, tmp_path):
    path = tmp_path / "model.h5"
    _model(system).save(path)
    with pytest.raises(ValueError) as err:
        learn.fit(_model(system), data, epochs=2, checkpoint=learn.Checkpoint(path, resume=True))
    message = str(err.value)
    assert str(path) in message
    assert "saved model" in message and "not a training checkpoint" in message
    assert "learn.LPNet.load(" in message and "learn.fit(model" in message


# One code path reads every attribute: two of them in the default run, the rest under -m slow.
@pytest.mark.parametrize("missing", ["fit_settings_json", "epoch", *(
    pytest.param(m, marks=pytest.mark.slow) for m in ("best_loss", "elapsed_s", "hyperparameters_json"))])
def test_checkpoint_missing_attribute_is_named(system, data, tmp_path, missing):
    path = tmp_path / "checkpoint.h5"
    learn.fit(_model(system), data, epochs=2, checkpoint=learn.Checkpoint(path))
    with h5py.File(path, "a") as f:
        del f.attrs[missing]
    with pytest.raises(ValueError) as err:
        learn.fit(_model(system), data, epochs=2, checkpoint=learn.Checkpoint(path, resume=True))
    message = str(err.value)
    assert str(path) in message
    assert missing.removesuffix("_json") in message


@pytest.mark.parametrize("missing", ["optimizer", *(pytest.param(m, marks=pytest.mark.slow) for m in ("best", "history"))])
def test_checkpoint_missing_group_is_named(system, data, tmp_path, missing):
    path = tmp_path / "checkpoint.h5"
    learn.fit(_model(system), data, epochs=2, checkpoint=learn.Checkpoint(path))
    with h5py.File(path, "a") as f:
        del f[missing]
    with pytest.raises(ValueError) as err:
        learn.fit(_model(system), data, epochs=2, checkpoint=learn.Checkpoint(path, resume=True))
    message = str(err.value)
    assert str(path) in message and missing in message


# -- a NaN in the data ---------------------------------------------------------------------------


@pytest.mark.parametrize("validation_fraction", [0.0, 0.2])
@pytest.mark.parametrize(("trajectory", "step"), [(1, 3), (0, 0), (2, 5)])
def test_nan_in_trajectories_names_trajectory_and_step(system, data, trajectory, step, validation_fraction):
    bad = _copy(data)
    bad.states[trajectory, step, 2] = np.nan  # the array is the user's to change after construction
    with pytest.raises(ValueError, match="finite") as err:
        learn.fit(_model(system), bad, epochs=2, validation_fraction=validation_fraction)
    assert f"data trajectory {trajectory}, step {step}" in str(err.value)
    assert "component 2" in str(err.value) and f"at index ({trajectory}, {step}, 2)" in str(err.value)


def test_nan_in_trajectories_is_reported_before_casimir_mismatch(system, data):
    bad = _copy(data)
    bad.states[0, 1] *= 2.0  # an earlier pair no Poisson map connects
    bad.states[2, 4, 0] = np.inf
    with pytest.raises(ValueError, match="finite") as err:
        learn.fit(_model(system), bad, epochs=2)
    assert "data trajectory 2, step 4" in str(err.value)


@pytest.mark.parametrize("which", [0, 1])
def test_nan_in_pairs_names_the_pair(system, data, which):
    y0, y1 = data.pairs()
    pair = (y0, y1)[which]
    pair[7, 1] = np.nan
    y0[2] *= 2.0  # an earlier Casimir mismatch: finiteness is checked first
    with pytest.raises(ValueError, match="finite") as err:
        learn.fit(_model(system), (y0, y1), h=H, epochs=2)
    message = str(err.value)
    assert f"y{which}" in message and "data pair 7" in message and "component 1" in message
