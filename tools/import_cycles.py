"""Import cycles between the modules of the project's packages (standard library only).

Every `.py` file of the packages is parsed with `ast`; each `import` and `from ... import`
(module level or inside a function, relative ones resolved; not those under
`if TYPE_CHECKING:`, which never run) is an edge to the module it names: `from p import m` is
an edge to the module `p.m` when there is one, else to `p`. A cycle is a strongly connected
component of more than one module, or a module that imports itself. Prints every cycle with
the import lines that close it; exit status 1 if there is one.

With `--private`, also lists the imports of another package's private module (a dotted path
with a component `_name`) in the non-test code, grouped by importing package, private module
and names.

    python tools/import_cycles.py [--root DIR] [--packages liepoisson integrators ...] [--private]
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path
from typing import NamedTuple

PACKAGES = ("liepoisson", "integrators", "learn", "paper")
# Non-test code that may import private modules of the packages (for --private).
OTHER_CODE = ("benchmarks", "tools")


class Import(NamedTuple):
    source: str  # the importing module
    target: str  # the imported module
    names: tuple[str, ...]  # the names taken from it (empty for `import target`)
    file: str
    line: int


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST):
    """The import statements of `tree` that can run (skipping `if TYPE_CHECKING:` bodies)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
            continue
        stack.extend(ast.iter_child_nodes(node))


def imports(root: Path, path: Path, modules: set[str]) -> list[Import]:
    """The imports in the file `path` of modules in `modules` (or of names they define)."""
    source = module_name(root, path)
    package = source if path.name == "__init__.py" else source.rpartition(".")[0]
    found = []
    for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        file, line = str(path.relative_to(root)), node.lineno
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = _known_prefix(alias.name, modules)
                if target:
                    found.append(Import(source, target, (), file, line))
            continue
        if node.level:
            base = package.split(".") if package else []
            base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
            base_name = ".".join(base + ([node.module] if node.module else []))
        else:
            base_name = node.module or ""
        by_target: dict[str, list[str]] = defaultdict(list)
        for alias in node.names:
            sub = f"{base_name}.{alias.name}"
            target = sub if sub in modules else _known_prefix(base_name, modules)
            if target:
                by_target[target].append(alias.name)
        found.extend(Import(source, t, tuple(n), file, line) for t, n in by_target.items())
    return found


def _known_prefix(name: str, modules: set[str]) -> str | None:
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in modules:
            return candidate
    return None


def scan(root: Path, folders: tuple[str, ...], modules: set[str]) -> list[Import]:
    found = []
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            found.extend(imports(root, path, modules))
    return found


def package_modules(root: Path, packages: tuple[str, ...]) -> set[str]:
    return {module_name(root, p) for pkg in packages for p in (root / pkg).rglob("*.py")}


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm (iterative): the strongly connected components of `graph`."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    components = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                components.append(sorted(component))
    return components


def cycles(found: list[Import]) -> list[tuple[list[str], list[Import]]]:
    """Every cycle: its modules and the imports between them."""
    graph: dict[str, set[str]] = defaultdict(set)
    for imp in found:
        graph[imp.source].add(imp.target)
        graph.setdefault(imp.target, set())
    result = []
    for component in strongly_connected(graph):
        members = set(component)
        if len(component) > 1 or component[0] in graph[component[0]]:
            edges = [i for i in found if i.source in members and i.target in members]
            result.append((component, edges))
    return result


def private_imports(found: list[Import]) -> dict[tuple[str, str], dict[str, list[str]]]:
    """`{(importing package, private module): {name: [file:line, ...]}}` for imports of another
    top-level package's private module."""
    grouped: dict[tuple[str, str], dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for imp in found:
        importer, imported = imp.source.split(".")[0], imp.target.split(".")[0]
        private = any(p.startswith("_") and not p.startswith("__") for p in imp.target.split("."))
        if importer != imported and private:
            for name in imp.names or ("(module)",):
                grouped[(importer, imp.target)][name].append(f"{imp.file}:{imp.line}")
    return grouped


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent)
    parser.add_argument("--packages", nargs="+", default=list(PACKAGES))
    parser.add_argument("--private", action="store_true", help="also list imports of another package's private modules")
    args = parser.parse_args(argv)
    root, packages = args.root.resolve(), tuple(args.packages)
    for pkg in packages:
        if not (root / pkg / "__init__.py").is_file():
            parser.error(f"--packages: {pkg!r} is not a package under {root} (no {pkg}/__init__.py)")
    modules = package_modules(root, packages)
    found = scan(root, packages, modules)
    status = 0
    found_cycles = cycles(found)
    for members, edges in found_cycles:
        print(f"import cycle among {len(members)} module(s): {', '.join(members)}")
        for e in edges:
            print(f"  {e.file}:{e.line}: {e.source} -> {e.target}" + (f" ({', '.join(e.names)})" if e.names else ""))
        status = 1
    print(f"{len(found_cycles)} import cycle(s) among {len(modules)} modules of {', '.join(packages)}")
    if args.private:
        others = tuple(d for d in OTHER_CODE if (root / d).is_dir())
        grouped = private_imports(found + scan(root, others, modules))
        count = sum(len({loc for locs in names.values() for loc in locs}) for names in grouped.values())
        print(f"\n{count} import statement(s) of another package's private module (non-test code):")
        for importer in sorted({k[0] for k in grouped}):
            print(f"{importer}:")
            for (imp, target), names in sorted(grouped.items()):
                if imp != importer:
                    continue
                files = sorted({loc for locs in names.values() for loc in locs})
                print(f"  {target}: {', '.join(sorted(names))}")
                print(f"    in {', '.join(files)}")
    return status


if __name__ == "__main__":
    sys.exit(main())
