"""The documentation site builds: `mkdocs build --strict` fails on a broken reference, a
docstring mkdocstrings cannot render, or a tutorial block that raises (the tutorials are
executed by markdown-exec during the build). And every public name has an API entry."""

import importlib
import os
import re
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# API page of each public package (docs/api/<page>.md).
API_PAGES = {
    "liepoisson": "liepoisson",
    "liepoisson.systems": "systems",
    "integrators": "integrators",
    "integrators.splitting": "splitting",
    "learn": "learn",
}


@pytest.mark.parametrize("package, page", sorted(API_PAGES.items()))
def test_every_public_name_has_an_api_entry(package, page):
    module = importlib.import_module(package)
    public = {
        name for name, value in vars(module).items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    }
    text = (ROOT / "docs" / "api" / f"{page}.md").read_text()
    documented = set(re.findall(rf"^::: {re.escape(package)}\.(\w+)$", text, re.MULTILINE))
    assert public - documented == set(), f"add to docs/api/{page}.md: {sorted(public - documented)}"
    assert documented - public == set(), f"not exported by {package}: {sorted(documented - public)}"


# Under -m slow: it executes every tutorial (trainings included), 130-200 s of the default run
# on a 2-core machine. `mkdocs build --strict` is the same check by hand.
@pytest.mark.slow
def test_mkdocs_build_strict(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "MPLBACKEND": "Agg"}
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False,
    )
    seconds = time.perf_counter() - start
    tail = "\n".join((done.stdout + done.stderr).splitlines()[-60:])
    assert done.returncode == 0, f"mkdocs build --strict failed (exit {done.returncode}):\n{tail}"
    for page in ("tutorials/own-algebra", "tutorials/learned-vs-classical", "tutorials/reproduce-the-paper",
                 "api/liepoisson"):
        assert (tmp_path / "site" / page / "index.html").exists(), page
    print(f"mkdocs build --strict: {seconds:.0f} s")
