"""The README's Python examples run as written (with a smaller training budget)."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_examples_run(capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.DOTALL)
    assert blocks, "README has no Python example"
    code = "\n".join(blocks)
    code = code.replace("epochs=30_000", "epochs=200").replace("refine_iterations=5_000", "refine_iterations=20")
    code = code.replace(".fit(data)", ".fit(data, max_iter=10, restarts=1, progress=False)")
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    # The first example prints the Casimir change of an exact coadjoint flow: round-off.
    first = capsys.readouterr().out.split("\n")[0]
    assert abs(float(first.strip("[] "))) < 8 * np.finfo(float).eps
    assert namespace["y"].shape == (10_001, 3)
