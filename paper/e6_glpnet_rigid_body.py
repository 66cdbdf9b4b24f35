"""E6: G-LPNet for the rigid body over a volume of phase space (paper Sec. 6.2, "Applications to
rigid body dynamics").

Data: 50 initial conditions uniform in [-2, 2]^3 (several Casimir surfaces), 20 pairs each,
h = 0.1, I = diag(1, 2, 3). Model: 6 modules exp(q_s (h/6) M(c_s e_k)) cycling over e1, e2, e3,
q_s = a_s sigmoid(c_s Pi_k) + b_s (18 parameters), trained by BFGS on the state MSE.
Prediction: 10 trajectories of 10,000 steps from initial conditions in |Pi_a| <= 1.25.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import integrators as it
import learn
import liepoisson as lp

from ._evaluate import compare
from ._experiment import AbstractExperiment, PaperValue, Profile, profiles

PROFILES = profiles(
    # "smoke" exercises the whole pipeline in seconds (tests); numbers are meaningless.
    smoke=Profile(max_iter=30, starts=1, baseline_epochs=300, prediction_steps=300),
    quick=Profile(max_iter=3500, starts=2, baseline_epochs=20_000, prediction_steps=10_000),
    full=Profile(max_iter=3500, starts=8, baseline_epochs=100_000, prediction_steps=10_000),
)
DATA_SEED = 6
TEST_SEED = 60


class E6(AbstractExperiment):
    id = "E6"
    title = "rigid body, G-LPNet over [-2, 2]^3"
    paper_values = (
        PaperValue("train_loss", 5e-10, "< 5e-10"),
        PaperValue("energy_rel_err_max", 4e-3, "max 0.4%"),
        PaperValue("energy_rel_err_mean", 1e-3, "~0.1%"),
        PaperValue("casimir_rel_drift_max", 1e-15, "round-off", "roundoff"),
        PaperValue("poisson_defect_max", 1e-15, "0 (exact)", "roundoff"),
    )

    def run(self, profile: str, out_dir: Path, progress: bool):
        P = PROFILES[profile]
        system = lp.systems.RigidBody(inertia=(1.0, 2.0, 3.0))
        h = 0.1
        rng = np.random.default_rng(DATA_SEED)
        y0s = rng.uniform(-2.0, 2.0, size=(50, 3))
        data = it.ground_truth(system, y0s, h=h, n_steps=20, seed=DATA_SEED)
        data.save(out_dir / "data.h5")
        test0 = np.random.default_rng(TEST_SEED).uniform(-1.25, 1.25, size=(10, 3))
        reference = it.ground_truth(system, test0, h=h, n_steps=P.prediction_steps, seed=TEST_SEED)

        gnet, record = learn.fit(
            learn.GLPNet(system, n_modules=6, key=0), data,
            optimiser=learn.KeepIfBetter(learn.Restarts(learn.WarmStart(learn.ScipyBFGS(P.max_iter)), P.starts)),
            validation_fraction=0.0, seed=0, progress=progress,
        )
        gnet.save(out_dir / "glpnet.h5")
        record.save(out_dir / "glpnet-training.h5")
        base = learn.fit(
            learn.MLPBaseline(system, hidden=(16, 16, 16), activation="sigmoid", key=0), data,
            optimiser=learn.Adam(P.baseline_epochs, learning_rate=1e-3, final_learning_rate=1e-5),
            validation_fraction=0.2, seed=0, progress=progress,
        )
        metrics, _ = compare(
            system, (gnet, record), base, reference, out_dir, data_states=data.states, label="G-LPNet"
        )
        metrics["n_parameters"] = gnet.n_parameters
        metrics["test_initial_conditions"] = test0
        metrics["model"] = "G-LPNet, 6 modules"
        metrics["baseline_model"] = "residual MLP 3x16"
        return metrics


EXPERIMENT = E6()
