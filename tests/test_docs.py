"""The documentation as a newcomer reads it, checked without building the site: every public
name has an API entry, the shown code defines what it uses, the docs install holds what the
executed pages import, and CI builds the site strictly (`mkdocs build --strict` fails on a broken
reference, a docstring mkdocstrings cannot render, or a tutorial block that raises: the tutorials
are executed by markdown-exec during the build)."""

import importlib
import re
import sys
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


# The strict build itself (`mkdocs build --strict`: broken references, docstrings mkdocstrings
# cannot render, tutorial blocks that raise) is .ci/run's, from the docs install in its own venv
# (test_ci_builds_the_docs_from_the_docs_install_in_its_own_venv below checks that it is there);
# a build here would only repeat it (130-900 s of a worker). By hand: `mkdocs build --strict`.


# -- the docs as a newcomer reads and installs them (cheap: no build) ----------------------------

DOCS = ROOT / "docs"
EXEC_BLOCK = re.compile(r'^```python ([^\n]*exec="on"[^\n]*)\n(.*?)^```', re.MULTILINE | re.DOTALL)


def exec_blocks(page: Path) -> list[tuple[str, str]]:
    """`(options, code)` of every block of `page` that markdown-exec executes, in order."""
    return EXEC_BLOCK.findall(page.read_text())


def shown_code(page: Path) -> dict[str, str]:
    """The code a reader sees on `page` (blocks with `source=`), concatenated per markdown-exec
    session in page order (a block without a session is its own)."""
    sessions: dict[str, str] = {}
    for k, (options, code) in enumerate(exec_blocks(page)):
        if "source=" not in options:
            continue
        session = re.search(r'session="([^"]+)"', options)
        key = session.group(1) if session else f"block {k}"
        sessions[key] = sessions.get(key, "") + code + "\n"
    return sessions


def unbound_names(code: str) -> set[str]:
    """Names `code` reads at module level (directly or from a function, class or comprehension)
    that it never binds (assignment, import, def, class, for, with, except) and that are not
    builtins: what a reader who copies the code would get a NameError on."""
    import builtins
    import symtable

    table = symtable.symtable(code, "<page>", "exec")
    bound = {s.get_name() for s in table.get_symbols() if s.is_assigned() or s.is_imported() or s.is_namespace()}
    read: set[str] = set()

    def walk(t):
        for s in t.get_symbols():
            if s.is_referenced() and (t.get_type() == "module" or s.is_global()):
                read.add(s.get_name())
        for child in t.get_children():
            walk(child)

    walk(table)
    return read - bound - set(dir(builtins))


def test_unbound_names_finds_a_hidden_helper():
    # the check below is only as good as this: a helper defined in a hidden block is caught
    assert unbound_names("import io\nfig = io.StringIO()\nshow(fig)\n") == {"show"}
    assert unbound_names("def f(x):\n    return [g(y) for y in x]\nf([1])\n") == {"g"}
    assert unbound_names("for k in range(3):\n    print(k)\nwith open('x') as f:\n    f.read()\n") == set()


EXECUTED_PAGES = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md") if exec_blocks(p))


@pytest.mark.parametrize("page", EXECUTED_PAGES)
def test_shown_code_runs_when_copied(page):
    """Every name the shown code of a page uses is defined in shown code: no hidden helper (a
    hidden block may print into the page, but defines nothing a reader needs)."""
    for session, code in shown_code(DOCS / page).items():
        missing = unbound_names(code)
        assert not missing, f"docs/{page}, session {session!r}: the shown code uses {sorted(missing)}, defined nowhere shown"


def _requirement_names(requirements: list[str]) -> set[str]:
    return {re.split(r"[\[<>=!~; ]", r, maxsplit=1)[0].lower().replace("_", "-") for r in requirements}


def test_docs_extra_has_what_the_executed_pages_import():
    """`pip install -e ".[docs]"` (the README's docs install) holds every package an executed
    block imports: the core dependencies and the docs extra, with dask[distributed] at the bound
    of the dask extra (the Dask tutorial is executed by the build)."""
    import importlib.metadata

    pyproject = (ROOT / "pyproject.toml").read_text()  # (tomllib is Python 3.11+; we support 3.10)

    def requirements(key):
        found = re.search(rf"^{key} = \[(.*?)\]$", pyproject, re.MULTILINE | re.DOTALL)
        assert found, f"pyproject.toml has no {key} = [...]"
        return re.findall(r'"([^"]+)"', found.group(1))

    docs, dask = requirements("docs"), requirements("dask")
    assert set(dask) <= set(docs), f"the docs extra lacks {set(dask) - set(docs)}"
    installed = _requirement_names(requirements("dependencies") + docs)
    ours = {"liepoisson", "integrators", "learn", "paper", "benchmarks"}
    providers = importlib.metadata.packages_distributions()
    for page in EXECUTED_PAGES:
        for _, code in exec_blocks(DOCS / page):
            for module in re.findall(r"^\s*(?:import|from)\s+(\w+)", code, re.MULTILINE):
                if module in sys.stdlib_module_names or module in ours:
                    continue
                dists = {d.lower().replace("_", "-") for d in providers.get(module, [module])}
                assert dists & installed, f"docs/{page} imports {module} ({sorted(dists)}), not in the docs install"


def test_ci_builds_the_docs_from_the_docs_install_in_its_own_venv():
    """.ci/run: a fresh second venv, exactly `pip install -e ".[docs]"` by its own pip (in the
    background while the tests run, waited for after them), and the strict build run from that
    venv after the tests."""
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]

    def index(pattern):
        found = [k for k, line in enumerate(lines) if re.search(pattern, line)]
        assert found, f".ci/run has no line matching {pattern!r}"
        return found[-1]

    tests = index(r"python -m pytest")
    venv = index(r"-m venv --clear (\S+)")
    docs_venv = re.search(r"-m venv --clear (\S+)", lines[venv]).group(1)
    install = index(rf'^{re.escape(docs_venv)}/bin/pip install -e "\.\[docs\]"$')
    background = index(r"^\) > (\S+) 2>&1 &$")  # the install's subshell, in the background
    pid = index(r"^(\w+)=\$!$")
    name = re.match(r"(\w+)=", lines[pid]).group(1)
    waited = index(rf'^wait "\${name}" \|\| status=\$\?$')  # its exit status kept ...
    failed = index(r'exit "\$status"')  # ... and a failed install fails the script
    activate = index(rf"source {re.escape(docs_venv)}/bin/activate")
    build = index(r"python -m mkdocs build --strict")
    assert venv < install < background < pid < tests < waited <= failed < activate < build, lines
    assert docs_venv != ".ci-venv", "the docs venv must be a second one, not the test venv"
    assert "NO_MKDOCS_2_WARNING=1" in lines[build - 1] + lines[build] and "MPLBACKEND=Agg" in lines[build - 1] + lines[build]


def test_ci_runs_the_default_suite_then_the_slow_one_then_the_docs():
    """.ci/run: the README's test command, then every `@pytest.mark.slow` test (`-m slow`: the
    default run deselects them), both in the test venv, before the docs build."""
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    default = lines.index("python -m pytest")
    slow = next(k for k, line in enumerate(lines) if line.startswith("python -m pytest -m slow"))
    docs = next(k for k, line in enumerate(lines) if "mkdocs build" in line)
    assert default < slow < docs, lines
    assert "deactivate" not in lines[default:slow], "the slow suite runs in the test venv"
    readme = (ROOT / "README.md").read_text()
    assert "`python -m pytest -m slow`" in readme, "the README no longer says how to run the long tests"


def test_home_page_points_to_every_tutorial_the_paper_and_the_experiments():
    import paper._registry

    index = (DOCS / "index.md").read_text()
    start = index.split("## Where to start", 1)[1].split("\n## ", 1)[0]
    tutorials = sorted(p.relative_to(DOCS).as_posix() for p in (DOCS / "tutorials").glob("*.md"))
    for tutorial in tutorials:
        assert f"]({tutorial})" in start, f"'Where to start' on the home page does not link {tutorial}"
        assert f": {tutorial}" in (ROOT / "mkdocs.yml").read_text(), f"{tutorial} is not in mkdocs.yml's nav"
    for text, where in ((index, "docs/index.md"), ((ROOT / "README.md").read_text(), "README.md")):
        assert "(https://arxiv.org/abs/2308.15349)" in text, f"{where} does not link the paper (arXiv:2308.15349)"
    for experiment in paper._registry.PAPER_EXPERIMENTS:
        assert re.search(rf"^\| {experiment} \| .+ \| .+ \|$", index, re.MULTILINE), (
            f"the home page's table of experiments does not say what {experiment} is")


def test_api_signatures_name_no_private_object():
    """With the griffe extensions mkdocs.yml gives mkdocstrings, no signature on the API pages
    shows a private name (learn.fit's TypeVar _Map is shown as its bound)."""
    import griffe
    import yaml

    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    handler = next(p["mkdocstrings"] for p in config["plugins"] if isinstance(p, dict) and "mkdocstrings" in p)
    paths = handler["handlers"]["python"]["options"].get("extensions", [])
    extensions = griffe.load_extensions(*(str(ROOT / p) for p in paths))

    def private(annotation):
        if isinstance(annotation, griffe.ExprName):
            parts = [annotation]
        elif isinstance(annotation, griffe.Expr):
            parts = [x for x in annotation.iterate(flat=True) if isinstance(x, griffe.ExprName)]
        else:
            parts = []
        return {x.name for x in parts if x.name.startswith("_")}

    shown = {}
    for package, page in API_PAGES.items():
        loader = griffe.GriffeLoader(search_paths=[str(ROOT)], extensions=extensions)
        top = loader.load(package.split(".")[0])
        loader.resolve_aliases(implicit=True, external=False)
        module = top if "." not in package else top[package.split(".", 1)[1]]
        text = (DOCS / "api" / f"{page}.md").read_text()
        for name in re.findall(rf"^::: {re.escape(package)}\.(\w+)$", text, re.MULTILINE):
            obj = module[name].final_target if module[name].is_alias else module[name]
            members = [obj] + ([m for k, m in obj.all_members.items() if not k.startswith("_") or k == "__init__"]
                               if obj.is_class else [])
            for member in members:
                member = member.final_target if member.is_alias else member
                if member.is_function:
                    names = set().union(*(private(p.annotation) for p in member.parameters), private(member.returns))
                    if names:
                        shown[f"{package}.{name}: {member.name}"] = names
    assert "learn.fit: fit" not in shown and not shown, f"signatures showing private names: {shown}"


def test_observations_tutorial_fits_a_csv_with_a_guessed_system():
    """The tutorial loads a CSV it wrote (`Observations.load(..., system=...)`) and fits with a
    system other than the one the measurements were made with (the inertia is unknown)."""
    import ast

    code = shown_code(DOCS / "tutorials" / "observations.md")["obs"]
    calls = {}
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            calls.setdefault(node.func.attr, []).append(node)
    assert "savetxt" in calls or ".csv" in code, "the tutorial writes no CSV file"
    load = calls["load"][0]
    assert any(k.arg == "system" for k in load.keywords), "Observations.load(path, system=...) is not shown"
    made_with = ast.unparse(calls["observe"][0].args[0])
    fitted_with = ast.unparse(calls["fit_splitting"][0].args[0])
    assert fitted_with != made_with, f"fit_splitting is given {fitted_with}, the system the data were made with"
    assert {"identifiable", "diagonal_differences"} <= set(calls)


@pytest.mark.parametrize("page", EXECUTED_PAGES)
def test_figures_are_drawn_by_shown_code(page):
    """A figure drawn for a page is drawn by code the reader sees (a hidden block may only embed
    a committed image or a table)."""
    for options, code in exec_blocks(DOCS / page):
        if "source=" not in options:
            drawing = re.search(r"matplotlib|\.subplots\(|\bfigure\(|\.plot\(|savefig", code)
            assert drawing is None, f"docs/{page}: a hidden block draws a figure ({drawing.group(0)!r}):\n{code[:300]}"
