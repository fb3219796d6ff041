"""The documentation: the README's Python examples run as written (in order, one namespace,
on ../shared/data) and say whether they converge; the site builds with warnings as errors.

Blocks fenced ```python are complete examples and run; blocks fenced ```py are fragments
(they name the user's own files and arrays) and are only shown."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import data_path

ROOT = Path(__file__).resolve().parents[1]


def python_blocks(markdown: str) -> list[str]:
    """The ```python fenced blocks of a Markdown text, in order."""
    return re.findall(r"```python\n(.*?)```", markdown, flags=re.S)


def test_readme_and_examples_page_show_the_same_code():
    readme = python_blocks((ROOT / "README.md").read_text())
    page = python_blocks((ROOT / "docs" / "examples.md").read_text())
    assert readme and all(block in readme for block in page), "docs/examples.md drifted from README"


@pytest.mark.slow
@pytest.mark.data
def test_readme_examples_run(tmp_path, monkeypatch):
    data = data_path()
    code = python_blocks((ROOT / "README.md").read_text())
    assert len(code) >= 5
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("JAXPARAM_PROGRESS", "0")
    import matplotlib.pyplot as plt

    ns: dict = {"__name__": "__main__"}
    for i, block in enumerate(code):
        block = block.replace("../shared/data", str(data))
        exec(compile(block, f"README.md[python block {i}]", "exec"), ns)
        if "res" in ns and hasattr(ns["res"], "converged"):
            assert ns["res"].converged, f"README block {i}: a minimization did not converge"
    plt.close("all")
    assert ns["rep"].flips == 0 and (tmp_path / "checker.png").stat().st_size > 10_000


@pytest.mark.slow
def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs", reason="the docs extra is not installed (pip install -e '.[docs]')")
    pytest.importorskip("mkdocstrings", reason="the docs extra is not installed")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                          str(tmp_path / "site")], cwd=ROOT, capture_output=True, text=True,
                         env=env, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    html = (tmp_path / "site" / "api" / "linear" / "index.html").read_text()
    assert 'id="jaxparam.linear.convex_map"' in html          # the API reference is generated
