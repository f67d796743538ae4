"""README promises: CI runs its two commands verbatim, and its Python examples run."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")


def code_blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_readme_opens_with_two_commands_that_ci_runs_verbatim():
    first = code_blocks("bash")[0].strip().splitlines()
    assert len(first) == 2, "README must open with exactly two commands: set up + main job, and tests"
    assert README.index("```bash") < README.index("\n## "), "the two commands come before any section"
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    for command in first:
        assert command in ci.splitlines(), f".ci/run does not run README's command verbatim: {command}"
    assert "pytest" in first[1]


PYTHON_EXAMPLES = code_blocks("python")


@pytest.mark.parametrize("index", range(len(PYTHON_EXAMPLES)))
def test_readme_python_example_runs(index, tmp_path):
    code = PYTHON_EXAMPLES[index]
    env = dict(os.environ, MPLBACKEND="Agg", CNCTWIN_OUT=str(tmp_path))
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, f"README example {index} failed:\n{code}\n--- stderr ---\n{result.stderr[-3000:]}"
