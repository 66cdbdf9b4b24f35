"""`python -m paper run ... --out PATH` with a PATH a run cannot write into: one line, exit status 2,
before the scheduler starts or any experiment runs (issue 40). No experiment runs here."""

import os

import pytest

import paper.__main__ as cli
from paper._registry import EXPERIMENTS


@pytest.fixture
def runs(monkeypatch):
    """The experiments the CLI would have run (none may be)."""
    calls = []
    monkeypatch.setattr(cli, "_run", lambda *args: calls.append(args) or 0)
    return calls


def _error_line(capsys):
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


@pytest.mark.parametrize("exp_id", ["W2", "W3"])
def test_out_is_a_file(tmp_path, capsys, runs, exp_id):
    file = tmp_path / "results.txt"
    file.write_text("not a folder")
    assert cli.main(["run", exp_id, "--profile", "smoke", "--out", str(file)]) == 2
    assert _error_line(capsys) == (f"python -m paper: error: --out {str(file)!r} exists and is not a folder; give a "
                                   "folder for the results (python -m paper --out DIR)\n")
    # below a file: the folder cannot be created
    assert cli.main(["run", exp_id, "--profile", "smoke", "--out", str(file / "deeper")]) == 2
    assert f"--out {str(file / 'deeper')!r} cannot be created: {str(file)!r} exists and is not a folder" in (
        _error_line(capsys))
    # an experiment's own folder that is a file
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / exp_id).write_text("")
    assert cli.main(["run", exp_id, "--profile", "smoke", "--out", str(tmp_path / "out")]) == 2
    assert f"--out {str(tmp_path / 'out' / exp_id)!r} exists and is not a folder" in _error_line(capsys)
    assert runs == []
    assert file.read_text() == "not a folder"


def test_out_is_not_writable(tmp_path, capsys, runs, monkeypatch):
    locked = tmp_path.resolve() / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root writes anywhere: say the folder is not writable
            access = os.access
            monkeypatch.setattr(os, "access", lambda p, mode: False if os.fspath(p) == str(locked) else access(p, mode))
        assert cli.main(["run", "W2", "--profile", "smoke", "--out", str(locked / "results")]) == 2
        assert _error_line(capsys) == (
            f"python -m paper: error: --out {str(locked / 'results')!r} cannot be created: {str(locked)!r} is not "
            "writable (permission denied); give a folder you can write to (python -m paper --out DIR)\n")
        assert runs == []
        assert not (locked / "results").exists()
    finally:
        locked.chmod(0o700)
    # A folder that can be created reaches the run; the check itself creates nothing.
    out = tmp_path / "new" / "results"
    assert cli.main(["run", "W3", "--profile", "smoke", "--out", str(out)]) == 0
    assert len(runs) == 1 and runs[0][3] == out
    assert not (tmp_path / "new").exists()


def test_execute_names_out_dir(tmp_path):
    file = tmp_path / "results.txt"
    file.write_text("")
    with pytest.raises(ValueError, match=r"out_dir '.*results\.txt/W2' cannot be created: '.*results\.txt' exists and "
                                         r"is not a folder"):
        EXPERIMENTS["W2"].execute(profile="smoke", progress=False, out_dir=file / "W2")


# -- a folder the check lets through but mkdir cannot create: one line, status 2, for every run --
@pytest.mark.parametrize("exp_id", list(EXPERIMENTS))
def test_out_that_cannot_be_created(tmp_path, capsys, exp_id, monkeypatch):
    # a dangling link: nothing exists at its target, so the check passes; mkdir meets the link
    link = tmp_path / "results"
    link.symlink_to(tmp_path / "missing" / "target")
    assert cli.main(["run", exp_id, "--profile", "smoke", "--out", str(link)]) == 2
    assert _error_line(capsys) == (
        f"python -m paper: error: --out {str(link)!r} cannot be created (it is a link to "
        f"{str(tmp_path / 'missing' / 'target')!r}, which does not exist); give a folder you can write to "
        "(python -m paper --out DIR)\n")
    # a name longer than the file system allows
    long = tmp_path / ("x" * 300)
    assert cli.main(["run", exp_id, "--profile", "smoke", "--out", str(long)]) == 2
    assert _error_line(capsys).startswith(f"python -m paper: error: --out {str(long)!r} cannot be created (")
    # below a regular file that appeared after the check (a race): as if the check had passed
    file = tmp_path / "somefile"
    file.write_text("")
    monkeypatch.setattr(cli, "check_out_dir", lambda *args: None)
    assert cli.main(["run", exp_id, "--profile", "smoke", "--out", str(file / "sub")]) == 2
    assert _error_line(capsys) == (f"python -m paper: error: --out {str(file / 'sub')!r} cannot be created (Not a "
                                   "directory); give a folder you can write to (python -m paper --out DIR)\n")
    assert file.read_text() == ""


def test_out_that_cannot_be_created_from_the_shell(tmp_path):
    import subprocess
    import sys

    link = tmp_path / "results"
    link.symlink_to(tmp_path / "missing")
    done = subprocess.run([sys.executable, "-m", "paper", "run", "W2", "--profile", "smoke", "--out", str(link)], check=False,
                          capture_output=True, text=True, timeout=600, cwd=os.path.dirname(os.path.dirname(__file__)))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert f"--out {str(link)!r} cannot be created" in done.stderr
    assert not (tmp_path / "missing").exists()
