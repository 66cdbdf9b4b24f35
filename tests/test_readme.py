"""The README's Python examples run as written (with a smaller training budget)."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"

# The training budgets of the README, cut down for the test run (each must be in the README,
# so that a changed example cannot silently run the full budget).
SMALLER_BUDGETS = {
    "learn.Adam(30_000)": "learn.Adam(200)",
    "learn.QuasiNewton(5_000)": "learn.QuasiNewton(20)",
    "learn.fit_splitting(body, obs, validation_fraction=0.0)": (
        "learn.fit_splitting(body, obs, iterations=10, validation_fraction=0.0, activation='identity', "
        "progress=False)"
    ),
    "optimiser=(learn.Adam(3000), learn.QuasiNewton(1000))": (
        "optimiser=(learn.Adam(20), learn.QuasiNewton(5)), progress=False"
    ),
    # BFGS as the default, without the warm start (a second compilation, ~5 s; the warm start
    # is tested in test_learn_warm_start.py)
    "learn.fit(learn.GLPNet(body, n_modules=6), data)": (
        "learn.fit(learn.GLPNet(body, n_modules=6), data, "
        "optimiser=learn.QuasiNewton(10, 'bfgs'), progress=False)"
    ),
}


def test_readme_examples_run(capsys, tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)
    assert blocks, "README has no Python example"
    code = "\n".join(blocks)
    for full, small in SMALLER_BUDGETS.items():
        assert full in code, f"the README no longer has {full!r}: update SMALLER_BUDGETS"
        code = code.replace(full, small)
    monkeypatch.chdir(tmp_path)  # the example writes its model files to the working directory
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    # The first example prints the Casimir change of an exact coadjoint flow: round-off.
    first = capsys.readouterr().out.split("\n")[0]
    assert abs(float(first.strip("[] "))) < 8 * np.finfo(float).eps
    # 10,000 steps saved every 10th, with the initial state
    assert namespace["y"].shape == (10_000 // 10 + 1, 3)
    assert (tmp_path / "lpnet.h5").exists() and (tmp_path / "lpnet-training.h5").exists()
    # the damped body's LPNet keeps |Pi| over the whole relaxation, however little trained
    flip = np.asarray(namespace["flip"])
    assert flip.shape == (1201, 3)
    assert np.ptp(np.sum(flip**2, axis=-1)) < 1e-13
