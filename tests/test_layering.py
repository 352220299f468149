"""The packages are layered optics <- fea <- pipeline: no import runs back up
(docs/architecture.md), so the FEA layer's caches can share the keyed store only because
it lives in fea/."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _imported(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


@pytest.mark.parametrize("package, above", [("optics", ("fea", "pipeline")), ("fea", ("pipeline",))])
def test_no_module_imports_a_layer_above_its_own(package, above):
    offenders = sorted(f"{path.relative_to(ROOT)}: {name}"
                       for path in (ROOT / package).rglob("*.py") for name in _imported(path)
                       if name.split(".")[0] in above)
    assert offenders == []


@pytest.mark.parametrize("module", ["fea.store", "fea.mesh_cache", "fea.operator_cache",
                                    "pipeline.io.common"])
def test_each_cache_module_imports_first_in_a_fresh_interpreter(module):
    """An import circle shows only when its module is the first one imported."""
    run = subprocess.run([sys.executable, "-c", f"import {module}"], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
