"""Evaluate any agent (controller, planner + follower, policy) on scenarios in a tier.

Per episode: outcome (success, collision, timeout, stuck: decided by :class:`common.task.Task`, as
the env decides it), steps, path length, wall time and SPL (Anderson et al. 2018: success x
shortest / max(shortest, taken)); the shortest path is A* on the scenario's ground-truth grid (its
static obstacles), less the goal radius, since an episode ends on entering it. Aggregates carry
mean ± std and 95% Wilson intervals for the rates.

Among movers, the social figures crowd-navigation papers report (CrowdNav, robot_sf): the
smallest gap between the robot's footprint and a person's body over the episode, the seconds
spent within :data:`PERSONAL_SPACE` of one, and a collision's kind (``static`` or ``mover``) and
who moved into whom (``robot`` or ``mover``: who closed in faster; see :class:`common.readings.Contact`).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import multiprocessing
import os
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from typing import Callable, Iterable, Iterator, Protocol, Sequence

import numpy as np
from scipy import stats

from common.conditions import Conditions
from common.geometry import box_distance, box_gap
from common.readings import Readings
from common.route import Route
from common.scenario import LidarSpec, RobotProfile, Scenario
from common.task import DEFAULT_MAX_STEPS, OUTCOMES, Task
from common.tiers import make_world


PERSONAL_SPACE = 0.5  # m between the robot's footprint and a person's body


class Agent(Protocol):
    """What the evaluator drives: the controller interface (policies are wrapped to it).

    ``bind`` tells the agent the robot, its lidar and the radius it must drive into; an agent may
    also carry ``max_steps``, the episode length it expects (a policy's, from its manifest), and
    ``reads_route`` with ``follow(route)``, to be given a route on the static map each episode
    (:func:`start_agent`).
    """

    name: str

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float) -> None: ...

    def reset(self) -> None: ...

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]: ...


@dataclass(frozen=True)
class Episode:
    """One evaluated episode."""

    agent: str
    scenario: str
    seed: int
    outcome: str
    steps: int
    path_length: float
    shortest_path: float
    spl: float
    wall_time: float
    min_person_gap: float | None = None  # m; None: no person in the world
    time_near_people: float = 0.0  # s within PERSONAL_SPACE of a person
    collision_with: str | None = None  # "static" or "mover"
    collision_by: str | None = None  # "robot" or "mover": who moved into whom


class SocialRecord:
    """The social figures of one episode, fed every readings (see the module)."""

    def __init__(self, robot: RobotProfile) -> None:
        self.robot = robot
        self.min_gap: float | None = None
        self.time_near = 0.0
        self._time = 0.0
        self.contact = None

    def __call__(self, readings: Readings) -> None:
        dt, self._time = readings.time - self._time, readings.time
        if readings.contact is not None:
            self.contact = readings.contact
        movers = readings.movers
        if movers is None:
            return
        people = [k for k, label in enumerate(movers.labels) if label == "person"]
        if not people:
            return
        rows = movers.rows[people]
        x, y, yaw = readings.pose
        c, s = math.cos(yaw), math.sin(yaw)
        x, y = x + self.robot.footprint_offset * c, y + self.robot.footprint_offset * s  # the footprint's centre
        robot = self.robot
        if robot.shape == "circle":
            gaps = np.hypot(rows[:, 0] - x, rows[:, 1] - y) - robot.radius - rows[:, 5]
        else:
            gaps = np.array([box_distance(px, py, x, y, robot.length, robot.width, c, s) - r
                             for px, py, r in rows[:, [0, 1, 5]]])
        for k in np.flatnonzero(rows[:, 6] > 0.0):  # a box-shaped person: its box, not the circle round it
            gaps[k] = self._box_gap(x, y, yaw, rows[k])
        nearest = float(gaps.min())
        self.min_gap = nearest if self.min_gap is None else min(self.min_gap, nearest)
        if nearest < PERSONAL_SPACE:
            self.time_near += dt

    def _box_gap(self, x: float, y: float, yaw: float, person: np.ndarray) -> float:
        """The gap between the robot's footprint (centred at x, y) and a box-shaped person's box."""
        px, py, heading, length, width = person[[0, 1, 2, 6, 7]]
        if self.robot.shape == "circle":
            return box_distance(x, y, px, py, length, width, math.cos(heading), math.sin(heading)) - self.robot.radius
        return box_gap((x, y, yaw, self.robot.length, self.robot.width), (px, py, heading, length, width))


def shortest_path_length(scenario: Scenario, goal_radius: float | None = None, resolution: float = 0.1) -> float:
    """Length of the A* path on the ground-truth grid (inflated by the robot's radius), less the goal
    radius (default the scenario's). Where the inflated grid blocks the start or the goal (a
    hand-made file may put either near an obstacle), the straight-line distance stands in: a lower
    bound, so SPL errs low. Otherwise it errs high: the grid path (8-connected, through cell
    centres, for the robot's bounding circle) is longer than the shortest, by up to 8.2% on a long
    open path and more on a short one (docs/cli.md); kept so that the published SPLs stay comparable."""
    from common.occupancy import scenario_grid
    from common.planners.astar import AStar, path_length

    grid = scenario_grid(scenario, resolution)
    path = AStar().plan(grid, scenario.start[:2], scenario.goal)
    length = path_length(path) if path is not None else math.dist(scenario.start[:2], scenario.goal)
    return max(length - (scenario.goal_threshold if goal_radius is None else goal_radius), 0.0)


def start_agent(agent: Agent, scenario: Scenario, goal_radius: float) -> None:
    """Bind ``agent`` to the scenario's robot and sensors and start its episode; an agent that
    reads a route on the static map (a policy observing ``lidar51_route``) is given the route a
    global planner would give it (:mod:`common.route`)."""
    agent.bind(scenario.robot, scenario.lidar, goal_radius)
    agent.reset()
    if getattr(agent, "reads_route", False):
        agent.follow(Route(scenario, goal_radius))


def episode_limit(agent: Agent, max_steps: int | None) -> int:
    """``max_steps`` if given, else the agent's own episode length, else :data:`DEFAULT_MAX_STEPS`."""
    return max_steps if max_steps is not None else getattr(agent, "max_steps", None) or DEFAULT_MAX_STEPS


def run_episode(
    agent: Agent,
    scenario: Scenario,
    tier: str = "flatland",
    seed: int = 0,
    max_steps: int | None = None,
    on_step: Callable[[Readings], None] | None = None,
    shortest: float | None = None,
    conditions: Conditions | None = None,
    goal_radius: float | None = None,
) -> Episode:
    """Drive ``agent`` in a fresh world of ``scenario`` under ``conditions`` (the tier's defaults
    where unset), judged within ``goal_radius`` (default the scenario's); ``on_step`` sees every
    readings (e.g. to render). ``max_steps`` defaults to the agent's own (see :func:`episode_limit`)."""
    task = Task(goal_radius, episode_limit(agent, max_steps), judge_stuck=True)
    world = make_world(tier, scenario, seed=seed, conditions=conditions)
    # A world holding a simulator's resources (a PyBullet client, IR-SIM's figure) lets them go at the end.
    with contextlib.closing(world) if hasattr(world, "close") else contextlib.nullcontext():
        scenario = world.scenario  # as conditioned: the robot the agent drives, its sensors' noise
        readings = world.reset(seed=seed)
        task.start(scenario, readings)
        start_agent(agent, scenario, task.radius)
        social = SocialRecord(scenario.robot)
        social(readings)
        if on_step:
            on_step(readings)
        outcome = None
        start = time.perf_counter()
        while outcome is None:
            v, w = agent.act(readings, scenario.goal)
            readings = world.step(v, w)
            social(readings)
            if on_step:
                on_step(readings)
            outcome = task.step(readings)
        wall = time.perf_counter() - start
    shortest = shortest_path_length(scenario, task.radius) if shortest is None else shortest
    travelled = task.travelled
    spl = shortest / max(shortest, travelled) if outcome == "success" and shortest > 0 else float(outcome == "success")
    crash = social.contact if outcome == "collision" else None
    return Episode(agent.name, scenario.name, seed, outcome, task.steps, travelled, shortest, spl, wall,
                   social.min_gap, round(social.time_near, 6), crash.kind if crash else None, crash.by if crash else None)


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a binomial rate (sound near 0 and 1, unlike the normal one)."""
    if n == 0:
        return (math.nan, math.nan)
    z = stats.norm.ppf(0.5 + confidence / 2)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    # At 0 or n successes the bound is exactly 0 or 1; the arithmetic leaves a rounding residue (5.6e-17).
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return (low, high)


@dataclass
class Summary:
    """Aggregates of one agent's episodes. Steps and path length are over successful episodes."""

    agent: str
    episodes: int
    success_rate: float
    collision_rate: float
    timeout_rate: float
    stuck_rate: float
    success_ci95: tuple[float, float]
    spl: float
    spl_std: float
    mean_steps: float | None
    std_steps: float | None
    mean_path_length: float | None
    std_path_length: float | None
    mean_wall_time: float
    rows: list[Episode] = field(default_factory=list, repr=False)
    social: dict | None = None  # the social figures, where the world has movers (see social_figures)

    def arrivals(self) -> list[bool]:
        """Whether each episode arrived, in episode order (for comparisons pair by pair)."""
        return [e.outcome == "success" for e in self.rows]

    def to_json(self) -> dict:
        """The agreed JSON object (plus stuck rate and the interval; and the social figures, among movers)."""
        keys = ("success_rate", "collision_rate", "timeout_rate", "stuck_rate", "spl", "mean_steps",
                "mean_path_length", "episodes", "success_ci95")
        out = {key: getattr(self, key) for key in keys}
        out["success_ci95"] = list(self.success_ci95)
        if self.social is not None:
            out["social"] = self.social
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}


def social_figures(episodes: Sequence[Episode]) -> dict | None:
    """Collisions by kind (static, mover) and by who moved into whom, as shares of all episodes;
    the mean and the smallest of the episodes' closest gaps to a person, and the mean seconds spent
    within PERSONAL_SPACE of one; None if no episode met a person or a mover."""
    crashes = [e for e in episodes if e.collision_with is not None]
    gaps = [e.min_person_gap for e in episodes if e.min_person_gap is not None]
    if not gaps and not any(e.collision_with == "mover" for e in crashes) and not any(
            e.time_near_people for e in episodes):
        return None
    n = len(episodes)
    return {
        "collision_static_rate": sum(e.collision_with == "static" for e in crashes) / n,
        "collision_mover_rate": sum(e.collision_with == "mover" for e in crashes) / n,
        "collision_robot_into_mover_rate": sum(e.collision_with == "mover" and e.collision_by == "robot" for e in crashes) / n,
        "collision_mover_into_robot_rate": sum(e.collision_with == "mover" and e.collision_by == "mover" for e in crashes) / n,
        "mean_min_person_gap": float(np.mean(gaps)) if gaps else None,
        "min_person_gap": float(np.min(gaps)) if gaps else None,
        "mean_time_near_people": float(np.mean([e.time_near_people for e in episodes])),
    }


def _mean_std(values: Sequence[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    return float(np.mean(values)), float(np.std(values))


def summarise(agent: str, episodes: Sequence[Episode]) -> Summary:
    """Aggregate episodes of one agent."""
    n = len(episodes)
    count = {o: sum(e.outcome == o for e in episodes) for o in OUTCOMES}
    wins = [e for e in episodes if e.outcome == "success"]
    spl = [e.spl for e in episodes]
    steps = _mean_std([e.steps for e in wins])
    length = _mean_std([e.path_length for e in wins])
    return Summary(
        agent=agent, episodes=n,
        success_rate=count["success"] / n, collision_rate=count["collision"] / n,
        timeout_rate=count["timeout"] / n, stuck_rate=count["stuck"] / n,
        success_ci95=wilson_interval(count["success"], n),
        spl=float(np.mean(spl)), spl_std=float(np.std(spl)),
        mean_steps=steps[0], std_steps=steps[1], mean_path_length=length[0], std_path_length=length[1],
        mean_wall_time=float(np.mean([e.wall_time for e in episodes])), rows=list(episodes),
        social=social_figures(episodes),
    )


EVALUATION_BLOCK = 1000
"""Scenarios :func:`evaluate` holds at a time (in each worker process, at most this many): a
scenario holds tens of kB, so a million-episode evaluation held at once would need tens of GB
before its first episode."""


class ScenarioSource(Protocol):
    """Scenarios drawn on demand: how many, all of them in order, and those from ``start`` to
    ``stop`` (exclusive), each the same whenever drawn. A source that pickles lets worker
    processes draw their own."""

    def __len__(self) -> int: ...

    def __iter__(self) -> Iterator[Scenario]: ...

    def part(self, start: int, stop: int) -> Iterable[Scenario]: ...


def evaluate(
    agents: Sequence[Agent],
    scenarios: Iterable[Scenario] | ScenarioSource,
    tier: str = "flatland",
    seed: int = 0,
    max_steps: int | None = None,
    progress: Callable[[int], None] | None = None,
    conditions: Conditions | None = None,
    goal_radius: float | None = None,
    jobs: int = 1,
) -> list[Summary]:
    """Every agent on the same scenarios with the same seeds (episode i uses ``seed + i``) under the
    same ``conditions``, judged within ``goal_radius`` (default each scenario's own); one summary
    per agent, in order. ``max_steps`` defaults to each agent's own (see :func:`episode_limit`).
    At most :data:`EVALUATION_BLOCK` scenarios are held at a time when ``scenarios`` is a lazy
    iterable (in this process) or a :class:`ScenarioSource` (in worker processes too).

    ``jobs`` > 1 runs the episodes in up to that many worker processes, one per core at most (see
    :func:`_in_processes`), with the same figures, provided each agent pickles (a policy opened
    from a file does) and its ``reset`` forgets everything of the episode before, as an agent
    must anyway; ``progress`` then hears of a chunk of episodes at a time."""
    settings = _Settings(tier, seed, max_steps, (conditions or Conditions()).for_tier(tier), goal_radius)
    workers = min(jobs, os.cpu_count() or 1)
    if workers > 1:
        scenarios = scenarios if hasattr(scenarios, "part") else list(scenarios)
        if len(agents) * len(scenarios) > 1:
            rows = _in_processes(list(agents), scenarios, settings, workers, progress)
            return [summarise(agent.name, episodes) for agent, episodes in zip(agents, rows)]
    rows = [[] for _ in agents]
    for first, block in _blocks(scenarios, EVALUATION_BLOCK):
        for row, more in zip(rows, _drive(agents, block, first, settings, progress)):
            row += more
    return [summarise(agent.name, episodes) for agent, episodes in zip(agents, rows)]


@dataclass(frozen=True)
class _Settings:
    """What every episode of one :func:`evaluate` shares: episode i has seed ``seed + i``."""

    tier: str
    seed: int
    max_steps: int | None
    conditions: Conditions
    goal_radius: float | None


def _drive(agents: Sequence[Agent], scenarios: list[Scenario], first: int, settings: _Settings,
           progress: Callable[[int], None] | None = None) -> list[list[Episode]]:
    """Each agent's episodes first to first + len(scenarios) - 1 (each scenario as the conditions
    make it, its shortest path planned once for all agents)."""
    scenarios = [settings.conditions.scenario(s) for s in scenarios]
    shortest = [shortest_path_length(s, settings.goal_radius) for s in scenarios]
    rows = []
    for agent in agents:
        episodes = []
        for i, (scenario, length) in enumerate(zip(scenarios, shortest), first):
            episodes.append(run_episode(agent, scenario, settings.tier, settings.seed + i, settings.max_steps,
                                        shortest=length, conditions=settings.conditions,
                                        goal_radius=settings.goal_radius))
            if progress:
                progress(1)
        rows.append(episodes)
    return rows


def _blocks(items: Iterable, size: int) -> Iterator[tuple[int, list]]:
    """``items`` in lists of ``size`` (the last shorter), each with the index of its first item."""
    iterator, first = iter(items), 0
    while block := list(itertools.islice(iterator, size)):
        yield first, block
        first += len(block)


_WORKER: dict[str, object] = {}  # a worker process's agents, scenarios and settings, unpickled once as it starts


def _start_worker(agents: list, source: Sequence[Scenario] | ScenarioSource, settings: _Settings) -> None:
    # A Ctrl-C reaches every process of the terminal's group: the parent ends the workers, who
    # would otherwise catch it, report it and take the next chunk (minutes of episodes).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _WORKER["agents"], _WORKER["source"], _WORKER["settings"] = agents, source, settings
    torch = sys.modules.get("torch")  # loaded by unpickling a policy
    if torch is not None:
        torch.set_num_threads(1)  # a worker per core: more threads each would only contend


def _run_chunk(start: int, stop: int) -> list[list[Episode]]:
    source = _WORKER["source"]
    scenarios = list(source.part(start, stop)) if hasattr(source, "part") else source[start:stop]
    return _drive(_WORKER["agents"], scenarios, start, _WORKER["settings"])


def _in_processes(agents: list, source: Sequence[Scenario] | ScenarioSource, settings: _Settings, workers: int,
                  progress: Callable[[int], None] | None) -> list[list[Episode]]:
    """Every agent's episodes in chunks of episodes over ``workers`` fresh processes (``spawn``: no
    thread or simulator state of this process is copied). Every episode builds its own world from
    its scenario and seed, so it ends as it does in this process. The agents, the scenarios (a
    source: the recipe that draws them, each worker drawing its chunks' own) and the settings are
    sent once per worker as it starts (a policy opened from a file is opened again there, by its
    path); a chunk is two numbers, as scenarios sent with each chunk (hundreds of kB) could fill
    the queue's pipe, and a Ctrl-C then left the process waiting on it."""
    count = len(source)
    size = min(max(1, math.ceil(count / (4 * workers))), EVALUATION_BLOCK)  # a few chunks per worker keep them all busy
    chunks = [(start, min(start + size, count)) for start in range(0, count, size)]
    done: dict[int, list[list[Episode]]] = {}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(min(workers, len(chunks)), mp_context=context, initializer=_start_worker,
                             initargs=(agents, source, settings)) as pool:
        try:
            # Submitting starts the workers: a Ctrl-C then must end them too, not wait for them.
            futures = {pool.submit(_run_chunk, *chunk): chunk[0] for chunk in chunks}
            for future in as_completed(futures):
                done[futures[future]] = rows = future.result()  # a worker's error (a ConfigError too) is raised here
                if progress:
                    progress(sum(len(episodes) for episodes in rows))
        except BaseException as error:
            if not isinstance(error, Exception):  # Ctrl-C: the chunks running are dropped too
                for process in list(pool._processes.values()):  # no public way before Python 3.14's terminate_workers
                    process.terminate()
            pool.shutdown(wait=True, cancel_futures=True)  # the chunks not yet begun are dropped
            raise
    rows: list[list[Episode]] = [[] for _ in agents]
    for start, _ in chunks:
        for row, episodes in zip(rows, done[start]):
            row += episodes
    return rows


def episodes_as_dicts(summaries: Sequence[Summary]) -> list[dict]:
    """All episodes of all summaries as flat dicts (for CSV)."""
    return [asdict(e) for s in summaries for e in s.rows]
