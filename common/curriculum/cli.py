"""The ``curriculum`` command: run, eval, compare, render, validate, bench."""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, Sequence

import numpy as np

from common.atomic import atomic_write_all, is_temporary_of, writable_place
from common.errors import ConfigError, ScenarioWarning, did_you_mean
from common.task import MAX_EPISODES

if TYPE_CHECKING:
    from common.conditions import Conditions
    from common.scenario import RobotProfile, Scenario
    from common.world_file import WorldFile

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command Ctrl-C stopped


def _validate(args: argparse.Namespace) -> int:
    """Every file is answered, a bad one in its own error line; exit 2 if any was bad."""
    bad = 0
    for path in args.files:
        try:
            print(_validated(path))
        except (ConfigError, OSError) as error:
            print(_error_line(error), file=sys.stderr)
            bad += 1
    return EXIT_BAD_INPUT if bad else 0


def _validated(path: str) -> str:
    """The ``ok:`` line of a valid curriculum, scenario or IR-SIM world file (its warnings on stderr)."""
    from common.curriculum.schema import curriculum_from_mapping, is_curriculum
    from common.world_file import WorldFile
    from common.yaml_io import read_yaml_mapping

    data = read_yaml_mapping(path)
    # A world file IR-SIM runs as it is (a start touching an obstacle, say) warns; so does a
    # curriculum's stage on one, whose world validation reads.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ScenarioWarning)
        if is_curriculum(data):
            config = curriculum_from_mapping(data, path)
            line = f"ok: {path}: curriculum {config.name!r}, {_counted(len(config.stages), 'stage')}"
        else:
            from common.motion.movers import refuse_unmodelled

            scenario = WorldFile(path).initial
            try:  # no tier builds such a world: a file nothing can run is not ok
                refuse_unmodelled(scenario)
            except ConfigError as error:
                raise error.with_source(path) from None
            line = f"ok: {path}: scenario {scenario.name!r}, {_counted(len(scenario.obstacles), 'obstacle')}"
    for warning in caught:
        if issubclass(warning.category, ScenarioWarning):
            print(f"warning: {warning.message}", file=sys.stderr)
        else:  # a library's own warning, as it would have shown
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    return line


def _run(args: argparse.Namespace) -> int:
    from common.curriculum.runner import Runner, resolve_device
    from common.curriculum.schema import load_curriculum

    config = load_curriculum(args.file)
    out = Path(args.out) if args.out else Path("runs") / config.name
    device = resolve_device(args.device, None, "--device") if args.device else resolve_device(config.device, args.file)
    try:
        state = Runner(config, out, resume=args.resume, device=device, progress=not args.no_progress).run()
    except KeyboardInterrupt:
        if not (out / "state.json").exists():
            raise
        print("interrupted; every checkpoint written so far is whole: continue with --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as error:
        raise ConfigError(error.filename or out, None, f"{error.strerror or error}; every checkpoint written so far is "
                          f"whole: once this is fixed, continue with --resume") from None
    for name, result in state["stages"].items():
        final = result["final"]
        print(f"{name}: {result['timesteps']:,} steps in {result['wall_seconds']:.0f} s; test success "
              f"{final['success_rate']:.1%} over {final['episodes']} episodes, collisions {final['collision_rate']:.1%}, "
              f"SPL {final['spl']:.3f}; policy {out / result['policy']}")
    transfer = state.get("transfer")
    if transfer:
        scratch = transfer.get("scratch_success")
        print(f"transfer over {transfer['seeds']} seeds: zero-shot {transfer['zero_shot_success']:.1%}, fine-tuned "
              f"{transfer['fine_tuned_success']:.1%}" + ("" if scratch is None else f", from scratch {scratch:.1%}")
              + f"; steps to 90% validation {transfer['steps_to_90']}")
    print(f"report: {out / 'report.md'}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from common.curriculum.sweep import run_sweep
    from common.statistics import interval_text

    try:
        import ray  # noqa: F401
        import optuna  # noqa: F401
    except ImportError:
        raise ConfigError(None, "sweep", "needs Ray Tune and Optuna: pip install -e \".[sweep]\"") from None
    out = Path(args.out) if args.out else Path("runs") / "sweeps" / Path(args.file).stem
    results = run_sweep(args.file, out, seeds=args.seeds, space=args.space, trials=args.trials, metric=args.metric,
                        address=args.address, cpus_per_trial=args.cpus_per_trial, max_failures=args.max_failures,
                        resume=args.resume, device=args.device)
    for name, agg in results["aggregate"].items():
        if agg["iqm"] is not None:
            # A search's trials are different settings: their IQM is no spread over seeds.
            n = agg["n"]
            over = f"{n} trial{'s' * (n != 1)} of different settings" if args.space else f"{n} seed{'s' * (n != 1)}"
            print(f"test {name}: IQM {agg['iqm']:.3f} ({interval_text(agg, '-')}), mean {agg['mean']:.3f}, over {over}")
    print(f"{len(results['trials'])} trials, {results['concurrent_trials']} at a time, {results['wall_seconds']:.0f} s; "
          f"results: {out / 'sweep.md'}")
    unfinished = [t for t in results["trials"] if t["status"] in ("stopped early", "not started")]
    if unfinished and not args.space:
        # A seed sweep stops no trial early: Ctrl-C did (Ray Tune ends the sweep on the first one and
        # says to resume with its own API), and the figures above are of unfinished runs.
        print(f"interrupted: {len(unfinished)} of {len(results['trials'])} trials unfinished (each run is whole to "
              f"its last checkpoint); continue with: curriculum sweep {args.file} --out {out} --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    failed = [t for t in results["trials"] if t["status"] == "error"]
    if not failed:
        return 0
    # The report is written and marks them; the exit code says the sweep is not what was asked for.
    print(f"error: {len(failed)} of {len(results['trials'])} trials failed (marked in {out / 'sweep.md'}):", file=sys.stderr)
    for trial in failed:
        print(f"  {trial['name']}: {trial['error']}", file=sys.stderr)
    return 1


def _eval(args: argparse.Namespace) -> int:
    from common.evaluation import evaluate
    from common.curriculum.comparison import markdown_table

    agents = _distinct_names(_policies(args.policy), [str(path) for path in args.policy])
    _settle(args, agents)
    _scenarios(args, count=1).first()  # a bad scenario file is refused before any episode
    # Each policy runs episodes as long as, under the conditions and judged within the goal radius
    # it trained with, unless --max-steps, --env-kwargs and --goal-threshold say otherwise.
    summaries = []
    for agent in agents:
        radius, conditions = _judged(args, [agent]), _conditions(args, [agent])
        scenarios = _scenarios(args, conditions=conditions)
        _announce(args, [agent], scenarios, radius, conditions)
        summaries += evaluate([agent], scenarios, args.world, seed=args.seed, max_steps=args.max_steps,
                              conditions=conditions, goal_radius=radius, jobs=args.jobs)
    if args.json:
        print(json.dumps(summaries[0].to_json() if len(summaries) == 1 else {s.agent: s.to_json() for s in summaries}))
    else:
        print(markdown_table(summaries))
    return 0


def _policies(paths):
    """Policy zips, and policies exported to ONNX (``.onnx``: run by onnxruntime, torch never loaded)."""
    from common.curriculum.onnx_policy import load_onnx_policy
    from common.curriculum.policy_file import PolicyFile

    paths = list(paths or [])
    # Every file is opened (and a file that is no policy refused) before torch loads.
    opened = [load_onnx_policy(path) if _is_onnx(path) else PolicyFile(path) for path in paths]
    if all(_is_onnx(path) for path in paths):
        return opened
    from common.curriculum.policy import load_policy

    return [agent if _is_onnx(path) else load_policy(agent) for path, agent in zip(paths, opened)]


def _distinct_names(agents: list, labels: list[str]) -> list:
    """The agents, those that share a name (two runs' ``best.zip`` are both CURRICULUM/STAGE, a
    policy file may be called like a controller) renamed by their label (a policy's path), and
    any still alike numbered: the table, the JSON and the GIFs key their rows by name."""
    counts = Counter(agent.name for agent in agents)
    for agent, label in zip(agents, labels):
        if counts[agent.name] > 1:
            agent.name = label
    seen: Counter = Counter()
    for agent in agents:
        seen[agent.name] += 1
        if seen[agent.name] > 1:
            agent.name = f"{agent.name} ({seen[agent.name]})"
    return agents


def _is_onnx(path) -> bool:
    return str(path).lower().endswith(".onnx")


def _export(args: argparse.Namespace) -> int:
    from common.curriculum.onnx_export import export_onnx

    out = export_onnx(args.policy, args.onnx)
    print(f"wrote {out} ({out.stat().st_size:,} bytes): input 'observation', output 'action' in [-1, 1]; "
          "its metadata holds the policy's manifest (docs/deploy.md)")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from common.curriculum.bench import gui_figures, run_benchmarks

    measure = gui_figures if args.gui else run_benchmarks
    results = measure(steps=args.steps) if args.steps else measure()  # each has its own default
    if args.json:
        print(json.dumps(results))
        return 0
    from rich.console import Console
    from rich.table import Table

    table = Table(title="curriculum bench")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for key, value in results.items():
        table.add_row(key, "n/a (not installed)" if value is None else f"{value:,}" if isinstance(value, (int, float)) else str(value))
    Console().print(table)
    return 0


def _scenarios(args: argparse.Namespace, count: int | None = None, conditions=None, first: int = 0):
    """The scenarios an eval/compare/render run uses, from the ``first``: a suite's, or a world
    file's (a file with random placements is drawn anew per episode, from seed S + i), as a
    :class:`Drawn` (a bad file or suite name refused here, before anything is drawn).
    Scenario i is drawn from its own seed alone, so the 1,000,000th costs what the first does. A
    suite laid out for its robot (``passages``) is drawn for the robot of ``conditions``."""
    from common.generators import get_suite
    from common.world_file import WorldFile

    count = args.episodes if count is None else count
    seed = args.seed + first
    if args.scenario_file:
        # Parsed here once (a file that is no world refused here): every draw, the workers' too,
        # comes from this reading, so a file edited mid-run changes nothing of the run.
        return Drawn(count, seed, file=WorldFile(args.scenario_file))
    get_suite(args.suite)  # as an unknown name is
    robot = conditions.for_tier(args.world, strict=False).profile if conditions is not None else None
    return Drawn(count, seed, suite=args.suite, robot=robot)


@dataclass(frozen=True)
class Drawn:
    """An evaluation's ``count`` scenarios from ``seed`` on, of a suite (laid out for ``robot``
    where it is a suite laid out per robot) or of a parsed world file, drawn as they are read: a million
    of them held at once would take tens of GB. Pickled, it is the recipe
    (:class:`common.evaluation.ScenarioSource`): worker processes draw their own."""

    count: int
    seed: int
    suite: str | None = None
    file: "WorldFile | None" = None
    robot: "RobotProfile | None" = None

    def __len__(self) -> int:
        return self.count

    def __iter__(self) -> Iterator[Scenario]:
        return iter(self.part(0, self.count))

    def part(self, start: int, stop: int) -> Iterator[Scenario]:
        """Scenarios ``start`` to ``stop`` (exclusive): scenario i is drawn from seed + i alone."""
        from common.generators import get_suite

        if self.file is not None:
            return (self.file.scenario(self.seed + i) for i in range(start, stop))
        return get_suite(self.suite).scenarios(count=stop - start, seed=self.seed + start, robot=self.robot)

    def first(self) -> Scenario:
        return next(iter(self.part(0, 1)))


def _settle(args: argparse.Namespace, agents) -> None:
    """Fill in --world, --suite, --seed and --episodes left unset: as the policies among ``agents``
    had their own test figure measured (if they agree), else flatland, sparse, seed 0 and the
    command's own number of episodes."""
    homes = {agent.home for agent in agents if getattr(agent, "home", None) is not None}
    world, suite, seed, episodes = homes.pop() if len(homes) == 1 else ("flatland", "sparse", 0, args.default_episodes)
    args.world = args.world or world
    args.suite = args.suite or suite
    args.seed = seed if args.seed is None else args.seed
    if hasattr(args, "episodes"):
        args.episodes = episodes if args.episodes is None else args.episodes


def _counted(count: int, noun: str) -> str:
    """``count`` of ``noun`` (a regular plural): "1 episode", "2 stages"."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"


def _announce(args: argparse.Namespace, agents: list, scenarios: Drawn | list, radius: float | None,
              conditions) -> None:
    """Say on stderr what the agents are measured on, so a figure can be told apart and re-run;
    a scenario that cannot be drawn, a world the tier cannot build, or an agent that cannot drive
    its robot, is refused first, instead (:func:`_refuse_undrivable`)."""
    _refuse_undrivable(agents, _driven_robots(args, scenarios, conditions), radius)
    resolved = conditions.for_tier(args.world)
    who = agents[0].name if len(agents) == 1 else _counted(len(agents), "agent")
    source = args.scenario_file or f"suite {args.suite}"
    judged = f"within {radius:g} m of the goal" if radius is not None else "within each scenario's goal radius"
    knobs = ", ".join(f"{k}={v}" for k, v in resolved.given().items()) or "ideal"
    print(f"{who}: {args.world}, {source}, {_counted(len(scenarios), 'episode')} from seed {args.seed}, "
          f"judged {judged}; conditions: {knobs}", file=sys.stderr)


def _driven_robots(args: argparse.Namespace, scenarios: Drawn | list, conditions) -> list:
    """Every scenario drawn once and let go (so an evaluation holds only the block it drives; a
    draw that fails is refused before any episode), checked as ``--world`` drives it under
    ``conditions`` (a world it cannot build, such as a grid map in 3D or a polygon robot among
    movers, refused with the suite or file it came from): one of them per robot and lidar."""
    from rich.progress import track

    from common.tiers import refuse_unbuildable

    resolved = conditions.for_tier(args.world)
    distinct = {}
    # A draw costs about a millisecond: a million scenarios are minutes of checking, shown as such
    # on a terminal (elsewhere the bar's last line would come before a refusal's one line).
    console = _stderr_console()
    for scenario in track(scenarios, f"checking {len(scenarios):,} scenarios", total=len(scenarios),
                          transient=True, console=console, disable=not console.is_terminal):
        # A robot that does not fit its world is the robot's error (--env-kwargs put it in), raised here.
        conditioned = resolved.scenario(scenario)
        try:
            refuse_unbuildable(args.world, scenario, conditioned)
        except ConfigError as error:
            raise ConfigError(args.scenario_file or f"suite {args.suite}", error.field, error.problem) from None
        distinct[(conditioned.robot, conditioned.lidar)] = conditioned
    return list(distinct.values())


def _refuse_undrivable(agents: list, scenarios: list, radius: float | None) -> None:
    """Bind each agent to every robot and lidar among ``scenarios`` (as conditioned), as the
    episodes will: one it cannot drive raises its one-line error here, before any episode."""
    for scenario in {(s.robot, s.lidar): s for s in scenarios}.values():
        for agent in agents:
            agent.bind(scenario.robot, scenario.lidar, scenario.goal_threshold if radius is None else radius)


def _judged(args: argparse.Namespace, agents) -> float | None:
    """The goal radius to judge by: ``--goal-threshold``, else the radius the policies among
    ``agents`` trained for (which must agree), else None (each scenario's own)."""
    from common.task import judged_radius

    if args.goal_threshold is not None:
        return args.goal_threshold
    radii = {judged_radius(agent.env_kwargs) for agent in agents if hasattr(agent, "env_kwargs")}
    if len(radii) > 1:
        raise ConfigError(None, "--policy", f"these policies trained for different goal radii ({sorted(map(str, radii))}); "
                          "give --goal-threshold to judge them alike")
    return radii.pop() if radii else None


def _controllers(names: str | None, flag: str):
    """Controllers by comma-separated names (all of them when ``names`` is None)."""
    from common.controllers import CONTROLLERS, make_controller

    if names is None:
        return [make_controller(name) for name in CONTROLLERS]
    chosen = [n.strip() for n in names.split(",") if n.strip()]
    if not chosen:
        raise ConfigError(None, flag, f"no controller named in {names!r}; allowed: a comma-separated list of {', '.join(CONTROLLERS)}")
    return [make_controller(name, source=flag) for name in chosen]


def _agent(spec: str):
    """``--agent``: a controller name or a policy zip."""
    from common.controllers import CONTROLLERS

    if spec.endswith(".zip") or _is_onnx(spec) or Path(spec).is_file():
        return _policies([spec])[0]
    if spec not in CONTROLLERS:
        raise ConfigError(None, "--agent", f"{spec!r} is neither a controller ({', '.join(CONTROLLERS)}) nor a policy "
                          ".zip or .onnx")
    return _controllers(spec, "--agent")[0]


def _compare(args: argparse.Namespace) -> int:
    from rich.progress import Progress

    if args.gif and Path(args.gif).exists() and not Path(args.gif).is_dir():
        raise ConfigError(args.gif, None, "--gif names a directory for the GIFs (one per agent), not a file")

    policies = _policies(args.policy)
    _settle(args, policies)
    scenarios = _scenarios(args)
    scenarios.first()  # a bad file is refused before the controllers and worlds load (seconds)
    controllers = _controllers(args.controllers, "--controllers")
    agents = _distinct_names(controllers + policies, [c.name for c in controllers] + [str(p) for p in args.policy or []])

    from common.evaluation import evaluate
    from common.curriculum.comparison import bar_chart, markdown_table, paired_table, write_csv

    radius, conditions = _judged(args, agents), _conditions(args, agents)
    scenarios = _scenarios(args, conditions=conditions) if not args.scenario_file else scenarios
    source = Path(args.scenario_file).stem if args.scenario_file else args.suite
    out = _compare_directory(Path(args.out) if args.out else Path("runs") / "compare" / f"{args.world}-{source}")
    _announce(args, agents, scenarios, radius, conditions)
    writable_place(out, "--out", directory=True)
    if args.gif:
        writable_place(args.gif, "--gif", directory=True)
    with Progress(transient=True, console=_stderr_console()) as bar:
        task = bar.add_task(f"{source}: {len(agents)} agents x {len(scenarios)} episodes", total=len(agents) * len(scenarios))
        summaries = evaluate(agents, scenarios, args.world, seed=args.seed, max_steps=args.max_steps,
                             conditions=conditions, goal_radius=radius, progress=lambda n: bar.advance(task, n),
                             jobs=args.jobs)
    judged = f"{radius:g} m" if radius is not None else "each scenario's radius"
    title = f"{args.world} / {source}: {_counted(len(scenarios), 'episode')} from seed {args.seed}, judged within {judged}"
    table = markdown_table(summaries, title)
    if paired := paired_table(summaries):
        table += "\n" + paired
    atomic_write_all({out / "comparison.md": lambda tmp: tmp.write_text(table),
                      out / "episodes.csv": lambda tmp: write_csv(summaries, tmp),
                      out / "comparison.png": lambda tmp: bar_chart(summaries, tmp, title)})
    gifs = [_record(agent, scenarios.first(), args, Path(args.gif) / f"{_file_name(agent.name)}.gif", radius=radius)[0]
            for agent in agents] if args.gif else []
    if args.json:
        print(json.dumps({s.agent: s.to_json() for s in summaries}))
    else:
        print(table)
        print(f"written: {out}/comparison.md, episodes.csv, comparison.png" + "".join(f", {gif}" for gif in gifs))
    return 0


COMPARE_FILES = ("comparison.md", "episodes.csv", "comparison.png")


def _compare_directory(out: Path) -> Path:
    """``--out`` of compare, checked: new, empty, or holding only an earlier comparison (which it
    replaces); anything else is refused before a file is written. Created when the results are."""
    if out.exists() and not out.is_dir():
        raise ConfigError(out, None, "is not a directory; --out names the comparison's directory")
    held = list(out.iterdir()) if out.is_dir() else []
    # A comparison's files, its GIFs (--gif may name the same directory) or temporaries a killed
    # one left: anything else, even a folder under one of their names, is the user's (and would
    # stop the set's renames halfway).
    if any(not p.is_file() or (p.name not in COMPARE_FILES and p.suffix.lower() != ".gif"
                               and not is_temporary_of(p.name, COMPARE_FILES)) for p in held):
        raise ConfigError(out, None, f"holds files other than a comparison's ({', '.join(COMPARE_FILES)}, GIFs); "
                          "choose an empty or a new --out (nothing was changed)")
    for leftover in (p for p in held if is_temporary_of(p.name, COMPARE_FILES)):
        leftover.unlink()
    return out


def _conditions(args: argparse.Namespace, agents) -> "Conditions":
    """The conditions to evaluate ``agents`` under: ``--env-kwargs``, over the conditions the
    policies among them trained with (which must agree, so every agent meets the same world)."""
    from common.conditions import Conditions, conditions_of, refuse_other_knobs

    trained = {json.dumps(conditions_of(agent.trained_conditions).given(), sort_keys=True)
               for agent in agents if hasattr(agent, "trained_conditions")}
    override = _given_env_kwargs(args)
    if len(trained) > 1 and not override:
        raise ConfigError(None, "--policy", "these policies trained under different conditions "
                          f"({'; '.join(sorted(trained))}); give --env-kwargs to compare them under one")
    # Flags override the knobs they name; the rest stay as trained (unless the policies disagree).
    base = json.loads(trained.pop()) if len(trained) == 1 else {}
    # A policy's knobs of the other tier (2D wheel dynamics in 3D, say) do not carry over.
    resolved = Conditions.parse(base).for_tier(args.world, strict=False)
    try:
        refuse_other_knobs(override, args.world)  # before the values: a value's advice is for a knob of this tier
        extra = Conditions.parse(override, field="--env-kwargs")
        extra.for_tier(args.world)
    except ConfigError as error:
        raise ConfigError(None, error.field if error.field.startswith("--") else f"--env-kwargs.{error.field}",
                          error.problem) from None
    if not override:
        return resolved
    trained_knobs = resolved.given()
    # A robot given on the command line drives instead of the robots a policy was trained on, and the other way round.
    for given, replaced in (("robot", "robot_family"), ("robot_family", "robot")):
        if given in extra.given():
            trained_knobs.pop(replaced, None)
    return Conditions.parse({**trained_knobs, **extra.given()})


def _given_env_kwargs(args: argparse.Namespace) -> dict:
    """``--env-kwargs`` as a mapping: a key given twice is refused, as a key twice in YAML is
    (the last would silently win)."""
    pairs = list(args.env_kwargs or [])
    for key, count in Counter(key for key, _ in pairs).items():
        if count > 1:
            raise ConfigError(None, f"--env-kwargs.{key}", "given twice; allowed: each key once")
    return dict(pairs)


def _file_name(name: str) -> str:
    """An agent's name as a file name (policies are named curriculum/stage)."""
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in name)


def _record(agent, scenario, args: argparse.Namespace, gif: Path, radius: float | None, every: int = 1):
    from flatland.render import record_agent

    return record_agent(agent, scenario, gif, tier=args.world, seed=args.seed, max_steps=args.max_steps, every=every,
                        conditions=_conditions(args, [agent]), goal_radius=radius)


def _output_file(name: str, flag: str, what: str, suffix: str) -> Path:
    """``flag``'s file to write, checked before any episode runs."""
    path = Path(name)
    if path.is_dir() or path.suffix.lower() != suffix:
        raise ConfigError(path, None, f"{flag} names {what} (FILE{suffix}), not a directory or another kind of file")
    return path


def _render(args: argparse.Namespace) -> int:
    from flatland.render import plot_odometry_drift

    gif = _output_file(args.out, "--out", "the GIF to write", ".gif")
    drift = _output_file(args.drift, "--drift", "the plot to write", ".png") if args.drift else None
    agent = _agent(args.agent)
    _settle(args, [agent])
    radius, conditions = _judged(args, [agent]), _conditions(args, [agent])
    (scenario,) = _scenarios(args, count=1, conditions=conditions, first=args.index)
    _announce(args, [agent], [scenario], radius, conditions)
    writable_place(gif, "--out")
    if drift:
        writable_place(drift, "--drift")
    scenario = conditions.for_tier(args.world).scenario(scenario)  # the robot and the encoders that drive
    gif, episode, true_path, estimate = _record(agent, scenario, args, gif, radius, args.every)
    print(f"{gif}: {agent.name} on {scenario.name}: {episode.outcome} after {episode.steps} steps, "
          f"{episode.path_length:.2f} m")
    if drift:
        drift.parent.mkdir(parents=True, exist_ok=True)
        plot_odometry_drift(scenario, true_path, estimate, drift)
        error = float(np.hypot(*(np.asarray(true_path[-1]) - np.asarray(estimate[-1]))))
        print(f"{drift}: odometry drift {error:.3f} m after {episode.path_length:.2f} m "
              f"(encoder noise {scenario.robot.encoder_noise})")
    return 0


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


def _add_scenario_source(parser: argparse.ArgumentParser, episodes: int | None) -> None:
    """--world, --suite | --scenario-file, --seed, --max-steps, and --episodes unless ``episodes`` is None."""
    from common.generators import SUITES
    from common.tiers import WORLDS

    parser.add_argument("--world", choices=WORLDS,
                        help="the tier, or irsim: IR-SIM itself, the [irsim] extra (default: where a policy's own "
                             "test figure was measured, else flatland)")
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--suite", choices=sorted(SUITES),
                        help="a named suite (default: a policy's own test suite, else sparse)")
    source.add_argument("--scenario-file", metavar="FILE", help="a scenario or IR-SIM world YAML")
    parser.set_defaults(default_episodes=episodes)
    if episodes is not None:
        parser.add_argument("--episodes", type=whole_number(1, MAX_EPISODES),
                            help=f"episodes (default: as many as a policy's own test figure, else {episodes})")
    parser.add_argument("--seed", type=whole_number(0, 2**32 - 1),
                        help="shifts the suite's base seed and the noise seeds, 0 to 2^32 - 1 (default: a "
                             "policy's own test draw's, else 0)")
    parser.add_argument("--max-steps", type=whole_number(1, 1_000_000), default=None,
                        help="steps before a timeout (default: a policy's own episode length, else 500)")
    parser.add_argument("--goal-threshold", type=_metres, metavar="M",
                        help="judge arrival within M metres (default: the radius a policy trained for, else each scenario's)")
    parser.add_argument("--env-kwargs", type=_key_value, nargs="+", metavar="KEY:VALUE",
                        help="conditions (e.g. lidar_noise:0.02 motor_scale:[0.8,1.2] robot:physics3d), "
                             "over a policy's own (values read as YAML)")


def _add_jobs(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--jobs", type=whole_number(1, 1024), default=1, metavar="N",
                        help="worker processes that run the episodes (default 1); every N gives the same figures")


def whole_number(low: int, high: int) -> Callable[[str], int]:
    """An argparse type: a whole number in [low, high] (argparse names the flag in its message)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be from {low:,} to {high:,}, got {value:,}")
        return value

    return parse


def _key_value(text: str) -> tuple[str, object]:
    """An argparse type: KEY:VALUE, the value read as YAML (rl-baselines3-zoo's --env-kwargs syntax)."""
    from common.conditions import CONDITION_KEYS
    from common.yaml_io import parse_yaml

    key, separator, value = text.partition(":")
    if not separator or key not in CONDITION_KEYS:
        hint = did_you_mean(key, CONDITION_KEYS) if separator else ""
        raise argparse.ArgumentTypeError(f"expected KEY:VALUE with KEY one of {', '.join(CONDITION_KEYS)}, "
                                         f"got {text!r}{hint}")
    try:
        return key, parse_yaml(value)
    except ConfigError:
        raise argparse.ArgumentTypeError(f"{key}: {value!r} is not a YAML value") from None


def _metres(text: str) -> float:
    """An argparse type: a goal radius, a finite number of metres in (0, 1000]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of metres, got {text!r}") from None
    if not (math.isfinite(value) and 0.0 < value <= 1000.0):
        raise argparse.ArgumentTypeError(f"must be more than 0 and at most 1000 m, got {text}")
    return value


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (no usage dump), exit code 2 like every bad input."""

    commands: dict[str, argparse.ArgumentParser] = {}  # the subcommands' parsers, by name

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"error: {self.prog}: {message} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):
        # argparse reports a subcommand's unknown flags from the top: pointed at `curriculum --help`.
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            command = self.commands.get(getattr(parsed, "command", None), self)
            command.error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="curriculum", description="Differential-drive navigation curricula, 2D to 3D.")
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="train a curriculum stage by stage into a run directory")
    run.add_argument("file", metavar="FILE.yaml")
    run.add_argument("--out", metavar="DIR", help="run directory (default runs/NAME)")
    run.add_argument("--resume", action="store_true", help="continue a run from its last checkpoint")
    run.add_argument("--device", choices=["auto", "cpu", "cuda", "mps"], help="overrides the curriculum's device")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.set_defaults(handler=_run)

    sweep = commands.add_parser("sweep", help="a curriculum over seeds, or a search, as Ray Tune trials (local or a cluster)")
    sweep.add_argument("file", metavar="FILE.yaml")
    sweep.add_argument("--seeds", type=whole_number(1, 1000), help="runs with seeds SEED + 1000·k (default 1)")
    sweep.add_argument("--space", metavar="SPACE.yaml", help="a search space: dotted curriculum paths -> distributions")
    sweep.add_argument("--trials", type=whole_number(1, 10_000), help="trials of a search (default 8)")
    sweep.add_argument("--metric", choices=["success_rate", "spl"], help="what a search maximises (default success_rate)")
    sweep.add_argument("--address", metavar="HOST:PORT", help="an existing Ray cluster (default: a local one, in-process)")
    sweep.add_argument("--cpus-per-trial", type=float, default=1.0, metavar="K", help="CPUs each trial holds (default 1)")
    sweep.add_argument("--max-failures", type=whole_number(0, 100), default=2, metavar="F",
                       help="retries of a trial whose process dies (default 2)")
    sweep.add_argument("--out", metavar="DIR", help="sweep directory (default runs/sweeps/NAME)")
    sweep.add_argument("--resume", action="store_true", help="continue an interrupted sweep")
    sweep.add_argument("--device", choices=["auto", "cpu", "cuda", "mps"], help="overrides the curriculum's device")
    sweep.set_defaults(handler=_sweep)

    evaluate = commands.add_parser("eval", help="evaluate trained policies on a suite or a scenario file")
    evaluate.add_argument("--policy", nargs="+", required=True, metavar="ZIP|ONNX")
    _add_scenario_source(evaluate, episodes=100)
    evaluate.add_argument("--json", action="store_true",
                          help="print one JSON object per policy: success_rate, collision_rate, timeout_rate, stuck_rate, "
                               "spl, mean_steps, mean_path_length, episodes, success_ci95 (and social, among movers)")
    _add_jobs(evaluate)
    evaluate.set_defaults(handler=_eval)

    validate = commands.add_parser("validate", help="check curriculum, scenario or IR-SIM world YAML files")
    validate.add_argument("files", nargs="+", metavar="FILE")
    validate.set_defaults(handler=_validate)

    bench = commands.add_parser("bench", help="measure simulator speed against references in the same run")
    bench.add_argument("--json", action="store_true", help="print one JSON object")
    bench.add_argument("--steps", type=whole_number(100, 10_000_000),
                       help="steps to time, at least 100: flatland's (default 20,000; IR-SIM runs a tenth), or "
                            "the GUI's with --gui (default 300)")
    bench.add_argument("--gui", action="store_true",
                       help="instead: the PyBullet GUI's speed against real time (needs a display; xvfb-run works)")
    bench.set_defaults(handler=_bench)

    compare = commands.add_parser("compare", help="run agents on the same scenarios; Markdown, CSV, PNG and JSON")
    _add_scenario_source(compare, episodes=20)
    compare.add_argument("--controllers", metavar="A,B,...", help="controllers to compare (default: all)")
    compare.add_argument("--policy", nargs="*", metavar="ZIP|ONNX", help="trained policies to add as rows")
    compare.add_argument("--out", metavar="DIR", help="output directory (default runs/compare/WORLD-SOURCE)")
    compare.add_argument("--gif", metavar="DIR", help="also record each agent's first episode as DIR/AGENT.gif")
    compare.add_argument("--json", action="store_true", help="print {agent: {success_rate, ...}} as JSON")
    _add_jobs(compare)
    compare.set_defaults(handler=_compare)

    render = commands.add_parser("render", help="record one episode of an agent as a GIF (and an odometry-drift plot)")
    _add_scenario_source(render, episodes=None)
    render.add_argument("--index", type=whole_number(0, 1_000_000), default=0,
                        help="which scenario of the suite or file draw (default 0)")
    render.add_argument("--agent", default="pid_blend",
                        help="a controller name, a policy zip or an exported .onnx (default pid_blend)")
    render.add_argument("--out", default="episode.gif", help="the GIF to write (default episode.gif)")
    render.add_argument("--every", type=whole_number(1, 1000), default=1, help="keep every k-th frame (default 1)")
    render.add_argument("--drift", metavar="PNG", help="also plot the true path against wheel odometry")
    render.set_defaults(handler=_render)

    export = commands.add_parser("export", help="write a policy's actor as an ONNX file (run with onnxruntime, no torch)")
    export.add_argument("policy", metavar="POLICY.zip")
    export.add_argument("--onnx", required=True, metavar="OUT.onnx", help="the file to write")
    export.set_defaults(handler=_export)
    parser.commands = commands.choices
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; bad input prints one line to stderr and exits with code 2."""
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except (ConfigError, OSError) as error:
        print(_error_line(_attributed(error, args)), file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # Ctrl-C: a stop the user asked for, not a crash to show a traceback of
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


# Refusals of a world's own robot and map, raised where the world is built or driven, which knows
# no file: a controller refusing its kinematics, movers the motion code cannot model.
_WORLD_REFUSALS = ("robot.kinematics", "robot.shape", "grid_map")


def _attributed(error: ConfigError | OSError, args: argparse.Namespace) -> ConfigError | OSError:
    """A refusal of the --scenario-file world's own robot or map, named with the file as validation
    names it; not when --env-kwargs put in another robot (the refusal may be of that one)."""
    scenario_file = getattr(args, "scenario_file", None)
    if not isinstance(error, ConfigError) or error.source is not None or not scenario_file:
        return error
    replaced = "robot" in dict(getattr(args, "env_kwargs", None) or [])
    if error.field not in _WORLD_REFUSALS or (replaced and error.field.startswith("robot")):
        return error
    return error.with_source(scenario_file)


def _error_line(error: ConfigError | OSError) -> str:
    """Bad input as one line. An OSError is the file system refusing (a file where a directory
    should be, no permission, a full disk): the user's to fix; a run stopped so is resumable
    from its last checkpoint."""
    if isinstance(error, ConfigError):
        return f"error: {error}"
    where = f"{error.filename}: " if error.filename else ""
    return f"error: {where}{error.strerror or error}"


if __name__ == "__main__":
    sys.exit(main())
