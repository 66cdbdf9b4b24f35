"""W2's protocols: each true family at its true parameters is the system's Hamiltonian, so the
parametric limit fits the right family; the rotated body is the rigid body in other axes."""

import functools
import unittest.mock

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import in_optimised_process, slow_except
from scipy.spatial.transform import Rotation

import learn
from paper import w2_observations as w2
from paper._systems import ROTATION

EPS = np.finfo(float).eps
PROTOCOLS = w2.protocols()


# the rotated rigid body and the coupled Kirchhoff body with -m slow (the rotated body's axes are
# checked by default below)
@pytest.mark.parametrize("name", slow_except(list(PROTOCOLS), set(PROTOCOLS) - {"rotated rigid body", "coupled Kirchhoff"}))
def test_the_true_family_at_the_true_parameters_is_the_hamiltonian(name):
    protocol = PROTOCOLS[name]
    y = protocol.initial(5, np.random.default_rng(0))
    family = jax.vmap(lambda z: protocol.family(z, jnp.asarray(protocol.true_theta)))(jnp.asarray(y))
    # sums of a few dozen O(1) terms (a log for one body) in another order: a few hundred ulps
    np.testing.assert_allclose(np.asarray(family), np.asarray(protocol.system.hamiltonian(y)), rtol=0, atol=200 * EPS)


def test_the_rotated_body_has_the_principal_axes_it_is_built_with():
    protocol = PROTOCOLS["rotated rigid body"]
    y = protocol.initial(30, np.random.default_rng(1))
    axes = learn.quadratic_part(protocol.system.hamiltonian, protocol.system, y).principal_axes()
    R = Rotation.from_rotvec(ROTATION).as_matrix()  # its columns: the axes of 1/I = 0.5, 1, 1.5
    np.testing.assert_allclose(axes.angles_to(R), 0.0, atol=1e-6)  # arccos near 1: sqrt of ~1e-13
    np.testing.assert_allclose(np.diff(axes.values), [0.5, 0.5], atol=300 * EPS)


def _heavy_top_rows() -> dict:
    # The criterion of issue 41 and of W2's reference table (paper/reference/W2) is BIC; on
    # observed states fit_splitting now defaults to held-out selection, which refits every family
    # on each of 5 folds (>15 min here instead of ~2 min), a criterion tested in
    # test_family_choice.py. The study's models otherwise as W2 builds them.
    with unittest.mock.patch.object(learn, "fit_splitting", functools.partial(learn.fit_splitting, selection="bic")):
        protocol = PROTOCOLS["heavy top"]
        data = w2.observations(protocol, 1e-3, "regular")
        y0, reference = w2.test_set(protocol)
        models = {m.label: m for m in w2.models(protocol, w2.PROFILES["full"]) if m.label in ("G-LPNet", "limit")}
        return {label: w2.evaluate(protocol, model, data, y0, reference, system="heavy top", noise=1e-3,
                                   sampling="regular") for label, model in models.items()}


@pytest.mark.slow  # two W2 fits of a 6-D body, ~2 min with LLVM's optimisations (8 min without)
def test_the_heavy_top_keeps_its_four_terms_and_is_within_its_limit():
    """Issue 41's heavy top (noise 1e-3, regular): the information criterion picks the selected
    quadratic with exactly the top's terms (1/I_k on Pi, gravity on Gamma_3), and the G-LPNet's
    state error at t = 100 is within 1.5x of the parametric limit's (measured 0.37x)."""
    rows = in_optimised_process(_heavy_top_rows)  # its time is in running the fits, not compiling them
    assert rows["G-LPNet"].family == "quadratic, selected"
    assert rows["G-LPNet"].state_error <= 1.5 * rows["limit"].state_error
    assert rows["G-LPNet"].casimir_drift <= 1e-13
