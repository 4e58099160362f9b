"""A stage resumed from its checkpoint goes on as that stage: the policies it writes after the
resume carry its own stage index and seed."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from common.curriculum.policy_file import read_manifest
from common.curriculum.runner import Runner
from common.curriculum.schema import CurriculumConfig, curriculum_from_mapping

TINY = Path(__file__).parent / "data" / "tiny_curriculum.yaml"
SEED = 7


class _Interrupted(Exception):
    """Raised where a killed run would have died: after a checkpoint of the second stage."""


def _config() -> CurriculumConfig:
    """The tiny curriculum cut to one evaluation in its first stage and two in its second. Its four
    envs per stage matter: the shadowing bug this guards against left the stage index at the last
    env's index (3), which no two-env curriculum would tell from stage 1."""
    data = yaml.safe_load(TINY.read_text())
    data["seed"] = SEED
    for stage, budget in zip(data["stages"], (512, 1024)):
        assert stage["n_envs"] == 4
        stage.update(budget=budget, max_steps=40, eval={"suite": "open", "episodes": 2, "every": 512})
    return curriculum_from_mapping(data, TINY)


def _killed_at_the_second_stages_checkpoint(out: Path) -> CurriculumConfig:
    """:func:`_config` run into ``out`` until the second stage's first checkpoint, where it dies."""
    config = _config()

    def interrupt(row: dict) -> None:
        if row["stage"] == "sparse":
            raise _Interrupted

    with pytest.raises(_Interrupted):
        Runner(config, out, progress=False, on_evaluation=interrupt).run()
    return config


def _finished_one_stage_run(out: Path) -> CurriculumConfig:
    """The tiny curriculum's first stage alone (one evaluation), run to its end into ``out``."""
    data = yaml.safe_load(TINY.read_text())
    data["stages"] = [{**data["stages"][0], "budget": 512, "max_steps": 40,
                       "eval": {"suite": "open", "episodes": 2, "every": 512}}]
    config = curriculum_from_mapping(data, TINY)
    Runner(config, out, progress=False).run()
    return config


def test_a_resumed_second_stage_writes_its_own_stage_index_and_seed(tmp_path):
    out = tmp_path / "run"
    config = _killed_at_the_second_stages_checkpoint(out)
    stage = out / "stages" / "1-sparse"
    assert read_manifest(stage / "checkpoints" / "last.zip")["timesteps"] == 512
    assert not (stage / "policy.zip").exists()

    Runner(config, out, resume=True, progress=False).run()
    last = read_manifest(stage / "checkpoints" / "last.zip")
    assert last["timesteps"] == 1024  # written after the resume
    assert len(last["env_rng"]) == 4  # the resume restored each env's generator from it
    for name in ("checkpoints/last.zip", "best.zip", "policy.zip"):
        manifest = read_manifest(stage / name)
        assert (manifest["stage"], manifest["stage_index"], manifest["seed"]) == ("sparse", 1, SEED + 1), name


def test_a_resumed_stage_sets_its_optimiser_kernels_after_loading_their_saved_state(tmp_path, monkeypatch):
    # Loading an optimiser's state brings back its saved settings: the stage's own must be set
    # again afterwards (here the saved ones are the stage's already, so only the order shows it).
    from common.curriculum import runner as runner_module

    config, out, calls = _config(), tmp_path / "run", []
    config = config.model_copy(update={"stages": [config.stages[0], config.stages[1].model_copy(
        update={"optimizer_kernels": "fused"})]})
    for name in ("load_weights", "use_optimizer_kernels"):
        original = getattr(runner_module, name)
        monkeypatch.setattr(runner_module, name, lambda *args, _name=name, _original=original, **kwargs: (
            calls.append((_name, *args[1:], *kwargs.values())), _original(*args, **kwargs))[1])

    def interrupt(row: dict) -> None:
        if row["stage"] == "sparse":
            raise _Interrupted

    with pytest.raises(_Interrupted):
        Runner(config, out, progress=False, on_evaluation=interrupt).run()
    calls.clear()
    Runner(config, out, resume=True, progress=False).run()
    assert [call[0] for call in calls] == ["load_weights", "use_optimizer_kernels"]
    assert calls[1][1:] == ("fused",)  # the resumed stage's own setting


def test_a_kill_while_a_checkpoint_is_written_leaves_weights_and_replay_buffer_together(tmp_path, monkeypatch):
    """The replay buffer was written before the weights: a kill between the two left a buffer a
    checkpoint ahead of them, which the resume trained on without a word."""
    import numpy as np

    from common.curriculum import training

    data = yaml.safe_load(TINY.read_text())
    data["stages"] = [{**data["stages"][0], "algorithm": "sac", "normalize": False, "n_envs": 2, "budget": 400,
                       "max_steps": 40, "hyperparams": {"learning_starts": 50, "buffer_size": 1000, "batch_size": 32},
                       "eval": {"suite": "open", "episodes": 2, "every": 200}}]
    config, out = curriculum_from_mapping(data, TINY), tmp_path / "run"
    written = training.policy_writer
    checkpoints = []

    def killed_at_the_second(model, manifest, normalizer=None):
        checkpoints.append(model.num_timesteps)
        write = written(model, manifest, normalizer)
        if len(set(checkpoints)) < 2:  # the first checkpoint writes last.zip and best.zip
            return write

        def dies(tmp):
            write(tmp)
            raise _Interrupted  # the weights' temporary written, the set not yet renamed

        return dies

    monkeypatch.setattr(training, "policy_writer", killed_at_the_second)
    with pytest.raises(_Interrupted):
        Runner(config, out, progress=False).run()
    checkpoint = out / "stages" / "0-open" / "checkpoints"
    steps = read_manifest(checkpoint / "last.zip")["timesteps"]
    with np.load(checkpoint / "last_replay.npz") as replay:
        # The first checkpoint's buffer: 200 steps of two envs, less the step whose transition SB3
        # stores after the callback that saved (the killed set's held 199 rows).
        assert steps == 200 and int(replay["pos"]) == 99
    assert sorted(p.name for p in checkpoint.iterdir()) == ["last.zip", "last_replay.npz"]  # no temporaries
    # A kill -9 leaves its temporaries (as large as the buffer); the resume clears them.
    (checkpoint / ".last_replay.npz.k1ll3d.tmp").write_bytes(b"a killed write")
    (checkpoint.parent / ".best.zip.k1ll3d.tmp").write_bytes(b"a killed write")
    (checkpoint / "notes.txt").write_text("the user's")
    monkeypatch.undo()
    Runner(config, out, resume=True, progress=False).run()
    assert sorted(p.name for p in checkpoint.iterdir()) == ["last.zip", "last_replay.npz", "notes.txt"]
    assert not (checkpoint.parent / ".best.zip.k1ll3d.tmp").exists()


def test_a_kill_while_a_checkpoint_is_written_leaves_best_zip_from_the_training_kept(tmp_path, monkeypatch):
    """best.zip was saved before the checkpoint: a kill between them left a best from the stretch
    of training the resume discards (its row dropped from eval.csv), which became the policy."""
    import dataclasses

    from common.atomic import atomic_write_all
    from common.curriculum import training

    data = yaml.safe_load(TINY.read_text())
    data["stages"] = [{**data["stages"][0], "budget": 1024, "max_steps": 40,
                       "eval": {"suite": "open", "episodes": 2, "every": 512}}]
    config, out = curriculum_from_mapping(data, TINY), tmp_path / "run"
    evaluate, rates = Runner.evaluate_model, iter([0.5, 1.0])

    def improving(self, *args, **kwargs):  # every evaluation a new best
        return dataclasses.replace(evaluate(self, *args, **kwargs), success_rate=next(rates))

    calls = []

    def dies_at_the_second(writes):
        calls.append(writes)
        if len(calls) == 2:
            raise _Interrupted  # killed before the second checkpoint's files are written
        atomic_write_all(writes)

    monkeypatch.setattr(Runner, "evaluate_model", improving)
    monkeypatch.setattr(training, "atomic_write_all", dies_at_the_second)
    with pytest.raises(_Interrupted):
        Runner(config, out, progress=False).run()
    stage = out / "stages" / "0-open"
    assert read_manifest(stage / "checkpoints" / "last.zip")["timesteps"] == 512
    assert read_manifest(stage / "best.zip")["timesteps"] == 512


def test_a_damaged_best_zip_is_refused_before_it_replaces_the_policy(tmp_path):
    """The stage's end copied best.zip over policy.zip unopened: a best.zip damaged while the run
    stood (a disk error, a hand) replaced a good policy with its bytes."""
    import json

    from common.errors import ConfigError

    out = tmp_path / "run"
    config = _finished_one_stage_run(out)
    stage = out / "stages" / "0-open"
    good = (stage / "policy.zip").read_bytes()
    (stage / "best.zip").write_bytes(b"garbage")
    (out / "state.json").write_text(json.dumps({"done": [], "stages": {}}))  # the stage ends again on resume
    with pytest.raises(ConfigError, match="best.zip"):
        Runner(config, out, resume=True, progress=False).run()
    assert (stage / "policy.zip").read_bytes() == good


@pytest.mark.parametrize("damage", [
    lambda text: text.replace(",512,", ",abc,"),  # a row's timesteps
    lambda text: "stage,steps\n" + text.split("\n", 1)[1],  # the header
    lambda text: "\udcff".encode("utf-8", "surrogateescape").decode("latin-1") + text,  # bytes that are no UTF-8
])
def test_resuming_a_finished_run_with_a_damaged_eval_csv_is_refused_in_one_line(tmp_path, damage):
    """With every stage done, only the report read eval.csv, parsing it by hand: a damaged row
    ended the resume in a traceback."""
    from common.errors import ConfigError

    out = tmp_path / "run"
    config = _finished_one_stage_run(out)
    log = out / "eval.csv"
    log.write_bytes(damage(log.read_text()).encode("latin-1"))
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != ".lock"}
    with pytest.raises(ConfigError, match="eval.csv"):
        Runner(config, out, resume=True, progress=False).run()
    assert {p: p.read_bytes() for p in before} == before


def _rewritten_manifest(path: Path, change: dict) -> None:
    """``path``'s zip with its manifest changed by hand, unchecked (as a damaged file would be)."""
    import json
    import zipfile

    with zipfile.ZipFile(path) as source:
        members = {info.filename: source.read(info) for info in source.infolist()}
    manifest = {**json.loads(members["nav_manifest.json"]), **change}
    members["nav_manifest.json"] = json.dumps(manifest).encode()
    with zipfile.ZipFile(path, "w") as target:
        for name, data in members.items():
            target.writestr(name, data)


@pytest.mark.parametrize("damage, message", [
    ({"timesteps": 10**30}, "timesteps"),  # TensorBoard's purge met it with a traceback
    ({"env_rng": ["hello"] * 4}, "env_rng: not the envs' generator states"),
    ({"env_rng": [{"bit_generator": "Evil", "state": "x"}] * 4}, "env_rng"),
])
def test_a_damaged_checkpoint_manifest_is_refused_in_one_line_on_resume(tmp_path, damage, message):
    from common.errors import ConfigError

    out = tmp_path / "run"
    config = _killed_at_the_second_stages_checkpoint(out)
    _rewritten_manifest(out / "stages" / "1-sparse" / "checkpoints" / "last.zip", damage)
    with pytest.raises(ConfigError, match=message):
        Runner(config, out, resume=True, progress=False).run()
