r"""E4: LPNet for a charged particle in a magnetic field (paper Sec. 5.3, "A particle in a magnetic
field"), a canonical-with-magnetic-term bracket without Casimirs.

System: $y = (p_1, p_2, x_1, x_2)$, $q = m = 1$, $B = r\,e_3$, $\varphi = 1/(100 r)$; second
integral $I = x_1p_2 - x_2p_1 + r^3/3$ (paper Sec. 5.3, eq. (53)).
Data: one heyoka trajectory of 20000 points (19999 pairs, h = 0.1) from $p_0 = (1, 0.5)$,
$x_0 = (0.5, 1)$; 80/20 random split. Its last point (t = 1999.9) is the paper's prediction
start $p \approx (0.119, 1.112)$, $x \approx (-0.627, 0.985)$. Model: MLP 3x32 sigmoid
(4 inputs, 4 outputs: 2404 parameters, as the paper), Adam 1e-3 decaying to 1e-5, loss on the
state. Prediction: 2000 steps from that end point against heyoka.

Training budget. The paper's 2e5 full-batch epochs over 16000 pairs do not fit on 2 cores in a
reasonable time; every profile uses mini-batches of 1000 pairs (15 Adam steps per epoch over the
15,999 training pairs); "full" runs 3000 epochs = 45,000 Adam steps (`metrics["adam_steps"]`).
The LPNet is not exactly Poisson, so its long-time energy drift is not monotone in the training
loss (the seeds x budgets of `python -m paper.e4_sweep`, in `paper/reference/E4/sweep.md`).

Parametrisation. The paper composes $\mathbb T_2\mathbb T_1$ (each for $h/2$: $\mathbb T_1$ the
flow of $\alpha\cdot p$, $\mathbb T_2$ of $\beta\cdot x$, closed-form parameters). We use
`learn.TestFlowParametrisation`: one exact test flow of $H = a\cdot p + \beta\cdot x$ for time
$h$ (`ChargedParticle.test_flow`), parameters found from each pair by Gauss-Newton. Both are
4-parameter families of exact Poisson maps of the same bracket that reach every nearby point
from $y$ (the map from parameters to $y_1$ is a local diffeomorphism near zero: $a$ sets
$x_1 - x_0$, then $\beta$ sets $p_1 - p_0$), so they represent the same step maps near the
identity; only the coordinates of the network's output differ.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import integrators as it
import learn
import liepoisson as lp

from ._evaluate import compare, glpnet_on_same_data, start_training
from ._experiment import GLPNET_ROWS, AbstractExperiment, PaperValue, Profile, profiles

PROFILES = profiles(
    Profile(glpnet_modules=12, glpnet_symmetric=True),
    # "smoke" exercises the whole pipeline in seconds (tests); numbers are meaningless. It skips
    # the G-LPNet (glpnet_iterations=0): compiling its test flows alone takes 5-20 s here.
    smoke=Profile(n_points=2000, epochs=20, batch_size=1000, prediction_steps=300, glpnet_iterations=0, glpnet_starts=1),
    # quick skips the G-LPNet too: its compilation and a few hundred iterations take ~40 s.
    quick=Profile(n_points=20_000, epochs=900, batch_size=1000, prediction_steps=2000, glpnet_iterations=0,
               glpnet_starts=1),
    # full: 3000 epochs (45,000 Adam steps; 6000 until issue 29, which changed no claim: the
    # losses are reached, the energy and integral at neither; the paper's budget: reference/E4/sweep.md);
    # the G-LPNet (no paper claim) 1000 BFGS iterations (2000 until issue 29).
    full=Profile(n_points=20_000, epochs=3000, batch_size=1000, prediction_steps=2000, glpnet_iterations=1000,
              glpnet_starts=1),
)
Y0 = np.array([1.0, 0.5, 0.5, 1.0])  # (p1, p2, x1, x2)
HIDDEN = (32, 32, 32)


class E4(AbstractExperiment):
    id = "E4"
    title = "charged particle in a magnetic field, LPNet from one trajectory"
    paper_values = (
        PaperValue("train_loss", 1e-5, "< 1e-5"),
        PaperValue("val_loss", 1e-5, "< 1e-5"),
        PaperValue("energy_rel_err_max", 2e-2, "1-2%"),
        PaperValue("integral_rel_err_max", 4e-2, "3-4%"),
    )
    table_rows = (
        AbstractExperiment.table_rows[:4]
        + (("integral_rel_err_max", "max |rel. error of the integral I|"),)
        + AbstractExperiment.table_rows[4:]
        + GLPNET_ROWS
        + (("glpnet.integral_rel_err_max", "G-LPNet on the same data: max |rel. error of I|"),)
    )

    def run(self, profile: str, out_dir: Path, progress: bool):
        P = PROFILES[profile]
        system = lp.systems.ChargedParticle()
        h = 0.1
        data = it.ground_truth(system, Y0, h=h, n_steps=P.n_points - 1)
        data.save(out_dir / "data.h5")
        start = data.states[0, -1]
        reference = it.ground_truth(system, start, h=h, n_steps=P.prediction_steps)

        fit = {
            "optimiser": learn.Adam(P.epochs, learning_rate=1e-3, final_learning_rate=1e-5, batch_size=P.batch_size),
            "validation_fraction": 0.2,
            "seed": 0,
            "progress": progress,
        }
        # The second integral I = x1 p2 - x2 p1 + r^3/3, reported like the energy.
        integrals = {"integral": system.angular_integral}
        # The independent trainings start together (in worker processes with --scheduler processes).
        glpnet = (start_training(glpnet_on_same_data, system, data, reference, out_dir, P.glpnet_iterations,
                        P.glpnet_starts, progress=progress, n_modules=P.glpnet_modules, full_vectors=True,
                        integrals=integrals,
                        method=it.splitting.Strang() if P.glpnet_symmetric else it.splitting.LieTrotter())
                  if P.glpnet_iterations else None)
        lpnet = start_training(learn.fit, learn.LPNet(system, hidden=HIDDEN, activation="sigmoid", key=0,
                                             parametrisation=learn.TestFlowParametrisation(system)), data, **fit)
        baseline = start_training(learn.fit, learn.MLPBaseline(system, hidden=HIDDEN, activation="sigmoid", key=0), data,
                         **fit)
        net, record = lpnet.result()
        net.save(out_dir / "lpnet.h5")
        record.save(out_dir / "lpnet-training.h5")
        base = baseline.result()
        metrics, _ = compare(system, (net, record), base, reference, out_dir, data_states=data.states,
                             integrals=integrals)
        if glpnet is not None:
            metrics["glpnet"] = glpnet.result()[1]
        n_train = round(0.8 * (P.n_points - 1))
        metrics["adam_steps"] = P.epochs * (n_train // P.batch_size if P.batch_size else 1)
        metrics["start_point"] = start
        metrics["n_parameters"] = net.n_parameters
        metrics["baseline_n_parameters"] = base[0].n_parameters
        metrics["model"] = "LPNet 3x32"
        metrics["baseline_model"] = "residual MLP 3x32"
        metrics["notes"] = [
            (
                f"Data: one trajectory of {P.n_points} points, 80/20 random split; prediction: "
                f"{P.prediction_steps} steps from its last point (t = {h * (P.n_points - 1):.1f})."
            ),
            (
                f"Budget: {P.epochs} epochs of mini-batches of {P.batch_size} pairs = "
                f"{metrics['adam_steps']} Adam steps (the paper: 2e5 full-batch epochs), "
                "learning rate 1e-3 decaying to 1e-5."
            ),
            (
                "No Casimirs: casimir_rel_drift_max is not applicable; integral_rel_err_max is "
                "max |I(t) - I(0)| / |<I>| of the integral I = x1 p2 - x2 p1 + r^3/3."
            ),
            (
                f"glpnet: a symmetric (palindromic) G-LPNet ({P.glpnet_modules} modules of test "
                "flows with free vectors alpha_s, exactly Poisson) trained on the same pairs and "
                "rolled out from the same point (its energy and integral errors sit at the paper's "
                "figures, on either side of them from run to run: BENCHMARKS.md). Measured: 6 modules along basis vectors reach "
                "MSE 2.1e-5 and a 19% energy error; 12 free non-symmetric ones (2000 BFGS "
                "iterations) 1.9e-6, 2.2% and 13.6% in I."
            ),
        ]
        return metrics


EXPERIMENT = E4()
