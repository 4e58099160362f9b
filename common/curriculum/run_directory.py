"""A run directory's files: where each stage keeps its checkpoints and policies, and eval.csv.

Run directory::

    OUT/config.yaml          the resolved, validated curriculum
    OUT/run.json             package version, git commit, seeds, devices, start time
    OUT/state.json           curriculum position (which stages are done), rewritten atomically
    OUT/eval.csv             every periodic evaluation of every stage
    OUT/report.md            the final evaluation table per stage, figures, throughput
    OUT/learning_curve.png   success rate and SPL against timesteps
    OUT/stages/I-NAME/       checkpoints/last.zip (+ last_replay.npz), best.zip, policy.zip, tensorboard/
    OUT/.lock                held while a run works in the directory
    OUT/.nav-curriculum-run  the run's mark, written before anything else

Only a directory that holds the mark is this project's: a run may clear what an interrupted run of
its own left behind, and never touches a directory that is not empty and not marked.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

from common.atomic import atomic_write, is_temporary_of
from common.errors import ConfigError
from common.files import read_bytes, read_text

LOCK_NAME = ".lock"
MARKER = ".nav-curriculum-run"
_PREPARED = {"config.yaml", "run.json", "state.json", "eval.csv"}  # what a run writes before training
MAX_EVAL_BYTES = 32 * 1024 * 1024  # eval.csv: about 100 bytes a row
EVAL_FIELDS = ["stage", "timesteps", "wall_time", "success_rate", "collision_rate", "timeout_rate", "stuck_rate",
               "spl", "mean_steps"]


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as JSON, atomically."""
    atomic_write(path, lambda tmp: tmp.write_text(json.dumps(data, indent=2)))


@dataclass
class StagePaths:
    """Where a stage keeps its files."""

    root: Path

    @property
    def last(self) -> Path:
        return self.root / "checkpoints" / "last.zip"

    @property
    def replay(self) -> Path:
        return self.root / "checkpoints" / "last_replay.npz"

    @property
    def best(self) -> Path:
        return self.root / "best.zip"

    @property
    def policy(self) -> Path:
        return self.root / "policy.zip"

    def clear_temporaries(self) -> None:
        """Remove what a killed write of this stage's files left (a replay buffer's is as large as
        the buffer: 109 MB for a SAC stage's), before the stage goes on."""
        files = (self.last, self.replay, self.best, self.policy)
        for folder in {file.parent for file in files if file.parent.is_dir()}:
            for leftover in folder.iterdir():
                if is_temporary_of(leftover.name, [file.name for file in files]):
                    leftover.unlink()

    @property
    def tensorboard(self) -> Path:
        return self.root / "tensorboard"


    @classmethod
    def of(cls, out: Path, index: int, name: str) -> "StagePaths":
        """The files of stage ``index`` (named ``name``) of the run in ``out``."""
        return cls(out / "stages" / f"{index}-{name}")


class EvalLog:
    """``eval.csv``: rows appended and flushed as they come; on resume, rows newer than the
    checkpoint being resumed are dropped (the run will evaluate those timesteps again), and so is
    a last row a kill tore mid-append (it lacks its line end)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        header = (",".join(EVAL_FIELDS) + "\n").encode()
        data = read_bytes(path, MAX_EVAL_BYTES, "this run's eval.csv") if path.exists() else b""
        if not data.endswith(b"\n"):
            whole = data[: data.rfind(b"\n") + 1] or header
            atomic_write(path, lambda tmp: tmp.write_bytes(whole))

    def rows(self) -> list[dict]:
        """The rows, each checked: a stage name, whole timesteps, finite wall time, rates and SPL,
        and mean steps finite or empty (the report draws every column)."""
        text = read_text(self.path, MAX_EVAL_BYTES, "this run's eval.csv")
        reader = csv.DictReader(io.StringIO(text))
        if reader.fieldnames != EVAL_FIELDS:
            raise ConfigError(self.path, "line 1", f"expected the header {','.join(EVAL_FIELDS)}")
        rows = list(reader)
        for line, row in enumerate(rows, start=2):
            try:
                good = bool(row["stage"]) and int(row["timesteps"]) >= 0 and all(
                    math.isfinite(float(row[key])) for key in EVAL_FIELDS[2:-1]) and (
                    row["mean_steps"] == "" or math.isfinite(float(row["mean_steps"])))
            except (TypeError, ValueError):
                good = False
            if not good:
                raise ConfigError(self.path, f"line {line}", "not an evaluation row this project writes; the log is damaged")
        return rows

    def truncate(self, stage: str, timesteps: int) -> None:
        keep = [r for r in self.rows() if r["stage"] != stage or int(r["timesteps"]) <= timesteps]

        def write(tmp: Path) -> None:
            with tmp.open("w", newline="") as handle:
                writer = csv.DictWriter(handle, fieldnames=EVAL_FIELDS, lineterminator="\n")
                writer.writeheader()
                writer.writerows(keep)

        atomic_write(self.path, write)

    def append(self, row: dict) -> None:
        with self.path.open("a", newline="") as handle:
            csv.DictWriter(handle, fieldnames=EVAL_FIELDS, lineterminator="\n").writerow(row)
            handle.flush()


def is_marked(out: Path) -> bool:
    """Whether ``out`` is a run directory of this project (it holds the mark)."""
    return (out / MARKER).is_file()


def mark(out: Path) -> None:
    """Mark ``out`` as a run directory, atomically (a kill leaves it marked or not, never half)."""
    atomic_write(out / MARKER, lambda tmp: tmp.write_text(json.dumps({"format": 1}) + "\n"))


def check_claimable(out: Path) -> None:
    """Refuse, before anything is written, an ``out`` that is not a directory, or one that holds
    files and is not marked (resuming or not: whatever its files are called, they are not a run's)."""
    if out.exists() and not out.is_dir():
        raise ConfigError(out, None, "is not a directory; --out names a run directory")
    if not out.is_dir() or is_marked(out):
        return
    if any(p.name != LOCK_NAME for p in out.iterdir()):
        raise ConfigError(out, None, "is not empty and not a run directory of this project (it has no "
                          f"{MARKER}); choose an empty or a new --out (nothing was changed)")


def unstarted(out: Path) -> bool:
    """Whether the run directory ``out`` (marked: :func:`check_claimable` let nothing else through)
    holds only what a run writes before its first checkpoint (and at least that)."""
    names = {p.name for p in out.iterdir()} - {LOCK_NAME, MARKER}
    if not names or not names - {"stages"} <= _PREPARED or not (out / "state.json").exists():
        return False
    if (out / "eval.csv").exists() and len(read_text(out / "eval.csv", MAX_EVAL_BYTES).splitlines()) > 1:
        return False
    stages = out / "stages"
    # Before its first checkpoint a stage holds at most its TensorBoard log.
    return not stages.exists() or all(stage.is_dir() and all(p.name == "tensorboard" for p in stage.iterdir())
                                      for stage in stages.iterdir())


def clear_unstarted(out: Path) -> None:
    """Remove what an unstarted run wrote: its prepared files and its stages' TensorBoard event
    files, then the directories left empty. A file the run did not write is kept (a user's notes in
    a stage's TensorBoard folder were deleted with the folder)."""
    for name in _PREPARED:
        (out / name).unlink(missing_ok=True)
    stages = out / "stages"
    if not stages.is_dir():
        return
    for event_file in stages.glob("*/tensorboard/**/events.out.tfevents.*"):
        if event_file.is_file():
            event_file.unlink()
    # Deepest first, so a folder emptied above is removed in turn; one holding anything stays.
    for folder in sorted((p for p in stages.rglob("*") if p.is_dir()), key=lambda p: len(p.parts), reverse=True):
        if not any(folder.iterdir()):
            folder.rmdir()
    if not any(stages.iterdir()):
        stages.rmdir()
