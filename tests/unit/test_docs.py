"""Every plain ```python block of README.md and docs/*.md runs as it is (the guide's worked
examples, fenced ```python example:NAME, run in test_guide_examples.py).

Each block runs in a fresh namespace from a temporary working directory, so a block may not rely
on another block or write into the repository. Blocks that are not meant to run are fenced as
``text``, ``toml`` or ``bash`` instead.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)


def python_blocks(path: Path) -> list[str]:
    """The contents of the ```python fenced blocks of a Markdown file, in order."""
    return FENCE.findall(path.read_text(encoding="utf-8"))


BLOCKS = [pytest.param(path, index, code, id=f"{path.relative_to(ROOT)}[{index}]")
          for path in DOCUMENTS for index, code in enumerate(python_blocks(path))]


def test_documents_have_python_blocks():
    assert BLOCKS, "no ```python block found in README.md or docs/*.md"


@pytest.mark.parametrize(("path", "index", "code"), BLOCKS)
def test_block_runs(path, index, code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name = f"{path.relative_to(ROOT)}, python block {index}"
    exec(compile(code, name, "exec"), {"__name__": "__docs__"})  # noqa: S102 - the documented code
