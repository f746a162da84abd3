"""README.md stays true: its Python examples run, and it opens with the two commands."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
TEXT = README.read_text() if README.is_file() else ""
BLOCKS = re.findall(r"```python\n(.*?)```", TEXT, flags=re.S)

pytestmark = pytest.mark.skipif(not TEXT, reason="README.md is not next to the tests (installed elsewhere)")


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_python_block_runs(index, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[index], f"README.md python block {index + 1}", "exec"), {"__name__": "__readme__"})


def test_readme_has_python_examples():
    assert BLOCKS


def test_readme_opens_with_the_two_commands():
    commands = re.findall(r"```bash\n(.*?)\n```", TEXT, flags=re.S)[:2]
    assert commands[0] == 'python3 -m venv .venv && .venv/bin/pip install ".[demo]" && .venv/bin/planner demo'
    assert commands[1] == 'python3 -m venv .venv && .venv/bin/pip install ".[test]" && .venv/bin/pytest'
    assert TEXT.index(commands[1]) < TEXT.index("## ")
