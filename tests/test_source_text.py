"""The library's source text: no string (a docstring above all) holds a control character.
`"$\\alpha$"` in a non-raw docstring is the BEL character followed by "lpha", which Python
accepts without a warning and the API pages print as garbage."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
FILES = sorted(p for package in ("liepoisson", "integrators", "learn", "paper", "benchmarks", "tools")
               for p in (ROOT / package).rglob("*.py"))
CONTROL = {"\a", "\b", "\v", "\f"}


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_control_character_in_strings(path):
    bad = [node.lineno for node in ast.walk(ast.parse(path.read_text()))
           if isinstance(node, ast.Constant) and isinstance(node.value, str) and CONTROL & set(node.value)]
    assert not bad, f"{path.relative_to(ROOT)}: control character in strings at lines {bad} (use r\"\"\"...\"\"\")"
