"""learn.fit_splitting refuses what it cannot fit before any fitting work."""

import numpy as np
import pytest

import integrators as it
import learn
from learn._training import _fit_splitting
from liepoisson.systems import RigidBody, damped_rigid_body

BODY = RigidBody(inertia=(2.0, 1.0, 2.0 / 3.0))


@pytest.fixture
def no_fitting(monkeypatch):
    """Any fit started fails the test: the refusal must come first."""

    def fail(*args, **kwargs):
        raise AssertionError("a fit ran before the bad input was refused")

    monkeypatch.setattr(_fit_splitting, "solve", fail)
    monkeypatch.setattr(_fit_splitting, "fit", fail)


def observations(system):
    y0 = np.array([[0.6, 0.0, 0.8], [0.0, 0.8, -0.6]])
    return it.observe(system, y0, it.uneven_times(2, 5, steps=(0.05, 0.3), seed=0), noise=0.0)


def test_a_loss_that_is_not_a_loss_is_refused_before_the_first_family_is_fitted(no_fitting):
    with pytest.raises(TypeError, match="loss"):
        learn.fit_splitting(BODY, observations(BODY), loss=3, progress=False)


def test_a_dissipative_system_is_refused_with_where_to_go(no_fitting):
    damped = damped_rigid_body()
    with pytest.raises(ValueError, match=r"dissipative .* LPNet .*system\.conservative.*Dissipation on the orbit"):
        learn.fit_splitting(damped, observations(damped), progress=False)


def test_observations_of_a_dissipative_system_with_its_conservative_part_are_fitted_with_a_warning(no_fitting):
    damped = damped_rigid_body()
    # the user chose the bracket: the fit goes on (to the stubbed solver), after the warning
    with (pytest.warns(UserWarning, match=r"dissipative .* cannot follow their energy decay; an LPNet can"),
          pytest.raises(AssertionError, match="a fit ran")):
        learn.fit_splitting(damped.conservative, observations(damped), progress=False)
