"""The Python examples of README.md and docs/python.md run as written.

Each page's ```python blocks run in order in one namespace (a page's later examples use the
names of its earlier ones). The Ray example is left out: it rolls out 1000 seeds on 4 Ray
workers, and test_ray.py runs the same call on a small range.
"""

from __future__ import annotations

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
PAGES = ["README.md", "docs/python.md"]


def python_blocks(page: str) -> list[str]:
    text = (ROOT / page).read_text(encoding="utf-8")
    return re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)


@pytest.mark.parametrize("page", PAGES)
def test_page_examples_run(page):
    blocks = python_blocks(page)
    assert blocks, f"{page} has no ```python examples"
    namespace: dict = {}
    ran = 0
    for i, code in enumerate(blocks):
        if "import mjskill.ray" in code:
            continue
        exec(compile(code, f"{page} (python example {i + 1})", "exec"), namespace)
        ran += 1
    assert ran >= 1
    for value in namespace.values():
        close = getattr(value, "close", None)
        if callable(close) and hasattr(value, "step"):
            close()
