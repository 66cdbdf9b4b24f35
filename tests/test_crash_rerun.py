"""tests/conftest.py's rerun of a test that kills its pytest-xdist worker: once, in a fresh
worker; a second crash fails the run, and a failing assertion is never rerun."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CONFTEST = Path(__file__).with_name("conftest.py")

CRASHES_ONCE = """
import os
from pathlib import Path

def test_crashes_the_first_time():
    marker = Path(__file__).with_name("crashed-once")
    if not marker.exists():
        marker.write_text("")
        os.abort()
"""

CRASHES_ALWAYS = """
import os

def test_crashes_every_time():
    os.abort()
"""

FAILS = """
from pathlib import Path

def test_fails_the_first_time():
    marker = Path(__file__).with_name("failed-once")
    first = not marker.exists()
    marker.write_text("")
    assert not first
"""


def _run(tmp_path: Path, source: str) -> subprocess.CompletedProcess:
    shutil.copy(CONFTEST, tmp_path / "conftest.py")
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "test_it.py").write_text(source)
    # a run of its own, not a worker of this one (its own compilation cache, removed at its end)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTEST_XDIST_WORKER", "LIEPOISSON_TEST_JAX_CACHE")}
    return subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "-p", "no:cacheprovider", "-q", str(tmp_path)],
                          check=False, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.slow  # three pytest runs, each starting two workers that import JAX
def test_a_crashed_test_is_rerun_once_and_a_failed_one_is_not(tmp_path):
    (tmp_path / "once").mkdir()
    once = _run(tmp_path / "once", CRASHES_ONCE)
    assert once.returncode == 0, once.stdout + once.stderr
    assert "1 passed" in once.stdout and "1 rerun" in once.stdout, once.stdout
    assert "rerun after crashing their worker: test_it.py::test_crashes_the_first_time" in once.stdout

    (tmp_path / "always").mkdir()
    always = _run(tmp_path / "always", CRASHES_ALWAYS)
    assert always.returncode == 1, always.stdout + always.stderr
    assert "1 failed" in always.stdout and "crashed while running" in always.stdout, always.stdout

    (tmp_path / "fails").mkdir()
    fails = _run(tmp_path / "fails", FAILS)
    assert fails.returncode == 1 and "1 failed" in fails.stdout and "rerun" not in fails.stdout, fails.stdout
