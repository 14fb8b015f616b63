"""Every module of the project's packages says what it owns in its docstring (issue 35)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("controller", "fmu", "bridge", "scenarios")


def test_every_module_has_a_docstring():
    modules = [p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))]
    assert len(modules) > 150
    missing = [str(p.relative_to(ROOT)) for p in modules
               if not (ast.get_docstring(ast.parse(p.read_text())) or "").strip()]
    assert not missing, f"modules without a docstring saying what they own: {missing}"
