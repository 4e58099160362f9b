"""``curriculum sweep`` on Ray Tune: aggregates, a local sweep, two nodes, a retried trial, a resumed sweep."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from common.curriculum.cli import main
from common.curriculum.machine import describe, machine
from common.errors import ConfigError
from common.statistics import aggregate

pytest.importorskip("ray")
ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests" / "data" / "tiny_sweep.yaml"


def test_the_aggregate_is_the_interquartile_mean_with_a_bootstrap_interval():
    values = [0.2, 0.9, 0.95, 1.0, 0.5, 0.85, 0.9, 0.7]
    result = aggregate(values)
    middle = sorted(values)[2:6]  # 8 values: the middle half is the 3rd to the 6th
    assert result["iqm"] == pytest.approx(sum(middle) / 4) and result["mean"] == pytest.approx(np.mean(values))
    low, high = result["ci95"]
    assert low < result["iqm"] < high and 0.2 <= low and high <= 1.0
    # The same interval by hand: resample, take each resample's IQM, read the 2.5 and 97.5 percentiles.
    rng = np.random.default_rng(1)
    boot = [stats.trim_mean(rng.choice(values, len(values)), 0.25) for _ in range(4000)]
    assert abs(low - np.percentile(boot, 2.5)) < 0.03 and abs(high - np.percentile(boot, 97.5)) < 0.03
    assert aggregate([])["iqm"] is None
    # One seed says nothing of the spread: no interval (a zero-width one read as certainty).
    assert aggregate([0.9])["ci95"] is None and aggregate([0.9, 0.9])["ci95"] == [0.9, 0.9]
    # A NaN made every figure NaN (and sweep.json no JSON): left out and counted.
    assert aggregate([0.9, float("nan"), 0.95]) == {**aggregate([0.9, 0.95]), "non_finite": 1}


@pytest.mark.slow
def test_an_unreachable_cluster_is_a_one_line_error_within_seconds(tmp_path):
    began = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "common.curriculum.cli", "sweep", str(TINY), "--address", "127.0.0.1:9",
                             "--out", str(tmp_path / "s")], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "--address: no Ray cluster answers at 127.0.0.1:9" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and time.perf_counter() - began < 30


def test_a_sweep_over_machines_says_which_seeds_ran_where(tmp_path):
    """A cluster's nodes may differ, and a seed trains other weights on another CPU."""
    from types import SimpleNamespace

    from common.curriculum.sweep_report import write_results

    final = {"success_rate": 0.9, "spl": 0.8}
    grid = [SimpleNamespace(config={"seed": seed}, error=None,
                            metrics={"done": True, "final": final, "machine": on, "run_dir": None})
            for seed, on in ((0, "A (AVX2, 2 cores)"), (1000, "B (AVX512, 8 cores)"), (2000, "A (AVX2, 2 cores)"))]
    results = write_results(tmp_path, grid, "success_rate", None, 2, 1.0, searched=False)
    assert [t["machine"] for t in results["trials"]] == ["A (AVX2, 2 cores)", "B (AVX512, 8 cores)", "A (AVX2, 2 cores)"]
    report = (tmp_path / "sweep.md").read_text()
    assert "**The trials ran on 2 kinds of machine**" in report
    assert "- A (AVX2, 2 cores): seeds 0, 2000\n- B (AVX512, 8 cores): seeds 1000\n" in report
    assert "Every trial ran on" not in report


def _trials(out: Path) -> list[dict]:
    return json.loads((out / "sweep.json").read_text())["trials"]


@pytest.mark.slow
def test_a_seed_sweep_runs_each_seed_as_an_ordinary_run_and_aggregates(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", str(TINY), "--seeds", "2", "--out", str(out)]) == 0
    assert "test success_rate: IQM" in capsys.readouterr().out
    trials = _trials(out)
    assert [t["seed"] for t in trials] == [0, 1000] and {t["status"] for t in trials} == {"done"}
    for trial in trials:
        run = Path(trial["run_dir"])
        assert (run / "report.md").exists() and json.loads((run / "run.json").read_text())["seed"] == trial["seed"]
    results = json.loads((out / "sweep.json").read_text())
    assert results["backend"] == "ray" and results["aggregate"]["success_rate"]["n"] == 2
    here = describe(machine())
    assert [t["machine"] for t in trials] == [here, here] and f"Every trial ran on {here}." in (out / "sweep.md").read_text()
    assert (out / "sweep.png").stat().st_size > 1000 and "| metric |" in (out / "sweep.md").read_text()
    # A sweep directory is not reused by accident.
    assert main(["sweep", str(TINY), "--seeds", "2", "--out", str(out)]) == 2


@pytest.mark.slow
def test_trials_spread_over_the_nodes_of_a_cluster(tmp_path):
    from ray.cluster_utils import Cluster

    from common.curriculum.sweep import run_sweep

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    try:
        results = run_sweep(TINY, tmp_path / "sweep", seeds=2, address=cluster.address)
        # Without --address a sweep runs on a Ray of its own, not on the cluster this machine started last.
        local = run_sweep(TINY, tmp_path / "local", seeds=1)
    finally:
        cluster.shutdown()
    assert {t["status"] for t in results["trials"]} == {"done"}
    nodes = {t["node"] for t in results["trials"]}
    assert len(nodes) == 2, results["trials"]  # one trial on each node
    assert local["trials"][0]["status"] == "done" and local["trials"][0]["node"] not in nodes


@pytest.mark.slow
def test_trials_run_at_the_niceness_of_the_user_who_started_them(tmp_path, monkeypatch):
    # Ray's default, 15, starves a sweep beside any other work on the machine.
    from common.curriculum.sweep import run_sweep
    from tests.sweep_faults import record_niceness

    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    monkeypatch.delenv("RAY_worker_niceness", raising=False)
    out = tmp_path / "sweep"
    results = run_sweep(TINY, out, seeds=1, trainable=record_niceness)
    assert results["trials"][0]["status"] == "done"
    assert int((out / "niceness-seed0").read_text()) == os.getpriority(os.PRIO_PROCESS, 0)
    # What a resume holds to, recorded as the sweep began; the time is this command's.
    recorded = json.loads((out / "options.json").read_text())
    assert recorded.pop("curriculum_sha256") and recorded == {"seeds": 1, "space": None, "trials": 8, "metric": "success_rate"}
    assert results["resumed"] is False


@pytest.mark.slow
def test_a_trial_whose_process_dies_is_retried_from_its_checkpoint(tmp_path, monkeypatch):
    from common.curriculum.sweep import run_sweep
    from tests.sweep_faults import crash_once

    monkeypatch.setenv("PYTHONPATH", str(ROOT))  # the workers import the fault injector from tests/
    out = tmp_path / "sweep"
    results = run_sweep(TINY, out, seeds=1, max_failures=1, trainable=crash_once)
    (trial,) = results["trials"]
    crashed_at = int((out / "crashed-seed0").read_text())
    assert trial["status"] == "done" and crashed_at == 128
    rows = [int(r["timesteps"]) for r in csv.DictReader((Path(trial["run_dir"]) / "eval.csv").open())]
    assert rows == [128, 256, 384, 512]  # the evaluation before the crash kept, none repeated


@pytest.mark.slow
def test_an_interrupted_sweep_continues_with_resume(tmp_path):
    # Eight times the tiny budget, so the driver is still training when it is killed on a busy machine.
    longer = tmp_path / "longer.yaml"
    longer.write_text(TINY.read_text().replace("budget: 512", "budget: 4096").replace("every: 128", "every: 512"))
    assert "budget: 4096" in longer.read_text() and "every: 512" in longer.read_text()
    out = tmp_path / "sweep"
    driver = subprocess.Popen([sys.executable, "-m", "common.curriculum.cli", "sweep", str(longer), "--seeds", "2", "--out", str(out)],
                              cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 240
    while time.time() < deadline and not list(out.glob("trials/*/eval.csv")):
        time.sleep(0.2)
    while time.time() < deadline and not list((out / "ray").glob("experiment_state*.json")):
        time.sleep(0.2)
    assert driver.poll() is None, "the sweep ended before it could be interrupted"
    os.killpg(driver.pid, signal.SIGKILL)  # the driver and the local Ray it started
    driver.wait()
    assert not (out / "sweep.json").exists()
    before = {run.name: _eval_steps(run) for run in (out / "trials").iterdir() if (run / "eval.csv").exists()}
    resumed = subprocess.run([sys.executable, "-m", "common.curriculum.cli", "sweep", str(longer), "--seeds", "2", "--out", str(out),
                              "--resume"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert [t["status"] for t in _trials(out)] == ["done", "done"]
    for name, steps in before.items():  # each run went on from where it was killed, nothing repeated
        assert _eval_steps(out / "trials" / name) == list(range(512, 4097, 512)), name
        assert steps == list(range(512, 512 * (len(steps) + 1), 512))


@pytest.mark.slow
def test_a_sweep_killed_before_tune_saved_its_state_resumes_from_the_run_directories(tmp_path):
    from common.curriculum.runner import Runner
    from common.curriculum.schema import load_curriculum
    from common.curriculum.sweep import run_sweep

    out = tmp_path / "sweep"
    Runner(load_curriculum(TINY), out / "trials" / "seed0", progress=False).run()  # the trial's training, done
    (out / "ray").mkdir()  # Tune's directory, empty: the driver died before its first save
    trained = (out / "trials" / "seed0" / "eval.csv").read_text()
    results = run_sweep(TINY, out, seeds=1, resume=True)
    assert [t["status"] for t in results["trials"]] == ["done"]
    assert (out / "trials" / "seed0" / "eval.csv").read_text() == trained  # resumed, not trained again
    with pytest.raises(Exception, match="nothing to resume here"):
        run_sweep(TINY, tmp_path / "never", seeds=1, resume=True)


def _eval_steps(run: Path) -> list[int]:
    return [int(row["timesteps"]) for row in csv.DictReader((run / "eval.csv").open())]


# A search space is checked completely, and before Ray starts: each case's one-line error names the
# space file and the field. The first is the one whose every trial used to fail (exit 0 all the same).
SPACES = [
    ("stages.0.budget: {randint: [1, 1.0e+300]}", "stages.0.budget.randint: got [1, 1e+300]; allowed: two whole numbers"),
    ("stages.0.budget: {randint: [0, 100]}", "stages.0.budget: randint value 0 is not valid in the curriculum "
                                             "(stages.0.budget: Input should be greater than or equal to 1"),
    ("stages.0.n_envs: {uniform: [1, 8]}", "stages.0.n_envs: uniform value 1.0 is not valid in the curriculum "
                                           "(stages.0.n_envs: Input should be a valid integer"),
    ("stages.0.max_steps: {choice: [60, 1.0e+9]}", "stages.0.max_steps: choice value 1000000000.0 is not valid"),
    ("stages.3.budget: {randint: [1, 5]}", "stages.3.budget: stages is a list of 1; allowed: an index from 0 to 0"),
    # Read as index 0 too: two parameters set one value, the trial recording one never used.
    ("stages.0.budget: {randint: [1, 5]}\nstages.00.budget: {randint: [6, 9]}",
     "stages.00.budget: stages is a list of 1; allowed: an index from 0 to 0"),
    ("stages.0.name.x: {choice: [1]}", "stages.0.name.x: stages.0.name is 'open', not a mapping or list"),
    ("stages.0.bogus: {choice: [1]}", "stages.0.bogus: choice value 1 is not valid in the curriculum"),
    ("stages.0.hyperparams.n_epochs: {choice: [3, .nan]}", "stages.0.hyperparams.n_epochs.choice: got nan; allowed: finite"),
    ("stages.0.hyperparams.learning_rate: {uniform: [-1.0e+308, 1.0e+308]}", "learning_rate.uniform: got [-1e+308, 1e+308]"),
    ("seed: {randint: [1, 3]}", "seed: the sweep sets each trial's seed (--seeds)"),
]


def test_a_space_file_is_checked_completely_before_ray_starts(tmp_path, capsys, monkeypatch):
    import ray

    def refuse(*args, **kwargs):
        raise AssertionError("Ray started before the space file was checked")

    monkeypatch.setattr(ray, "init", refuse)
    space = tmp_path / "space.yaml"
    for text, expected in SPACES:
        space.write_text(text + "\n")
        code = main(["sweep", str(TINY), "--space", str(space), "--out", str(tmp_path / "s")])
        err = capsys.readouterr().err
        assert (code, err.count("\n")) == (2, 1) and err.startswith(f"error: {space}: ") and expected in err, (text, err)
    assert not (tmp_path / "s").exists()
    # The documented example space is accepted (and then reaches Ray, refused here).
    space.write_text("stages.0.hyperparams.learning_rate: {loguniform: [1.0e-4, 1.0e-3]}\n"
                     "stages.0.hyperparams.n_epochs: {choice: [3, 5, 10]}\nstages.0.env_kwargs.lidar_noise: {uniform: [0.0, 0.05]}\n")
    with pytest.raises(AssertionError, match="Ray started"):
        main(["sweep", str(TINY), "--space", str(space), "--out", str(tmp_path / "s")])
    # So is a CPU share that would have divided by zero once the sweep had run.
    assert main(["sweep", str(TINY), "--cpus-per-trial", "0", "--out", str(tmp_path / "s")]) == 2
    assert "--cpus-per-trial: got 0.0; allowed: a number above 0" in capsys.readouterr().err


@pytest.mark.slow
def test_failed_trials_fail_the_sweep_which_names_them_and_still_reports_the_rest(tmp_path, capsys, monkeypatch):
    from common.curriculum import sweep
    from tests.sweep_faults import fail_first_to_start

    monkeypatch.setenv("PYTHONPATH", str(ROOT))  # the workers import the fault injector from tests/
    monkeypatch.setattr(sweep, "run_trial", fail_first_to_start)
    space, out = tmp_path / "space.yaml", tmp_path / "sweep"
    space.write_text("stages.0.hyperparams.n_epochs: {choice: [1]}\n")  # both trials get the same value
    code = main(["sweep", str(TINY), "--space", str(space), "--trials", "2", "--max-failures", "0", "--out", str(out)])
    printed = capsys.readouterr()
    results = json.loads((out / "sweep.json").read_text())
    assert code == 1 and len(results["failed"]) == 1, (code, printed.err[-2000:])
    (failed,) = results["failed"]
    (other,) = [t for t in results["trials"] if t["name"] != failed]
    assert failed.startswith("seed0-n_epochs=1-") and other["status"] == "done"
    # Tune logs the trial's traceback as it happens; the sweep ends with which trials failed and why,
    # each in one line (the first of its error).
    assert printed.err.splitlines()[-2:] == [f"error: 1 of 2 trials failed (marked in {out / 'sweep.md'}):",
                                             f"  {failed}: RuntimeError: planted failure at the first evaluation"]
    # The report is still written, over the trial that ran (a search's: no spread over seeds).
    assert "(no interval from one value), mean" in printed.out and "over 1 trial of different settings" in printed.out
    report = (out / "sweep.md").read_text()
    assert "**1 of 2 trials failed**" in report and f"- `{failed}`: RuntimeError: planted failure" in report
    assert report.count("| **failed** |") == 1
    # The same values proposed twice are two trials, each with a run directory of its own.
    assert sorted(p.name for p in (out / "trials").iterdir()) == sorted([failed, other["name"]])


def test_a_resumed_sweep_holds_to_the_options_it_began_with(tmp_path, capsys):
    """Tune restores the sweep it saved: --seeds 3 on a resumed sweep of 2 kept 2 seeds, and an
    edited budget the old one, silently."""
    import yaml

    from common.curriculum.sweep import OPTIONS_FILE, curriculum_digest, sweep_options

    out, digest = tmp_path / "sweep", curriculum_digest(yaml.safe_load(TINY.read_text()))
    fresh = sweep_options(out, {"seeds": 2, "space": None, "trials": None, "metric": None}, False, TINY, digest)
    assert fresh == {"seeds": 2, "space": None, "trials": 8, "metric": "success_rate", "curriculum_sha256": digest}
    out.mkdir()
    (out / OPTIONS_FILE).write_text(json.dumps(fresh))
    given = {"seeds": None, "space": None, "trials": None, "metric": None}
    recorded = {**fresh, "space_sha256": None}  # a seed sweep's: no space file
    assert sweep_options(out, given, True, TINY, digest) == recorded  # left out: as it began
    assert sweep_options(out, {**given, "seeds": 2}, True, TINY, digest) == recorded  # the same: fine
    assert main(["sweep", str(TINY), "--seeds", "3", "--out", str(out), "--resume"]) == 2
    assert capsys.readouterr().err == ("error: --seeds: 3, but this sweep began with 2: a resume continues it as it "
                                       "began (leave the option out, or choose another --out)\n")
    edited = tmp_path / "edited.yaml"
    edited.write_text(TINY.read_text().replace("budget: 512", "budget: 256"))
    assert main(["sweep", str(edited), "--out", str(out), "--resume"]) == 2
    assert capsys.readouterr().err == (f"error: {edited}: changed since this sweep began; a resume continues it as it "
                                       "began (restore the file, or start a new sweep with another --out)\n")
    for bad, expected in (('{"seeds": 2}', "space: Field required"),
                          ('{"seeds": 1e9, "space": null, "trials": 8, "metric": "spl"}', "seeds: Input should be a valid integer"),
                          ('{"seeds": 100000, "space": null, "trials": 8, "metric": "spl"}', "seeds: Input should be less than")):
        (out / OPTIONS_FILE).write_text(bad)  # a shared run directory: its seeds drive a loop
        with pytest.raises(ConfigError, match=f"options.json: {expected}"):
            sweep_options(out, given, True, TINY, digest)


def test_a_sweep_writes_only_into_its_own_directory(tmp_path, capsys):
    """A sweep wrote its ray/, trials/ and reports among a user's files, and named a temporary
    only after Ray had started where --out was a file."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("x")
    assert main(["sweep", str(TINY), "--out", str(mine)]) == 2
    assert capsys.readouterr().err == (f"error: {mine}: is not empty and not a sweep's directory (it has no "
                                       "options.json, ray or trials); choose an empty or a new --out (nothing was changed)\n")
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    assert main(["sweep", str(TINY), "--out", str(mine / "notes.txt")]) == 2
    assert capsys.readouterr().err == f"error: {mine / 'notes.txt'}: is not a directory; --out names the sweep's directory\n"


def test_parameter_importance_is_not_drawn_when_every_trial_scored_the_same():
    """PED-ANOVA split the importance equally (0.5 each) over trials that all scored 0.0."""
    from matplotlib.figure import Figure

    from common.curriculum.sweep_report import _importance

    def trials(scores):
        return [{"final": {"success_rate": score}, "params": {"stages.0.hyperparams.gamma": 0.9 + 0.01 * k,
                                                              "stages.0.hyperparams.n_epochs": 1 + k % 3}}
                for k, score in enumerate(scores)]

    flat, varied = Figure().add_subplot(), Figure().add_subplot()
    _importance(flat, trials([0.0] * 6), "success_rate")
    assert not flat.patches and "no parameter importance" in flat.texts[0].get_text()
    _importance(varied, trials([0.1, 0.9, 0.2, 0.8, 0.3, 0.7]), "success_rate")
    assert len(varied.patches) == 2 and not varied.texts


def test_a_seed_sweep_stopped_by_ctrl_c_says_so_and_how_to_go_on(tmp_path, capsys, monkeypatch):
    """Ray Tune ends a sweep on the first Ctrl-C and returns: its unfinished trials were reported
    as the sweep's figures, with exit code 0 (seen by running one and sending SIGINT)."""
    from common.curriculum import sweep

    stopped = {"status": "stopped early", "name": "seed0", "final": None}
    results = {"aggregate": {}, "trials": [stopped, {**stopped, "name": "seed1000"}], "concurrent_trials": 2,
               "wall_seconds": 35.0}
    monkeypatch.setattr(sweep, "run_sweep", lambda *args, **kwargs: results)
    out = tmp_path / "sweep"
    assert main(["sweep", str(TINY), "--seeds", "2", "--out", str(out)]) == 130
    assert capsys.readouterr().err == (f"interrupted: 2 of 2 trials unfinished (each run is whole to its last "
                                       f"checkpoint); continue with: curriculum sweep {TINY} --out {out} --resume\n")


def test_a_trial_ray_never_started_counts_as_unfinished():
    """Ctrl-C with more seeds than cores: Ray leaves a trial it never started without a config,
    and the report crashed on it (a traceback, exit 1, no results)."""
    from types import SimpleNamespace

    from common.curriculum.sweep_report import _trial

    waiting = _trial(SimpleNamespace(config=None, metrics=None, error=None))
    assert waiting["status"] == "not started" and waiting["seed"] is None and waiting["final"] is None


def test_options_that_do_not_apply_and_seeds_past_the_last_are_refused_before_ray(tmp_path, capsys, monkeypatch):
    """--seeds with --space ran one seed while options.json recorded three; --trials and --metric
    without one did nothing; a seed sweep past 2**31 - 1 failed every later trial three times in Ray."""
    import ray

    monkeypatch.setattr(ray, "init", lambda *args, **kwargs: pytest.fail("Ray started"))
    space = tmp_path / "space.yaml"
    space.write_text("stages.0.hyperparams.n_epochs: {choice: [3, 5]}\n")
    late = tmp_path / "late.yaml"
    late.write_text(TINY.read_text().replace("\nseed: 0\n", "\nseed: 2147483000\n"))
    for argv, expected in (
            (["--space", str(space), "--seeds", "3"], "error: --seeds: 3 with --space; allowed: a search (--space) runs"),
            (["--trials", "4"], "error: --trials: 4 without --space; allowed: only with a search (--space)"),
            (["--metric", "spl"], "error: --metric: 'spl' without --space; allowed: only with a search (--space)"),
            (["--resume"], "nothing to resume here (no sweep ran); run without --resume")):
        assert main(["sweep", str(TINY), "--out", str(tmp_path / "s"), *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expected in err, err
    assert main(["sweep", str(late), "--seeds", "2", "--out", str(tmp_path / "s")]) == 2
    assert capsys.readouterr().err == (f"error: {late}: seed: 2147483000: --seeds 2 runs seeds up to 2,147,484,000; "
                                       "allowed: a seed of at most 2,147,482,647 for --seeds 2\n")
    assert not (tmp_path / "s").exists()


def test_a_search_resumed_after_its_space_file_changed_is_refused(tmp_path, capsys, monkeypatch):
    """Only the curriculum was compared: a space edited between runs went on unnoticed."""
    import ray
    import yaml

    from common.curriculum.sweep import OPTIONS_FILE, curriculum_digest

    monkeypatch.setattr(ray, "init", lambda *args, **kwargs: pytest.fail("Ray started"))
    space = tmp_path / "space.yaml"
    space.write_text("stages.0.hyperparams.n_epochs: {choice: [3, 5]}\n")
    out = tmp_path / "search"
    out.mkdir()
    (out / OPTIONS_FILE).write_text(json.dumps({
        "seeds": 1, "space": str(space), "trials": 2, "metric": "success_rate",
        "curriculum_sha256": curriculum_digest(yaml.safe_load(TINY.read_text())),
        "space_sha256": curriculum_digest(yaml.safe_load(space.read_text()))}))
    space.write_text("stages.0.hyperparams.n_epochs: {choice: [3, 10]}\n")
    assert main(["sweep", str(TINY), "--out", str(out), "--resume"]) == 2
    assert capsys.readouterr().err == (f"error: {space}: changed since this sweep began; a resume continues it as it "
                                       "began (restore the file, or start a new sweep with another --out)\n")
