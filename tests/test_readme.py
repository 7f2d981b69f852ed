"""Every Python snippet of the README runs as written (in order, in one namespace, as a
reader pastes them), with its batch sizes shortened for CI."""

import re

import pytest
from conftest import ROOT

SHORT = {r"\b(64|1024)\b": "4", r"\bnthread=2\b": "nthread=1"}
"""Batch sizes of the snippets, shortened (the same calls, fewer environments)."""


def python_blocks() -> list[tuple[int, str]]:
    """(line, code) of every ```python block of the README."""
    text = (ROOT / "README.md").read_text()
    return [
        (text[: m.start()].count("\n") + 1, m.group(1))
        for m in re.finditer(r"^```python\n(.*?)^```", text, flags=re.S | re.M)
    ]


def shortened(code: str) -> str:
    for pattern, replacement in SHORT.items():
        code = re.sub(pattern, replacement, code)
    return code


def test_the_readme_has_python_snippets():
    assert len(python_blocks()) >= 4


@pytest.mark.slow
def test_every_readme_python_snippet_runs():
    namespace: dict = {}
    for line, code in python_blocks():
        if "WarpVecEnv" in code:
            pytest.importorskip("mujoco_warp")
        try:
            exec(compile(shortened(code), f"README.md:{line}", "exec"), namespace)
        except Exception as exc:  # name the snippet, keep the cause
            raise AssertionError(f"the README snippet at line {line} fails: {exc!r}") from exc
