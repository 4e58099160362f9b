"""A run directory is the project's only when it carries the run's mark: nothing of a user's is
ever cleared or overwritten, and a bad --out is one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.curriculum.cli import main
from common.curriculum.run_directory import MARKER
from common.curriculum.runner import Runner
from common.curriculum.schema import load_curriculum
from common.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests/data/tiny_curriculum.yaml"


def _tree(directory: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(directory)): p.read_bytes() if p.is_file() else None for p in directory.rglob("*")}


def test_a_users_files_named_as_a_runs_are_left_alone(tmp_path, capsys):
    # The names an unstarted run leaves, written by a user: they are not a run's.
    out = tmp_path / "d"
    (out / "stages" / "x" / "tensorboard").mkdir(parents=True)
    (out / "config.yaml").write_text("my\n")
    (out / "state.json").write_text("{}\n")
    (out / "stages" / "x" / "tensorboard" / "ev").write_text("log\n")
    before = _tree(out)
    for resume in ([], ["--resume"]):
        assert main(["run", str(TINY), "--out", str(out), "--no-progress", *resume]) == 2
        error = capsys.readouterr().err
        assert error.count("\n") == 1 and "not a run directory of this project" in error
        assert _tree(out) == before  # not a file deleted, changed or added (not even the lock)


def test_a_run_marks_its_directory_before_anything_else_and_restarts_only_its_own(tmp_path):
    config, out = load_curriculum(TINY), tmp_path / "run"
    first = Runner(config, out)
    first.prepare()
    assert (out / MARKER).is_file()
    first.release()  # it died before its first checkpoint: its own leftovers may be cleared
    # What it wrote in a stage's TensorBoard folder goes; a note a user put beside it stays.
    board = out / "stages" / "0-sparse" / "tensorboard" / "PPO_1"
    board.mkdir(parents=True)
    (board / "events.out.tfevents.1.host").write_bytes(b"event")
    (board.parent / "my_notes.txt").write_text("mine\n")
    again = Runner(config, out)
    assert again.prepare() == {"done": [], "stages": {}}
    again.release()
    assert not board.exists() and (board.parent / "my_notes.txt").read_text() == "mine\n"
    (out / "stages" / "notes.txt").write_text("mine too\n")  # a file, not a stage: the run is not provably unstarted
    with pytest.raises(ConfigError, match="the run directory is not empty; pass --resume"):
        Runner(config, out).prepare()
    (out / MARKER).unlink()  # the same files, unmarked: no longer provably the run's
    with pytest.raises(Exception, match="not a run directory of this project"):
        Runner(config, out).prepare()


@pytest.mark.parametrize("make_out, expected", [
    (lambda tmp: tmp / "a-file", "is not a directory"),
    (lambda tmp: tmp / "a-file" / "run", "cannot write here"),
])
def test_an_out_that_cannot_be_a_run_directory_is_one_line(tmp_path, capsys, make_out, expected):
    (tmp_path / "a-file").write_text("mine\n")
    assert main(["run", str(TINY), "--out", str(make_out(tmp_path)), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and expected in error and "Traceback" not in error
    assert (tmp_path / "a-file").read_text() == "mine\n"


def _row(stage: str, timesteps: int, wall_time: float, success_rate: float) -> dict:
    """An evaluation row as a run writes it (every column)."""
    return {"stage": stage, "timesteps": timesteps, "wall_time": wall_time, "success_rate": success_rate,
            "collision_rate": 1.0 - success_rate, "timeout_rate": 0.0, "stuck_rate": 0.0, "spl": 0.4, "mean_steps": ""}


def test_the_csv_files_end_every_line_alike(tmp_path):
    from common.curriculum.comparison import write_csv
    from common.curriculum.run_directory import EvalLog
    from common.evaluation import Episode, summarise

    log = EvalLog(tmp_path / "eval.csv")
    log.append(_row("open", 1024, 1.0, 0.5))
    log.truncate("open", 2048)
    log.append(_row("open", 2048, 2.0, 0.75))
    episode = Episode("a", "s", 0, "success", 10, 1.0, 1.0, 1.0, 0.1)
    written = write_csv([summarise("a", [episode, episode])], tmp_path / "episodes.csv")
    for path in (tmp_path / "eval.csv", written):
        data = path.read_bytes()
        assert b"\r" not in data and data.count(b"\n") == 3, path.name


def test_a_row_torn_by_a_kill_is_dropped_when_the_log_is_reopened(tmp_path):
    from common.curriculum.run_directory import EvalLog

    log = EvalLog(tmp_path / "eval.csv")
    log.append(_row("sparse", 1024, 1.0, 0.5))
    with (tmp_path / "eval.csv").open("a") as handle:
        handle.write("spars")  # killed mid-append
    reopened = EvalLog(tmp_path / "eval.csv")
    assert [r["timesteps"] for r in reopened.rows()] == ["1024"]
    reopened.truncate("sparse", 4096)
    assert "spars," not in (tmp_path / "eval.csv").read_text()


@pytest.mark.slow
def test_a_full_disk_stops_a_run_in_one_line_and_it_resumes(tmp_path, capsys, monkeypatch):
    import errno

    from common.curriculum import training

    out, saved = tmp_path / "run", training.policy_writer
    calls = []

    def fills_the_disk(*args, **kwargs):
        calls.append(args)
        write = saved(*args, **kwargs)
        if len(calls) != 2:
            return write

        def full(tmp):  # the second evaluation's checkpoint
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp))

        return full

    monkeypatch.setattr(training, "policy_writer", fills_the_disk)
    assert main(["run", str(TINY), "--out", str(out), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "No space left on device" in error and "--resume" in error
    monkeypatch.setattr(training, "policy_writer", saved)
    assert main(["run", str(TINY), "--out", str(out), "--no-progress", "--resume"]) == 0
    assert (out / "report.md").exists()


def test_compare_writes_only_into_a_directory_of_its_own(tmp_path, capsys):
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine\n")
    argv = ["compare", "--controllers", "go_to_goal", "--episodes", "1", "--max-steps", "5"]
    assert main([*argv, "--out", str(theirs)]) == 2
    assert "holds files other than a comparison's" in capsys.readouterr().err
    assert [p.name for p in theirs.iterdir()] == ["notes.txt"]
    assert main([*argv, "--out", str(theirs / "notes.txt")]) == 2
    assert "is not a directory" in capsys.readouterr().err
    assert main([*argv, "--out", str(tmp_path / "mine")]) == 0
    assert main([*argv, "--out", str(tmp_path / "mine")]) == 0  # an earlier comparison is replaced
    # Its GIFs beside it (--gif naming the same directory) are the comparison's, not the user's.
    assert main([*argv, "--out", str(tmp_path / "mine"), "--gif", str(tmp_path / "mine")]) == 0
    assert (tmp_path / "mine" / "go_to_goal.gif").is_file()
    assert main([*argv, "--out", str(tmp_path / "mine")]) == 0


def test_a_comparison_killed_while_writing_leaves_the_earlier_one_whole(tmp_path, capsys, monkeypatch):
    from common.curriculum import comparison

    out = tmp_path / "mine"
    argv = ["compare", "--episodes", "1", "--max-steps", "5", "--out", str(out)]
    assert main([*argv, "--controllers", "go_to_goal"]) == 0
    earlier = {p.name: p.read_bytes() for p in out.iterdir()}

    def killed(*args, **kwargs):
        raise KeyboardInterrupt  # the chart is written last: the table and episodes are new by then

    monkeypatch.setattr(comparison, "bar_chart", killed)
    assert main([*argv, "--controllers", "reactive"]) == 130  # Ctrl-C, said in one line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == earlier
    (out / ".comparison.md.x1y2.tmp").write_text("a kill -9 left this")  # not a reason to refuse the next one
    monkeypatch.undo()
    assert main([*argv, "--controllers", "reactive"]) == 0
    assert "reactive" in (out / "comparison.md").read_text() and "reactive" in (out / "episodes.csv").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["comparison.md", "comparison.png", "episodes.csv"]  # cleared
    (out / "episodes.csv").unlink()
    (out / "episodes.csv").mkdir()  # a folder under a comparison's name: the user's, and the set's renames would stop
    assert main([*argv, "--controllers", "reactive"]) == 2
    assert "holds files other than a comparison's" in capsys.readouterr().err


def test_render_to_a_directory_is_one_line(tmp_path, capsys):
    assert main(["render", "--agent", "go_to_goal", "--max-steps", "5", "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and str(tmp_path) in error


@pytest.mark.parametrize("name, content, expected", [
    ("state.json", "{}\n", "not the state this project writes"),
    ("state.json", '{"done": ["sparse"], "stages": {}}\n', "not the state this project writes"),
    ("run.json", '{"seed": 0}\n', "run.json: git_commit: missing"),
    ("eval.csv", "stage,timesteps\nopen,1024\n", "eval.csv: line 1: expected the header"),
    ("eval.csv", None, "eval.csv: line 3: not an evaluation row"),
    # Read by the report only, they gave tracebacks.
    ("eval.csv", "spl", "eval.csv: line 3: not an evaluation row"),
    ("state.json", '{"done": ["open"], "stages": {"open": {}}}\n', "not the state this project writes"),
    ("run.json", '{"git_commit": null, "package_version": "0.1.0"}\n', "run.json: device: missing"),
])
def test_a_damaged_run_state_is_refused_in_one_line_on_resume(tmp_path, capsys, name, content, expected):
    out = tmp_path / "run"
    runner = Runner(load_curriculum(TINY), out)
    runner.prepare()
    runner.eval_log.append(_row("open", 1024, 1.0, 0.5))
    runner.release()
    if content is None:
        content = (out / name).read_text() + "open,2048,nan,0.5,0,0,0,0,\n"
    elif content == "spl":
        content = (out / name).read_text() + "open,2048,2.0,0.5,0,0,0,abc,\n"
    (out / name).write_text(content)
    assert main(["run", str(TINY), "--out", str(out), "--resume", "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and expected in error


@pytest.mark.parametrize("device, flag", [("cuda", False), ("mps", True)])
def test_a_device_this_machine_lacks_is_refused_before_training(tmp_path, capsys, monkeypatch, device, flag):
    """stable-baselines3 trained the stage on the CPU, then its policy failed to load onto CUDA,
    reported as a damaged policy file."""
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.backends.mps, "is_available", lambda: False)
    curriculum, out = tmp_path / "c.yaml", tmp_path / "run"
    curriculum.write_text(TINY.read_text().replace("device: cpu", "device: cpu" if flag else f"device: {device}"))
    assert main(["run", str(curriculum), "--out", str(out), "--no-progress", *(["--device", device] if flag else [])]) == 2
    where = f"--device: '{device}'" if flag else f"c.yaml: device: '{device}'"
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and where in error and "allowed here: auto, cpu" in error, error
    assert not out.exists()
    with pytest.raises(ConfigError, match=f"device: '{device}', but torch finds no"):
        Runner(load_curriculum(curriculum), out, device=device)


def test_ctrl_c_is_one_line_that_says_how_to_go_on(tmp_path, capsys, monkeypatch):
    """It printed some fifty lines of KeyboardInterrupt traceback; --resume then worked."""
    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(Runner, "run", interrupted)
    assert main(["run", str(TINY), "--out", str(tmp_path / "run"), "--no-progress"]) == 130
    assert capsys.readouterr().err == "interrupted\n"  # before the run directory held a state to resume

    def interrupted_once_prepared(self):
        self.prepare()
        self.release()
        raise KeyboardInterrupt

    monkeypatch.setattr(Runner, "run", interrupted_once_prepared)
    assert main(["run", str(TINY), "--out", str(tmp_path / "run"), "--no-progress"]) == 130
    assert capsys.readouterr().err == "interrupted; every checkpoint written so far is whole: continue with --resume\n"


def test_a_finished_stage_s_result_is_checked_field_by_field():
    """A state.json stage result as a run writes it passes; true where a count belongs, a number
    as text, NaN, or an interval of one end is refused (the report would misread it)."""
    from common.curriculum.runner import _is_result

    result = {"timesteps": 1024, "wall_seconds": 1.5, "steps_per_second": 680.0, "promoted": False,
              "policy": "stages/0-open/policy.zip",
              "final": {"success_rate": 0.5, "collision_rate": 0.5, "timeout_rate": 0, "stuck_rate": 0.0, "spl": 0.4,
                        "episodes": 4, "success_ci95": [0.15, 0.85], "mean_steps": None, "draw": "test"}}
    assert _is_result(result)
    for damaged in ({**result, "timesteps": True}, {**result, "wall_seconds": "1.5"},
                    {**result, "final": {**result["final"], "spl": float("nan")}},
                    {**result, "final": {**result["final"], "success_ci95": [0.15]}},
                    {key: value for key, value in result.items() if key != "policy"}):
        assert not _is_result(damaged), damaged
