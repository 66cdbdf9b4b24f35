"""What the exploration scripts share: the systems of `benchmarks.any_algebra` by name, the
benchmark's initial conditions and training data, the LPNet variants by composition, options
and output files."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import integrators as it
import learn
from benchmarks import any_algebra
from benchmarks._report import RESULTS
from liepoisson.systems import reversing_symmetries, sign_symmetries

SYSTEMS = {"rigid_body": any_algebra.rigid_body, **any_algebra.SYSTEMS}
H = 0.1
#: Where the exploration scripts write by default.
OUT = RESULTS / "exploration"


def add_system_option(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    parser.add_argument("--system", choices=list(SYSTEMS), default=default, required=default is None,
                        help="a system of benchmarks.any_algebra (rigid_body: the catalogue's so(3) body)")


def add_out_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, help=f"JSON file written (default: a name from the options, under {OUT})")


def out_path(args: argparse.Namespace, name: str) -> Path:
    """`--out`, or `benchmarks/results/exploration/<name>.json`."""
    return args.out if args.out is not None else OUT / f"{name}.json"


def initial_conditions(dim: int, seed: int, extra: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's initial conditions, uniform in [-1, 1]^dim from `numpy.random.default_rng(seed)`:
    40 training ICs, then 10 held-out ICs, then `extra` more training ICs (appended to the 40)."""
    rng = np.random.default_rng(seed)
    y_train = rng.uniform(-1.0, 1.0, size=(40, dim))
    y_test = rng.uniform(-1.0, 1.0, size=(10, dim))
    if extra:
        y_train = np.concatenate([y_train, rng.uniform(-1.0, 1.0, size=(extra, dim))])
    return y_train, y_test


def training_data(system, y_train: np.ndarray, seed: int, n_steps: int = 50) -> it.Trajectories:
    """`n_steps` steps of h = 0.1 from every training IC (heyoka): 40 x 50 pairs by default."""
    return it.ground_truth(system, y_train, h=H, n_steps=n_steps, seed=seed, progress=False)


def lpnet(system, *, width: int = 16, key: int = 0, symmetry=None, equivariant: bool = False,
          network_wrapper=None) -> learn.LPNet | learn.Reversible:
    """An LPNet 3 x `width` built by composition: `network_wrapper(network)` if given (e.g. a
    linear skip); `learn.GroupAveraged` over `sign_symmetries(system)` if `equivariant`;
    `learn.Reversible(..., symmetry)` unless `symmetry` is None (`"auto"`, a sign vector, or an
    index into `reversing_symmetries(system)`)."""
    hidden = (width,) * 3
    if network_wrapper is None and not equivariant:
        net = learn.LPNet(system, hidden=hidden, key=key)
    else:
        n_params = learn.default_parametrisation(system).n_params
        network = learn.AffineMLP(system.dim, n_params, hidden, key=key)
        if network_wrapper is not None:
            network = network_wrapper(network)
        if equivariant:
            network = learn.GroupAveraged(network, sign_symmetries(system))
        net = learn.LPNet(system, network=network)
    if symmetry is None:
        return net
    if isinstance(symmetry, int):
        symmetry = reversing_symmetries(system)[symmetry]
    return learn.Reversible(net, symmetry=symmetry)


def relative_energy_error(system, y: np.ndarray) -> np.ndarray:
    """|H(y_t) - H(y_0)| / |H(y_0)| per trajectory and time, for states `(n_traj, T, dim)`."""
    energy = np.asarray(system.hamiltonian(y))
    return np.abs(energy - energy[:, :1]) / np.abs(energy[:, :1])
