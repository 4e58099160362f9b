"""Speed benchmarks: each figure is measured in the same run as the reference it is compared to.

``curriculum bench`` prints them; ``curriculum bench --json`` prints one JSON object whose keys
later milestones extend (planner timings, the 3D tier).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np
import yaml

from common.actions import ActionMapping
from common.irsim_package import import_irsim
from common.curriculum.stdout import stdout_to_stderr
from common.errors import ConfigError
from common.generators import SUITES
from common.occupancy import OccupancyGrid, scenario_grid
from common.planners import RRT, AStar, Planner, path_length
from common.scenario import RobotProfile, Scenario


# What the code costs, not what other work on the machine takes from it: every single-process
# figure is timed on this process's CPU time. On an idle machine it equals the wall clock
# (flatland, IR-SIM and PyBullet each measured at CPU/wall 1.00: one thread each); beside a
# second job it stops counting the time the job held the core. The GUI's pace is real time and
# PPO's subprocess envs spend theirs in other processes: those keys keep the wall clock.
cpu_seconds = time.process_time


def bench_scenario() -> Scenario:
    """The benchmark world: the first ``warehouse`` suite scenario (31 obstacles, 36-beam 360° 5 m lidar)."""
    return next(SUITES["warehouse"].scenarios(count=1))


def flatland_steps_per_s(world: Scenario | str | Path, steps: int = 20_000, seed: int = 0) -> float:
    """Steps per second of ``gymnasium.make("flatland/Nav-v0", world=world)`` (lidar43) under random
    actions, resetting whenever an episode ends (random driving crashes often, so resets are part of
    it; with a generator kind as ``world`` every reset draws a new scenario)."""
    return _steps_per_s("flatland", world, steps, seed)


def physics3d_steps_per_s(scenario: Scenario, steps: int = 2_000, seed: int = 0) -> float:
    """Steps per second of ``gymnasium.make("physics3d/WarehouseNav-v0")`` (lidar43, headless, default
    control period) under random actions, resetting whenever an episode ends."""
    return _steps_per_s("physics3d", scenario, steps, seed)


def _steps_per_s(tier: str, world: Scenario | str | Path, steps: int, seed: int) -> float:
    with _env_drive(tier, world, steps, seed) as drive:
        start = cpu_seconds()
        drive(range(steps))
        return steps / (cpu_seconds() - start)


_ENV_IDS = {"flatland": "flatland/Nav-v0", "physics3d": "physics3d/WarehouseNav-v0"}


@contextlib.contextmanager
def _env_drive(tier: str, world: Scenario | str | Path, steps: int, seed: int = 0,
               warmed: Callable[[Any], None] | None = None) -> Iterator[Callable[[range], Any]]:
    """A tier's env on ``world`` (lidar43, headless), warmed up and reset with ``seed``: a function
    that drives it through steps k of ``steps`` random actions, resetting as episodes end.
    ``warmed`` is called with the env after the warm-up, before that reset."""
    import gymnasium as gym

    importlib.import_module(tier)  # registers the env
    env = gym.make(_ENV_IDS[tier], world=world if isinstance(world, Scenario) else str(world), observation="lidar43")
    try:
        actions = _random_actions(steps, seed)
        env.reset(seed=seed)
        _drive(env, actions, range(min(200, steps)))  # warm-up: numba kernels compiled or loaded from cache
        if warmed is not None:
            warmed(env)
        env.reset(seed=seed)
        yield lambda indices: _drive(env, actions, indices)
    finally:
        env.close()


def _random_actions(steps: int, seed: int) -> np.ndarray:
    """The benchmarks' random drive: ``steps`` actions uniform in [-1, 1]², float32 as a policy's."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (steps, 2)).astype(np.float32)


def _drive(env, actions: np.ndarray, steps: Iterable[int]) -> set[int]:
    """Step ``env`` through ``actions[k]`` for each k of ``steps``, resetting as episodes end; the
    steps after which it reset."""
    resets = set()
    for k in steps:
        _, _, terminated, truncated, _ = env.step(actions[k])
        if terminated or truncated:
            env.reset()
            resets.add(k)
    return resets


def _timed_random_drive(env, actions: np.ndarray, seed: int, clock: Callable[[], float] = cpu_seconds) -> float:
    """Seconds (of ``clock``) to step ``env`` through ``actions`` from ``reset(seed)``, resetting as episodes end."""
    env.reset(seed=seed)
    start = clock()
    _drive(env, actions, range(len(actions)))
    return clock() - start


@contextlib.contextmanager
def _irsim_drive(world: Scenario | Path, robot: RobotProfile | None, steps: int,
                 seed: int = 0) -> Iterator[Callable[[range], Any] | None]:
    """IR-SIM headless on the same world (a scenario, exported, or an IR-SIM world file; the same
    lidar), warmed up and reset: a function that drives it through steps k of ``steps`` random
    actions mapped to the velocities flatland's env gets, resetting on collision or arrival as
    the env does; None without IR-SIM."""
    irsim = import_irsim()
    if irsim is None:
        yield None
        return
    from common.irsim_export import passing, scenario_to_irsim

    mapping = ActionMapping(robot or world.robot)  # the env's default mapping: the same commands flatland gets
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, (steps, 2))
    commands = np.array([mapping.to_velocity(action) for action in actions])
    with tempfile.TemporaryDirectory() as tmp:
        path = world
        if isinstance(world, Scenario):
            path = Path(tmp) / "bench_world.yaml"
            # IR-SIM's people walk through walls where flatland's slide along them: in the moving
            # bench world's hall the two differ only once the robot has pushed someone that far.
            path.write_text(yaml.safe_dump(scenario_to_irsim(passing(world)), sort_keys=False))
        env = irsim.make(str(path), headless=True, log_level="ERROR", seed=seed)
        try:
            for command in commands[:50]:
                env.step(command.reshape(2, 1))
            env.reset()

            def drive(indices: range) -> None:
                for k in indices:
                    env.step(commands[k].reshape(2, 1))
                    env.get_lidar_scan()
                    if env.robot.collision_flag or env.robot.arrive_flag:
                        env.reset()

            yield drive
        finally:
            env.end(0)


def steps_per_s_taking_turns(drives: Sequence[Callable[[range], Any]], steps: Sequence[int],
                             rounds: int) -> list[float]:
    """Steps per second (CPU time) of each of ``drives`` through its ``steps`` steps, split into
    ``rounds`` turns taken one after another. Measured as separate runs of a few seconds, one side
    of a ratio strayed by a third on this noisy machine (`movers_vs_static` read 0.70 once, 0.42 to
    0.49 otherwise, 2026-11-27); taking turns, a slow minute falls on every side alike."""
    turns = [iter([range(n * r // rounds, n * (r + 1) // rounds) for r in range(rounds)]) for n in steps]
    spent = _cpu_seconds_taking_turns([lambda drive=drive, pending=pending: drive(next(pending))
                                       for drive, pending in zip(drives, turns)], rounds)
    return [n / seconds for n, seconds in zip(steps, spent)]


def flatland_and_irsim_steps_per_s(worlds: Sequence[Scenario | Path], steps: int, irsim_steps: int,
                                   robot: RobotProfile | None = None,
                                   rounds: int = 20) -> tuple[list[float], float | None]:
    """Flatland's steps per second on each of ``worlds`` (as :func:`flatland_steps_per_s`) and
    IR-SIM's on the first of them (``robot``: its robot, for a world file), all taking turns;
    IR-SIM's None without it."""
    with contextlib.ExitStack() as stack:
        drives = [stack.enter_context(_env_drive("flatland", world, steps)) for world in worlds]
        irsim = stack.enter_context(_irsim_drive(worlds[0], robot, irsim_steps))
        counts = [steps] * len(worlds)
        if irsim is not None:
            drives.append(irsim)
            counts.append(irsim_steps)
        rates = steps_per_s_taking_turns(drives, counts, rounds)
    return rates[:len(worlds)], (rates[-1] if irsim is not None else None)


CIRCLE_WORLD = {
    "world": {"width": 10, "height": 10, "step_time": 0.1},
    "robot": {"kinematics": {"name": "diff"}, "shape": {"name": "circle", "radius": 0.2}, "state": [1, 1, 0],
              "goal": [9, 9, 0], "vel_min": [0, -1], "vel_max": [1, 1],
              "sensors": [{"name": "lidar2d", "range_max": 5, "angle_range": 6.283185307179586, "number": 36}]},
    "obstacle": [{"number": 31, "distribution": {"name": "random", "range_low": [2, 2, 0], "range_high": [8, 8, 0],
                                                 "min_distance": 0.6},
                  "shape": {"name": "circle", "radius": 0.2}}],
}
"""IR-SIM's typical world: 31 random circles of 0.2 m and a 36-beam 360° lidar (as its examples)."""


GRID_WORLD = {
    "world": {"width": 20, "height": 20, "step_time": 0.1,
              "obstacle_map": {"name": "perlin", "resolution": 0.1, "complexity": 0.12, "fill": 0.32, "fractal": 1,
                               "attenuation": 0.5, "seed": 48}},
    "robot": {**CIRCLE_WORLD["robot"], "shape": {"name": "circle", "radius": 0.1}, "state": [5.3, 5.5, 0],
              "goal": [15.5, 17.9, 0]},
}
"""IR-SIM's Perlin grid-map example (``10grid_map/grid_map_perlin.yaml``: 200 x 200 cells of 0.1 m),
with the circle world's robot limits and lidar."""


def irsim_grid_world_figures(steps: int) -> dict[str, Any]:
    """Flatland against IR-SIM on IR-SIM's Perlin grid map (IR-SIM's generator builds it for both:
    without IR-SIM there is no figure)."""
    if import_irsim() is None:
        return {"grid_flatland_steps_per_s": None, "grid_irsim_steps_per_s": None, "grid_flatland_vs_irsim": None}
    return _irsim_file_figures("grid", GRID_WORLD, steps)


def irsim_circle_world_figures(steps: int) -> dict[str, Any]:
    """Flatland against IR-SIM on an IR-SIM world file of circles, both resetting as episodes end."""
    return _irsim_file_figures("circles", CIRCLE_WORLD, steps)


def _irsim_file_figures(key: str, data: dict, steps: int) -> dict[str, Any]:
    """Flatland's and IR-SIM's steps per second on the IR-SIM world file ``data``, the two taking
    turns (:func:`flatland_and_irsim_steps_per_s`), and their ratio."""
    from common.world_file import WorldFile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{key}.yaml"
        path.write_text(yaml.safe_dump(data))
        (flat,), theirs = flatland_and_irsim_steps_per_s([path], steps, max(500, steps // 10),
                                                         WorldFile(path).initial.robot)
    return {f"{key}_flatland_steps_per_s": round(flat, 1),
            f"{key}_irsim_steps_per_s": None if theirs is None else round(theirs, 1),
            f"{key}_flatland_vs_irsim": None if theirs is None else round(flat / theirs, 1)}


MAIN_JOB = Path(__file__).resolve().parents[2] / "curricula" / "stage1_2d.yaml"
"""The main job's curriculum, whose PPO stage the ``ppo_*`` keys train."""


@contextlib.contextmanager
def _main_job_ppo(kind: str, seed: int = 0, vec_env: str = "dummy"):
    """PPO as the runner trains :data:`MAIN_JOB`'s stage (its envs, with their observation,
    reward and conditions, and its hyperparameters, read from the file; one torch thread), on the
    generator kind ``kind`` instead of the stage's worlds, after a warm-up rollout (which also
    compiles numba kernels); torch's settings restored afterwards."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger

    from common.curriculum.hyperparams import resolve_hyperparams
    from common.curriculum.policy import NavActorCriticPolicy, vec_env_class
    from common.curriculum.runner import stage_env_kwargs
    from common.curriculum.schema import load_curriculum
    from flatland.env import NavEnv

    (stage,) = load_curriculum(MAIN_JOB).stages
    threads, checks = torch.get_num_threads(), torch.distributions.Distribution._validate_args
    torch.set_num_threads(1)
    env = make_vec_env(NavEnv, n_envs=stage.n_envs, seed=seed, vec_env_cls=vec_env_class(vec_env),
                       env_kwargs={**stage_env_kwargs(stage), "world": kind})
    try:
        model = PPO(NavActorCriticPolicy, env, seed=seed, device="cpu", **resolve_hyperparams(stage.hyperparams))
        model.set_logger(Logger(folder=None, output_formats=[]))  # else SB3 leaves an empty /tmp/SB3-* folder
        _train_as(model, stock=False)
        model.learn(2048)
        yield model
    finally:
        env.close()  # a subproc env's worker processes end here, even if training failed
        torch.set_num_threads(threads)
        torch.distributions.Distribution.set_default_validate_args(checks)


def _train_as(model, stock: bool) -> None:
    """Train ``model`` from now on as the runner does, or (``stock``) as stable-baselines3 and torch
    do by default: module calls, distribution argument checks, Adam's loop over tensors. The same
    arithmetic either way."""
    import torch

    from common.curriculum.policy import use_optimizer_kernels

    torch.distributions.Distribution.set_default_validate_args(stock)
    model.policy.direct_layer_calls = not stock
    use_optimizer_kernels(model, None if stock else "foreach")


def ppo_steps_per_s(kind: str, steps: int = 16_384, seed: int = 0, vec_env: str = "dummy") -> float:
    """PPO's training throughput (env steps per wall-clock second, learner included) with the main
    job's settings as the runner trains it (:func:`_main_job_ppo`). ``vec_env``: ``dummy`` (one
    process) or ``subproc`` (one process per env, whose work the wall clock sees), as a stage's
    ``vec_env``."""
    with _main_job_ppo(kind, seed, vec_env) as model:
        start = time.perf_counter()
        model.learn(steps, reset_num_timesteps=False)
        return steps / (time.perf_counter() - start)


def _cpu_seconds_taking_turns(turns: Sequence[Callable[[], None]], rounds: int) -> list[float]:
    """CPU seconds each of ``turns`` took, called one after another ``rounds`` times, so a noisy
    machine's swings fall on every turn alike."""
    spent = [0.0] * len(turns)
    for _ in range(rounds):
        for i, turn in enumerate(turns):
            start = cpu_seconds()
            turn()
            spent[i] += cpu_seconds() - start
    return spent


def _rollout(model, stock: bool | None = None) -> None:
    """One rollout of 2,048 steps and its update (trained the stock way or the runner's, if given)."""
    if stock is not None:
        _train_as(model, stock)
    model.learn(2048, reset_num_timesteps=False)


def ppo_runner_and_stock_steps_per_s(kind: str = "sparse", rollouts: int = 30, seed: int = 0) -> tuple[float, float]:
    """Env steps per CPU second of the main job's PPO trained as the runner trains it and as
    stable-baselines3 and torch do by default (:func:`_train_as`), the two taking turns rollout by
    rollout in one model: the same arithmetic, so one trajectory. Separate runs of a few seconds
    each read ratios from 0.93 to 1.29 within two hours for a difference of a few percent."""
    with _main_job_ppo(kind, seed) as model:
        runner, stock = _cpu_seconds_taking_turns([lambda: _rollout(model, False), lambda: _rollout(model, True)],
                                                  rollouts)
    return rollouts * 2048 / runner, rollouts * 2048 / stock


def ppo_kinds_steps_per_s(kinds: Sequence[str] = ("sparse", "cluttered"), rollouts: int = 30,
                          seed: int = 0) -> dict[str, tuple[float, float]]:
    """For each generator kind, env steps per CPU second of the main job's PPO as the runner trains
    it (:func:`_main_job_ppo`, one process) and the share of that time spent collecting rollouts
    (the envs and the policy's forward passes) rather than in gradient updates: one model per
    kind, the models taking turns rollout by rollout."""
    spent = {kind: {"collect_rollouts": 0.0, "train": 0.0} for kind in kinds}
    with contextlib.ExitStack() as stack:
        models = {kind: stack.enter_context(_main_job_ppo(kind, seed)) for kind in kinds}
        for kind, model in models.items():
            for name in spent[kind]:
                setattr(model, name, _timed(getattr(model, name), spent[kind], name))
        total = _cpu_seconds_taking_turns([lambda model=model: _rollout(model) for model in models.values()], rollouts)
    return {kind: (rollouts * 2048 / seconds, spent[kind]["collect_rollouts"] / sum(spent[kind].values()))
            for kind, seconds in zip(kinds, total)}


def planner_pairs(scenario: Scenario, grid: OccupancyGrid, count: int = 20, seed: int = 0,
                  min_distance: float = 2.0) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The scenario's start and goal, then free-cell centre pairs of the start's free component
    at least ``min_distance`` apart (one component, so every pair has a path)."""
    rows, cols = np.nonzero(grid.free_component(*scenario.start[:2]))
    centres = np.column_stack([grid.origin[0] + (cols + 0.5) * grid.resolution,
                               grid.origin[1] + (rows + 0.5) * grid.resolution])
    rng = np.random.default_rng(seed)
    pairs = [(tuple(scenario.start[:2]), tuple(scenario.goal))]
    while len(pairs) < count:
        a, b = centres[rng.integers(len(centres), size=2)]
        if np.hypot(*(a - b)) >= min_distance:
            pairs.append((tuple(a), tuple(b)))
    return pairs


def _time_planner(planner: Planner, grid: OccupancyGrid, pairs: list, repeats: int) -> tuple[float, float | None]:
    """Median plan time (ms) over every pair and repeat, and mean length (m) of the paths found."""
    planner.plan(grid, *pairs[0])  # warm-up: numba kernels compiled or loaded from cache
    times, lengths = [], []
    for start, goal in pairs:
        for _ in range(repeats):
            tic = cpu_seconds()
            path = planner.plan(grid, start, goal)
            times.append(cpu_seconds() - tic)
            if path is not None:
                lengths.append(path_length(path))
    return 1e3 * float(np.median(times)), float(np.mean(lengths)) if lengths else None


def planner_figures(scenario: Scenario, resolution: float = 0.2, count: int = 20, repeats: int = 5,
                    seed: int = 0) -> dict[str, float | None]:
    """A* and RRT on the scenario's ground-truth grid over ``count`` start/goal pairs, each planned
    ``repeats`` times (RRT drawing fresh samples each time): median ms and mean path length."""
    grid = scenario_grid(scenario, resolution)
    pairs = planner_pairs(scenario, grid, count, seed)
    astar_ms, astar_m = _time_planner(AStar(), grid, pairs, repeats)
    rrt_ms, rrt_m = _time_planner(RRT(seed=seed), grid, pairs, repeats)
    metres = lambda value: None if value is None else round(value, 2)
    return {"astar_ms": round(astar_ms, 4), "rrt_ms": round(rrt_ms, 4),
            "astar_path_m": metres(astar_m), "rrt_path_m": metres(rrt_m)}


def physics3d_bench_scenario() -> Scenario:
    """The 3D benchmark world: the first ``warehouse`` suite scenario drawn around the 3D robot's template."""
    from physics3d.robot import TEMPLATE

    return next(SUITES["warehouse"].scenarios(count=1, template=TEMPLATE))


def gui_figures(steps: int = 300, seed: int = 0) -> dict[str, float]:
    """The PyBullet GUI (``render_mode="human"``, its previews and debug drawing on) under random
    actions: steps per second against real time (one control period per step, which the GUI
    paces to), so ``gui_vs_real_time`` 1.0 means it keeps real time; then the same among 10
    walking people (``gui_movers_vs_real_time``). Needs an X display."""
    if not os.environ.get("DISPLAY"):
        raise ConfigError(None, "--gui", "needs an X display (DISPLAY is not set); run it as: xvfb-run -a curriculum bench --gui")
    import gymnasium as gym

    import physics3d  # noqa: F401  (registers the env)

    from physics3d.robot import TEMPLATE

    figures: dict[str, float] = {}
    worlds = (("gui", physics3d_bench_scenario()), ("gui_movers", moving_bench_scenario(people=10, template=TEMPLATE)))
    actions = _random_actions(steps, seed)
    with stdout_to_stderr():
        for name, world in worlds:  # one GUI window a process: one env at a time
            env = gym.make("physics3d/WarehouseNav-v0", world=world, observation="lidar43", render_mode="human")
            elapsed = _timed_random_drive(env, actions, seed, time.perf_counter)
            real_time = 1.0 / env.unwrapped.world.period
            env.close()
            figures[f"{name}_steps_per_s"] = round(steps / elapsed, 2)
            figures[f"{name}_vs_real_time"] = round(steps / elapsed / real_time, 3)
    return {"gui_real_time_steps_per_s": real_time, **figures}


def physics3d_and_bare(scenario: Scenario, steps: int, chunk: int = 100, seed: int = 0) -> tuple[float, float]:
    """The 3D env's steps per second under random actions (as :func:`physics3d_steps_per_s`) and
    a bare PyBullet loop's on the same episodes, the two taking turns ``chunk`` steps at a time,
    each timed by CPU: in separate runs of a few seconds one side strayed by a quarter on this
    noisy machine; taking turns, a slow minute falls on both alike.

    The bare loop is the same physics with no env around it. Per step: the wheel targets the env
    drove its robot at (the actions through its limits, delay and motor gain), the world's
    sub-steps and one ``rayTestBatch`` of the lidar's beams. After each step where the env reset:
    the start restored, with the friction and mass the env drew for the episode. So the bare
    robot drives the env's episodes to the bit, contacts and all; a ``RuntimeError`` says if it
    did not."""
    import pybullet as p

    from physics3d.robot import yaw_of
    from physics3d.world import World

    calls: list[tuple[str, tuple[float, ...]]] = []  # what the env did to its robot's dynamics, in order
    envs: list[Any] = []
    resets: set[int] = set()  # the steps after which the env reset, for the bare loop to replay

    def record(env: Any) -> None:
        envs.append(env)
        _log_dynamics(env.unwrapped.world.robot, calls)

    with _env_drive("physics3d", scenario, steps, seed, warmed=record) as drive, \
            contextlib.closing(World(scenario, seed=seed)) as world:
        # Two PyBullet clients are open at once: neither outlives a failure.
        client, robot, substeps, rays = world.client, world.robot, world.substeps, world.lidar.rays
        replayed = 0

        def replay_to_drive() -> None:
            """Apply the env's calls to the bare robot up to and including its next wheel targets."""
            nonlocal replayed
            while True:
                name, args = calls[replayed]
                replayed += 1
                getattr(robot, name)(*args)
                if name == "drive":
                    return

        def bare(indices: range) -> None:
            for k in indices:
                replay_to_drive()
                for _ in range(substeps):
                    p.stepSimulation(physicsClientId=client)
                (x, y, z), orientation = p.getBasePositionAndOrientation(robot.id, physicsClientId=client)
                p.rayTestBatch(*rays(x, y, z, yaw_of(orientation)), physicsClientId=client)
                if k in resets:
                    world.reset()
                    replay_to_drive()

        replay_to_drive()  # the env's first episode: its draws and its robot at rest
        # Each round the env drives a chunk, then the bare loop replays it.
        env_rate, bare_rate = steps_per_s_taking_turns([lambda indices: resets.update(drive(indices)), bare],
                                                       [steps, steps], rounds=-(-steps // chunk))
        if world.pose() != envs[0].unwrapped.world.pose():
            raise RuntimeError("the bare PyBullet loop ended elsewhere than the env: it drove other episodes")
    return env_rate, bare_rate


def _log_dynamics(robot: Any, calls: list[tuple[str, tuple[float, ...]]]) -> None:
    """Make ``robot`` (a :class:`physics3d.robot.Robot`) append to ``calls`` each call that sets
    its dynamics: its wheel targets, its tyres' friction, its mass."""
    for name in ("drive", "set_friction", "set_mass_scale"):
        def logged(*args: float, name: str = name, method: Callable[..., None] = getattr(robot, name)) -> None:
            calls.append((name, args))
            method(*args)

        setattr(robot, name, logged)


def camera_fps(scenario: Scenario, frames: int = 100) -> float:
    """Frames per second of the robot's 320 × 240 RGB, depth and segmentation camera (headless,
    PyBullet's TinyRenderer), the robot driving between frames."""
    from physics3d.world import World

    world = World(scenario, seed=0, camera=True)
    world.step(0.2, 0.5)
    start = cpu_seconds()
    for _ in range(frames):
        world.camera.from_mount(*world.robot.camera_pose())
    elapsed = cpu_seconds() - start
    world.close()
    return frames / elapsed


def reset_ms(repeats: int = 30) -> dict[str, float]:
    """Median milliseconds to draw a new scenario of each generator kind, and to redraw a random
    IR-SIM world file (31 random circles, as IR-SIM's examples have) from its parse."""
    from common.generators import KINDS, generate
    from common.world_file import WorldFile

    def median_ms(draw) -> float:
        draw(0)  # warm-up: numba kernels compiled or loaded from cache
        times = []
        for seed in range(1, repeats + 1):
            began = cpu_seconds()
            draw(seed)
            times.append(cpu_seconds() - began)
        return round(1000 * float(np.median(times)), 2)

    figures = {f"reset_ms_{kind}": median_ms(lambda seed, kind=kind: generate(kind, seed)) for kind in KINDS}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "random.yaml"
        path.write_text(yaml.safe_dump({
            "world": {"width": 10, "height": 10},
            "robot": {"kinematics": {"name": "diff"}, "state": [1, 1, 0], "goal": [9, 9, 0]},
            "obstacle": [{"number": 31, "distribution": {"name": "random", "range_low": [1.5, 1.5, 0],
                                                         "range_high": [8.5, 8.5, 0]},
                          "shape": {"name": "circle", "radius": 0.2}}]}))
        file = WorldFile(path)
        figures["reset_ms_irsim_random"] = median_ms(file.scenario)
    return figures


def moving_bench_scenario(people: int = 20, speed: float = 1.0, template: Scenario | None = None) -> Scenario:
    """The moving benchmark world: the first eval ``crowd`` of difficulty 1 (20 people under the
    social force, planning as one group, seeing the robot), every person at ``speed`` and walking
    back and forth to its first goal, so that IR-SIM runs the same world (IR-SIM's group shares one
    speed, and each simulator would draw a wanderer's next goals from its own generator); the first
    ``people`` of them, drawn around ``template``'s robot and lidar if given."""
    from common.generators import generate

    crowd = generate("crowd", 0, 1.0, "eval", template, reacting=True, behavior="sfm")
    walkers = [person.model_copy(update={"motion": person.motion.model_copy(update={
        "wander": None, "route": "back_and_forth", "vel_max": (speed, speed),
        "behavior": person.motion.behavior.model_copy(update={"vmax": speed})})}) for person in crowd.movers[:people]]
    return crowd.model_copy(update={"obstacles": [*crowd.static_obstacles, *walkers]})


def frozen(scenario: Scenario) -> Scenario:
    """The same world with every mover standing where it starts."""
    return scenario.model_copy(update={"obstacles": [
        obstacle.model_copy(update={"motion": None}) if getattr(obstacle, "motion", None) is not None else obstacle
        for obstacle in scenario.obstacles]})


def fastest_alternated(measures: dict[str, Callable[[], Any]], runs: int) -> dict[str, Any]:
    """Each measure's largest result over ``runs`` rounds, the measures alternated within a round:
    on this noisy machine one run strayed by a quarter, and alternating spreads a slow minute
    over both sides of a ratio."""
    results: dict[str, list[Any]] = {name: [] for name in measures}
    for _ in range(runs):
        for name, measure in measures.items():
            results[name].append(measure())
    return {name: max(values) for name, values in results.items()}


def movers_figures(steps: int) -> dict[str, Any]:
    """The env among 20 walking people against the same world frozen, and IR-SIM's own steps on
    the same moving world, the three taking turns (:func:`steps_per_s_taking_turns`)."""
    moving = moving_bench_scenario()
    (flat, static), theirs = flatland_and_irsim_steps_per_s([moving, frozen(moving)], steps, max(300, steps // 40),
                                                            rounds=25)
    return {"movers_env_steps_per_s": round(flat, 1), "movers_frozen_env_steps_per_s": round(static, 1),
            "movers_vs_static": round(flat / static, 3),
            "movers_irsim_steps_per_s": None if theirs is None else round(theirs, 1),
            "movers_flatland_vs_irsim": None if theirs is None else round(flat / theirs, 1)}


def movers3d_figures(steps: int) -> dict[str, Any]:
    """The 3D env among 10 walking people against the same world frozen, the two taking turns
    (:func:`steps_per_s_taking_turns`)."""
    from physics3d.robot import TEMPLATE

    moving = moving_bench_scenario(people=10, template=TEMPLATE)
    with _env_drive("physics3d", moving, steps) as among_movers, \
            _env_drive("physics3d", frozen(moving), steps) as among_statues:
        flat, static = steps_per_s_taking_turns([among_movers, among_statues], [steps, steps], rounds=10)
    return {"physics3d_movers_steps_per_s": round(flat, 1), "physics3d_movers_frozen_steps_per_s": round(static, 1),
            "physics3d_movers_vs_static": round(flat / static, 3)}


SHIPPED_POLICIES = Path(__file__).resolve().parents[2] / "curricula" / "policies"


def _calls_per_s(predict: Callable[[np.ndarray], Any], observations: np.ndarray) -> float:
    """Calls per second (CPU time) of ``predict`` over ``observations``, one at a time, after a warm-up call."""
    predict(observations[0])
    began = cpu_seconds()
    for observation in observations:
        predict(observation)
    return len(observations) / (cpu_seconds() - began)


def onnx_figures(calls: int = 20_000, policies: Sequence[str] = ("stage1_2d_ppo", "stage1_2d_sac")) -> dict[str, Any]:
    """Actions per second of a shipped policy exported to ONNX (onnxruntime, one thread), against
    the same policy's torch network (one thread, SB3's ``predict``), one observation per call as a
    robot's loop asks; and of the loaded policy's own deterministic action (the evaluator's:
    :class:`common.curriculum.policy.DeterministicAction`), the same network on the same thread."""
    import torch

    from common.curriculum.onnx_export import export_onnx
    from common.curriculum.onnx_policy import OnnxPolicy
    from common.curriculum.policy import load_policy

    figures: dict[str, Any] = {}
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with tempfile.TemporaryDirectory() as folder:
            for name in policies:
                algorithm = name.rsplit("_", 1)[-1]
                try:
                    agent = load_policy(SHIPPED_POLICIES / f"{name}.zip")
                except ConfigError:  # an installed package without the source tree's shipped policies
                    figures.update({f"{key}_{algorithm}": None for key in (
                        "torch_actions_per_s", "agent_actions_per_s", "agent_vs_torch", "onnx_actions_per_s",
                        "onnx_vs_torch")})
                    continue
                network = agent.model
                observations = np.random.default_rng(0).uniform(-1, 1, (calls, network.observation_space.shape[0]))
                observations = observations.astype(np.float32)
                torch_rate = _calls_per_s(lambda o: network.predict(o, deterministic=True), observations)
                agent_rate = _calls_per_s(agent.predict, observations)
                figures.update({f"torch_actions_per_s_{algorithm}": round(torch_rate, 1),
                                f"agent_actions_per_s_{algorithm}": round(agent_rate, 1),
                                f"agent_vs_torch_{algorithm}": round(agent_rate / torch_rate, 2)})
                try:
                    runtime = OnnxPolicy(export_onnx(SHIPPED_POLICIES / f"{name}.zip", Path(folder) / f"{name}.onnx"))
                except (ConfigError, ImportError):  # no onnxruntime or onnxscript
                    figures.update({f"onnx_actions_per_s_{algorithm}": None, f"onnx_vs_torch_{algorithm}": None})
                    continue
                onnx_rate = _calls_per_s(lambda o: runtime.predict(o, deterministic=True), observations)
                figures.update({f"onnx_actions_per_s_{algorithm}": round(onnx_rate, 1),
                                f"onnx_vs_torch_{algorithm}": round(onnx_rate / torch_rate, 2)})
    finally:
        torch.set_num_threads(threads)
    return figures


def run_benchmarks(steps: int = 20_000) -> dict[str, Any]:
    """All figures of this milestone, as one flat mapping."""
    scenario = bench_scenario()
    (flat,), irsim = flatland_and_irsim_steps_per_s([scenario], steps, max(500, steps // 10))
    scenario3d = physics3d_bench_scenario()
    steps3d = max(500, steps // 5)
    env3d, bare3d = physics3d_and_bare(scenario3d, steps3d)
    return {
        "world": scenario.name,
        "obstacles": len(scenario.obstacles),
        "lidar_beams": scenario.lidar.beams,
        "flatland_steps_per_s": round(flat, 1),
        "irsim_steps_per_s": None if irsim is None else round(irsim, 1),
        "flatland_vs_irsim": None if irsim is None else round(flat / irsim, 1),
        **planner_figures(scenario),
        "physics3d_steps_per_s": round(env3d, 1),
        "bare_pybullet_steps_per_s": round(bare3d, 1),
        "physics3d_vs_bare": round(env3d / bare3d, 3),
        "camera_fps": round(camera_fps(scenario3d), 1),
        **reset_ms(),
        **irsim_circle_world_figures(steps),
        **irsim_grid_world_figures(steps),
        "warehouse_env_steps_per_s": round(flatland_steps_per_s("warehouse", max(500, steps // 4)), 1),
        **movers_figures(max(1000, steps // 4)),
        **movers3d_figures(max(250, steps // 40)),
        **onnx_figures(max(1000, steps)),
        **_ppo_figures(max(2048, steps)),
    }


def _timed(method, spent: dict[str, float], name: str):
    """``method``, adding the CPU seconds each call takes to ``spent[name]``."""
    def wrapper(*args, **kwargs):
        began = cpu_seconds()
        try:
            return method(*args, **kwargs)
        finally:
            spent[name] += cpu_seconds() - began

    return wrapper


def _ppo_figures(steps: int) -> dict[str, float]:
    # Rollout by rollout in one process where the clock is the CPU's; one process per env (whose
    # work is in other processes) against one process by the wall clock, each setting's best of
    # two alternated runs: one round of those few-second runs swung a ratio from 0.96 to 0.80
    # between two benches of the same code on this noisy machine.
    rollouts = max(1, steps // 1024)
    kinds = ppo_kinds_steps_per_s(("sparse", "cluttered"), rollouts)
    (sparse, sparse_share), (cluttered, cluttered_share) = kinds["sparse"], kinds["cluttered"]
    fastest = fastest_alternated({vec_env: lambda vec_env=vec_env: ppo_steps_per_s("cluttered", steps, vec_env=vec_env)
                                  for vec_env in ("dummy", "subproc")}, runs=2)
    dummy, subproc = fastest["dummy"], fastest["subproc"]
    runner, stock = ppo_runner_and_stock_steps_per_s(rollouts=rollouts)
    return {"ppo_steps_per_s_sparse": round(sparse, 1), "ppo_steps_per_s_cluttered": round(cluttered, 1),
            "ppo_cluttered_vs_sparse": round(cluttered / sparse, 3),
            "ppo_steps_per_s_cluttered_subproc": round(subproc, 1), "ppo_subproc_vs_dummy": round(subproc / dummy, 3),
            "ppo_rollout_share_sparse": round(sparse_share, 3), "ppo_rollout_share_cluttered": round(cluttered_share, 3),
            "ppo_stock_steps_per_s_sparse": round(stock, 1), "ppo_vs_stock_sparse": round(runner / stock, 3)}
