"""Bad input found by a held-out battery, each refused with a message naming the argument:
matrix algebras too large to build, tolerances of the isospectral stage iteration,
quaternions given scalar first, the named nonholonomic systems' arguments."""

import time

import numpy as np
import pytest

import liepoisson as lp
import liepoisson._memory
from liepoisson._matrix_algebra import FAMILIES, SEMIDIRECT, MatrixLieAlgebra

# -- matrix algebras too large for the machine ---------------------------------------------------
_CONSTRUCTORS = {"so": lp.so, "u": lp.u, "su": lp.su, "sp": lp.sp, "gl": lp.gl, "sl": lp.sl, "se": lp.se}


@pytest.mark.parametrize("family", [*_CONSTRUCTORS, "Zeitlin"])
def test_too_large_an_algebra_is_refused_at_once(family):
    build = lp.systems.Zeitlin if family == "Zeitlin" else _CONSTRUCTORS[family]
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"^N: .* at N = 1,000,000 .* would need .* GiB .* available to one "
                                         r"request .*; give N <= [0-9,]+ for"):
        build(10**6)
    assert time.perf_counter() - t0 < 0.5  # the size is checked from a closed form, nothing is built
    with pytest.raises(ValueError, match="^N: "):  # any integer: the check does not overflow
        build(10**400)


@pytest.mark.parametrize("family", sorted(SEMIDIRECT.values()))
def test_too_large_a_semidirect_product_is_refused(family, monkeypatch):
    small = MatrixLieAlgebra(family, 3)
    monkeypatch.setattr(liepoisson._memory, "physical_memory", lambda: (1000, True))  # after small is built
    with pytest.raises(ValueError, match=r"^algebra: .* at N = 3 .* would need"):
        lp.semidirect(small)


@pytest.mark.parametrize("family", FAMILIES)
def test_the_largest_size_said_to_fit_is_built(family, monkeypatch):
    # 4 MiB of "physical memory": the N the message offers is built, one more is refused
    monkeypatch.setattr(liepoisson._memory, "physical_memory", lambda: (2**22, True))
    with pytest.raises(ValueError, match="give N <= ") as info:
        MatrixLieAlgebra(family, 10**4)
    largest = int(str(info.value).rsplit("give N <= ", 1)[1].split()[0].replace(",", ""))
    g = MatrixLieAlgebra(family, largest)
    assert g.N == largest
    with pytest.raises(ValueError, match=f"^N: {family}\\(N\\) at N = {largest + 1:,} "):
        MatrixLieAlgebra(family, largest + 1)


# -- the isospectral stage iteration's relative tolerance -----------------------------------------
@pytest.mark.parametrize("tol", [1.0, 10, 1e300])
def test_stage_tolerance_must_be_below_one(tol):
    import integrators as it
    import learn

    body = lp.systems.GeneralizedRigidBody((1.0, 1.3, 1.9, 2.6))
    for build in (lambda: it.IsospectralMidpoint(body, 0.1, tol=tol), lambda: it.IsospectralTripleJump(body, 0.1, tol=tol),
                  lambda: learn.IsospectralPolynomial(body, h=0.1, tol=tol)):
        with pytest.raises(ValueError, match=r"^tol must be in \(0, 1\): .* got "):
            build()
    # a small tolerance is taken as it is
    assert it.IsospectralMidpoint(body, 0.1, tol=0.5).tol == 0.5
    assert learn.IsospectralPolynomial(body, h=0.1, tol=1e-14).tol == 1e-14
