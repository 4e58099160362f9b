"""The course: notebooks committed clean and complete, and the course site built with strict checks.

The notebooks themselves are executed by pytest's nbmake plugin (``--nbmake`` in pyproject's
addopts), each as one test item, in CI like every other test.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_there_is_a_lesson_per_topic():
    assert [n.stem[:2] for n in NOTEBOOKS] == [f"{i:02d}" for i in range(len(NOTEBOOKS))] and len(NOTEBOOKS) >= 9


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_a_notebook_is_committed_without_outputs_and_with_goals_and_exercises(notebook):
    cells = json.loads(notebook.read_text())["cells"]
    code = [c for c in cells if c["cell_type"] == "code"]
    assert all(c["outputs"] == [] and c["execution_count"] is None for c in code), "strip the outputs before committing"
    first = "".join(cells[0]["source"])
    assert first.startswith("# ") and "**You will:**" in first
    markdown = "".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    assert "## Exercises" in markdown
    assert any("solution" in c.get("metadata", {}).get("tags", []) for c in code), "exercises need a solution cell"
    # The course uses the public API only: no private names imported.
    assert not any(" import _" in line for c in code for line in "".join(c["source"]).splitlines())


def test_every_lesson_is_on_the_site_and_its_index():
    site, index = (ROOT / "mkdocs.yml").read_text(), (ROOT / "docs" / "index.md").read_text()
    for notebook in NOTEBOOKS:
        assert f"course/{notebook.name}" in site and f"course/{notebook.name}" in index, notebook.name


@pytest.mark.slow
def test_the_course_site_builds_with_strict_checks(tmp_path):
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                            cwd=ROOT, capture_output=True, text=True, timeout=600,
                            env={**os.environ, "NO_MKDOCS_2_WARNING": "1", "COURSE_EXECUTE": "false"})
    assert result.returncode == 0, result.stderr[-3000:]
    assert (tmp_path / "site" / "course" / "00_first_drive" / "index.html").exists()
    assert "Kinematics and odometry" in (tmp_path / "site" / "index.html").read_text()
