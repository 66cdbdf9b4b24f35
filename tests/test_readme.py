"""The README's Python examples run as written (with a smaller training budget)."""

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"

# The training budgets of the README, cut down for the test run (each must be in the README,
# so that a changed example cannot silently run the full budget).
SMALLER_BUDGETS = {
    "learn.Adam(30_000)": "learn.Adam(200)",
    "learn.KeepIfBetter(learn.ScipyLBFGSB(5_000))": "learn.KeepIfBetter(learn.ScipyLBFGSB(20))",
    "learn.fit_splitting(body, obs, validation_fraction=0.0)": (
        "learn.fit_splitting(body, obs, iterations=10, validation_fraction=0.0, activation='identity', "
        "progress=False)"
    ),
    "optimiser=(learn.Adam(3000), learn.KeepIfBetter(learn.ScipyLBFGSB(1000)))": (
        "optimiser=(learn.Adam(20), learn.KeepIfBetter(learn.ScipyLBFGSB(5))), progress=False"
    ),
    # the timing of each map in the comparison: one short run, not the fastest of five runs of
    # at least 0.05 s (step_timing is tested in test_compare.py)
    "t_final=100.0)": "t_final=100.0, timing_seconds=0.005, timing_repeats=1)",
    # BFGS as the default, without the warm start (a second compilation, ~5 s; the warm start
    # is tested in test_learn_warm_start.py)
    "learn.fit(learn.GLPNet(body, n_modules=6), data)": (
        "learn.fit(learn.GLPNet(body, n_modules=6), data, "
        "optimiser=learn.KeepIfBetter(learn.ScipyBFGS(10)), progress=False)"
    ),
}


def _examples() -> list[str]:
    """The README's Python blocks, with the smaller budgets."""
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)
    assert blocks, "README has no Python example"
    code = "\n".join(blocks)
    for full in SMALLER_BUDGETS:
        assert full in code, f"the README no longer has {full!r}: update SMALLER_BUDGETS"
    for full, small in SMALLER_BUDGETS.items():
        blocks = [block.replace(full, small) for block in blocks]
    return blocks


# The examples in three pieces that the test workers share. Each runs the README's own lines:
# the first block, and for the later ones the opening of the second up to its trajectories
# (`data`), which they read; every block runs in exactly one piece.
_DATA_LINE = "data = it.ground_truth(body, mu, h=0.1, n_steps=999)"
PIECES = {
    "first and training": (0, 1),
    "observations": (0, "data", 2),
    "damped and own system": (0, "data", 3, 4),
}


def _code(piece, blocks):
    parts = []
    for part in PIECES[piece]:
        if part == "data":
            opening, found, _ = blocks[1].partition(_DATA_LINE)
            assert found, (
                f"the README's second block no longer has {_DATA_LINE!r}: update _DATA_LINE"
            )
            parts.append(opening + _DATA_LINE)
        else:
            parts.append(blocks[part])
    return "\n".join(parts)


def test_the_pieces_run_every_block_once():
    blocks = _examples()
    runs = [part for piece in PIECES.values() for part in piece[1:] if part != "data"]
    assert sorted(runs) == list(range(1, len(blocks)))


@pytest.mark.parametrize("piece", PIECES)
def test_readme_examples_run(piece, capsys, tmp_path, monkeypatch):
    code = _code(piece, _examples())
    monkeypatch.chdir(tmp_path)  # the example writes its model files to the working directory
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    # The first example prints the Casimir change of an exact coadjoint flow: round-off.
    first = capsys.readouterr().out.split("\n")[0]
    assert abs(float(first.strip("[] "))) < 8 * np.finfo(float).eps
    if piece == "first and training":
        # 10,000 steps saved every 10th, with the initial state
        assert namespace["y"].shape == (10_000 // 10 + 1, 3)
        assert (tmp_path / "lpnet.h5").exists() and (tmp_path / "lpnet-training.h5").exists()
    if piece == "observations":
        assert namespace["y"].shape == (1001, 3)
    if piece == "damped and own system":
        # the damped body's LPNet keeps |Pi| over the whole relaxation, however little trained
        flip = np.asarray(namespace["flip"])
        assert flip.shape == (1201, 3)
        assert np.ptp(np.sum(flip**2, axis=-1)) < 1e-13
        assert (tmp_path / "oscillator.h5").exists()
