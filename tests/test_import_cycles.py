"""No import cycle between the modules of liepoisson, integrators, learn and paper
(tools/import_cycles.py), and that script finds the cycles it should."""

import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "tools" / "import_cycles.py"


def _run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, check=False)


def test_the_packages_have_no_import_cycle():
    result = _run()
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 import cycle(s)" in result.stdout


def _write(root, files):
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))


def test_cycles_through_relative_and_local_imports_are_found(tmp_path):
    _write(tmp_path, {
        "pkg/__init__.py": "from ._a import f as f\n",
        "pkg/_a.py": "from ._c import C\nfrom .sub import _e\n\ndef f():\n    pass\n",
        # a function-local import still closes a cycle ...
        "pkg/_b.py": "def g():\n    from . import _a\n",
        "pkg/sub/__init__.py": "",
        "pkg/sub/_e.py": "from .._b import g\nfrom .. import _a\n",
        # ... an import that only type checkers run does not
        "pkg/_c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ._a import f\nclass C: ...\n",
        "pkg/_d.py": "import pkg._d\n",
        "other/__init__.py": "",
        "other/_x.py": "from pkg._b import g\nfrom pkg import _c\nimport pkg\n",
    })
    result = _run("--root", str(tmp_path), "--packages", "pkg", "other", "--private")
    assert result.returncode == 1, result.stdout + result.stderr
    out = result.stdout
    assert "import cycle among 3 module(s): pkg._a, pkg._b, pkg.sub._e" in out
    assert "pkg/_b.py:2: pkg._b -> pkg._a (_a)" in out
    assert "pkg/sub/_e.py:1: pkg.sub._e -> pkg._b (g)" in out
    assert "pkg/sub/_e.py:2: pkg.sub._e -> pkg._a (_a)" in out
    assert "import cycle among 1 module(s): pkg._d" in out
    assert "pkg._c" not in out.split("cycle(s) among")[0]
    assert "2 import cycle(s)" in out
    # another package's private modules, grouped by package, module and names
    assert "other:\n  pkg._b: g\n    in other/_x.py:1\n  pkg._c: _c\n    in other/_x.py:2" in out


def test_no_cycle_exits_zero(tmp_path):
    _write(tmp_path, {"pkg/__init__.py": "from ._a import f as f\n", "pkg/_a.py": "def f():\n    pass\n"})
    result = _run("--root", str(tmp_path), "--packages", "pkg")
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.strip() == "0 import cycle(s) among 2 modules of pkg"


# Each floor imports only the floors below it (data flows one way), and inside `learn` the
# solvers know nothing of learned maps, the maps nothing of training.
LAYERS = ["liepoisson", "integrators", "learn", "paper"]
LEARN_ROOMS = ["_solvers", "_models", "_training"]


def _imports(path: Path, package: str) -> set[str]:
    """Every module an `import`/`from ... import` in `path` names (relative ones resolved
    against `package`, the file's dotted package)."""
    import ast

    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - (node.level - 1)] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            names.add(module)
            names |= {f"{module}.{alias.name}" for alias in node.names}
    return names


def _modules(root: Path, package: str):
    for path in sorted((root / package.replace(".", "/")).rglob("*.py")):
        dotted = ".".join(path.relative_to(root).with_suffix("").parts)
        yield path, dotted if path.name == "__init__.py" else dotted.rsplit(".", 1)[0]


def test_each_layer_imports_only_the_layers_below_it():
    root = SCRIPT.parent.parent
    wrong = []
    for i, layer in enumerate(LAYERS):
        above = LAYERS[i + 1 :]
        for path, package in _modules(root, layer):
            for name in _imports(path, package):
                if name.split(".")[0] in above:
                    wrong.append(f"{path.relative_to(root)} imports {name}")
    assert not wrong, "\n".join(wrong)


def test_learn_solvers_know_no_maps_and_maps_no_training():
    root = SCRIPT.parent.parent
    wrong = []
    for i, room in enumerate(LEARN_ROOMS):
        above = {f"learn.{r}" for r in LEARN_ROOMS[i + 1 :]}
        for path, package in _modules(root, f"learn.{room}"):
            for name in _imports(path, package):
                if any(name == a or name.startswith(a + ".") for a in above):
                    wrong.append(f"{path.relative_to(root)} imports {name}")
    assert not wrong, "\n".join(wrong)


def test_the_layer_check_sees_an_import_running_back_up(tmp_path):
    (tmp_path / "pkg" / "_low").mkdir(parents=True)
    (tmp_path / "pkg" / "_low" / "m.py").write_text("from .._high import x\nimport paper\n")
    names = _imports(tmp_path / "pkg" / "_low" / "m.py", "pkg._low")
    assert {"pkg._high", "pkg._high.x", "paper"} <= names
