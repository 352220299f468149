"""The README's Python example between the ``readme-test`` markers runs as written."""
import re
import runpy
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_blocks() -> list[str]:
    """Python code blocks between ``<!-- readme-test: begin -->`` and ``<!-- readme-test: end -->``."""
    text = README.read_text(encoding="utf-8")
    sections = re.findall(r"<!-- readme-test: begin -->(.*?)<!-- readme-test: end -->", text, re.DOTALL)
    return [b for s in sections for b in re.findall(r"```python\n(.*?)```", s, re.DOTALL)]


def test_readme_has_a_tested_example():
    assert readme_blocks(), "no python block between the readme-test markers"


@pytest.mark.slow
def test_readme_example_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)          # the example writes runs/... relative to the working directory
    for i, block in enumerate(readme_blocks()):
        script = tmp_path / f"readme_block_{i}.py"   # a file: tracebacks point at the example's lines
        script.write_text(block, encoding="utf-8")
        runpy.run_path(str(script), run_name="readme")
    out = capsys.readouterr().out
    assert "15 FEA case(s), 72 line profile(s), 7 figure(s)" in out
    assert "25 200/50 FWHM" in out
    assert (tmp_path / "runs" / "alsi40" / "profiles.csv").exists()
