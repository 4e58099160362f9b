"""The curriculum CLI: validate's one-line errors (exit code 2, no traceback) and bench's JSON."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from common.cli import main
from common.scenario import Scenario

GOOD = Scenario(name="good").to_yaml()

BAD_FILES = {
    "unknown key": ("name: x\nwheels: 3\n", "wheels: unknown key"),
    "wrong type": ("world:\n  width: wide\n", "world.width: Input should be a valid number"),
    "negative radius": ("obstacles:\n  - {type: circle, x: 5, y: 5, radius: -1}\n", "obstacles.0.circle.radius: Input should be greater than 0"),
    "unknown obstacle type": ("obstacles:\n  - {type: blob, x: 5, y: 5}\n", "obstacles.0"),
    "empty file": ("", "the file is empty"),
    "not YAML": ("name: [unclosed\n  - {\n", "not valid YAML"),
    "not a mapping": ("- 1\n- 2\n", "expected a YAML mapping"),
    "goal inside obstacle": ("goal: [5, 5]\nobstacles:\n  - {type: circle, x: 5, y: 5, radius: 1}\n", "goal: (5, 5) is inside an obstacle"),
    "start outside world": ("start: [-3, 1, 0]\n", "start: (-3, 1) lies outside the world"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_validate_reports_one_line_naming_file_and_field(case, tmp_path, capsys):
    text, expected = BAD_FILES[case]
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert str(path) in err and expected in err, err


def test_validate_accepts_a_good_file_and_missing_files_fail(tmp_path, capsys):
    good = tmp_path / "good.yaml"
    good.write_text(GOOD)
    assert main(["validate", str(good)]) == 0
    assert "ok:" in capsys.readouterr().out
    assert main(["validate", str(tmp_path / "missing.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_cli_process_exits_2_without_traceback(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("obstacles:\n  - {type: circle, x: 5, y: 5, radius: -1}\n")
    result = subprocess.run([sys.executable, "-m", "common.cli", "validate", str(path)], capture_output=True, text=True)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_bench_json_has_the_agreed_keys(capsys):
    assert main(["bench", "--json", "--steps", "2000"]) == 0
    results = json.loads(capsys.readouterr().out)
    assert results["obstacles"] == 31 and results["lidar_beams"] == 36
    assert results["flatland_steps_per_s"] > 0
    assert "irsim_steps_per_s" in results
