"""Scenario model, YAML round trip, generators, suites and reachability."""

from __future__ import annotations

import hashlib
import json
import math
import re

import numpy as np
import pytest

from common.errors import ConfigError
from common.geometry import box_corner_table
from common.generators import KINDS, SUITES, generate, get_suite
from common.occupancy import OccupancyGrid, goal_reachable, path_exists, scenario_grid
from common.scenario import (
    BoxObstacle, CircleObstacle, PolygonObstacle, RobotProfile, Scenario, SegmentObstacle, load_scenario, save_scenario,
)


def test_yaml_round_trip_keeps_every_obstacle_kind(tmp_path):
    scenario = Scenario(
        name="all-kinds",
        obstacles=[
            CircleObstacle(x=5, y=5, radius=0.5),
            BoxObstacle(x=3, y=7, length=1.0, width=0.4, yaw=0.3),
            PolygonObstacle(vertices=[(6, 1), (7, 1), (6.5, 2)]),
            SegmentObstacle(points=[(8, 6), (8, 8), (9, 8)]),
        ],
    )
    path = tmp_path / "s.yaml"
    save_scenario(scenario, path)
    assert load_scenario(path) == scenario


@pytest.mark.parametrize("kind", KINDS)
def test_generated_scenarios_round_trip_and_are_valid(kind, tmp_path):
    scenario = generate(kind, seed=3)
    path = tmp_path / f"{kind}.yaml"
    save_scenario(scenario, path)
    assert load_scenario(path) == scenario
    assert goal_reachable(scenario)


@pytest.mark.parametrize("kind", ["open", "trap"])
def test_a_world_too_small_for_the_start_and_goal_is_refused(kind):
    # Placed kinds draw start and goal 1 m inside the world, a trap 3 m from its centre: a 0.9 m
    # world has no such place, and every kind checks its own layouts (none may come out invalid).
    tiny = Scenario(world={"width": 0.9, "height": 0.9, "walls": False}, start=(0.45, 0.45, 0.0), goal=(0.5, 0.5))
    with pytest.raises(ConfigError, match=f"robot: no reachable {kind} layout .* allowed: a smaller robot or a larger world"):
        generate(kind, 0, template=tiny)


@pytest.mark.parametrize("kind", KINDS)
def test_generators_are_deterministic_and_seed_sensitive(kind):
    assert generate(kind, 7) == generate(kind, 7)
    assert generate(kind, 7) != generate(kind, 8)


# Digests of the first 20 train and 20 eval scenarios of each kind at its suite's difficulty, as
# every published figure was measured on them. A change to the generators that moves a single
# obstacle changes a digest: then re-measure docs/benchmarks.md and update these on purpose.
SUITE_DIGESTS = {"open": "7dd5a0357ca22cea", "sparse": "f6460bdee89d46da", "cluttered": "096ce43262819b31",
                 "warehouse": "08dabd76ddf8a343", "trap": "565ea0984c189ebc", "crowd": "ab55f549b6c4fdf2",
                 "warehouse_moving": "dc534d7d8fc412e3", "maze": "00ccff5f1abbcd01", "passages": "4cbbfe27abfc8c7b"}


def _digest(scenarios: list[Scenario]) -> str:
    drawn = [scenario.model_dump(mode="json") for scenario in scenarios]
    return hashlib.sha256(json.dumps(drawn, sort_keys=True).encode()).hexdigest()[:16]


@pytest.mark.parametrize("kind", KINDS)
def test_the_generated_scenarios_are_the_ones_the_figures_were_measured_on(kind):
    difficulty = SUITES[kind].difficulty
    drawn = [generate(kind, seed, difficulty, split) for split in ("train", "eval") for seed in range(20)]
    assert _digest(drawn) == SUITE_DIGESTS[kind]


# The same for the ends of the difficulty range and for physics3d's template (its robot's larger
# footprint sets the gaps): 10 train and 10 eval scenarios each, as 28be363's generators drew them
# (the moving kinds' people since slide along walls: the same layouts, a new field).
EDGE_DIGESTS = {
    "open": ("bf95db95934438ef", "33b409d750e5806f", "60f37bfa0dfe7537"),
    "sparse": ("a880b0b5db84a880", "b4475c40ae7639a1", "0ce8d2a853ed6c06"),
    "cluttered": ("1ac768cf125fac61", "32d9b293c6c95618", "c76996cd7e070e21"),
    "warehouse": ("6790129ec960dd0f", "1c8057ebaa79ed0f", "17bf7dd8d265cc77"),
    "trap": ("3e84e209176d1e51", "245e0cf15e4c4755", "b318b182e07cd049"),
    "crowd": ("6c4d355f0b34ab61", "b8e0c8a04fe4f2d4", "75a3e23276c0dbb0"),
    "warehouse_moving": ("6456b1d5341ffb5b", "9e5dbc174c4e3e06", "eded5b92e6156f53"),
    "maze": ("d94f99af1cf2db3c", "a7cd7c495c9b2285", "112fe3d7fea86262"),
    "passages": ("f77f1549a6a65c89", "4e428804cd167c94", "bf57594d8e26f999"),
}


@pytest.mark.parametrize("kind", KINDS)
def test_easiest_hardest_and_3d_robot_scenarios_are_unchanged(kind):
    from physics3d.robot import TEMPLATE

    def digest(difficulty: float, template: Scenario | None = None) -> str:
        return _digest([generate(kind, seed, difficulty, split, template)
                        for split in ("train", "eval") for seed in range(10)])

    assert (digest(0.0), digest(1.0), digest(0.5, TEMPLATE)) == EDGE_DIGESTS[kind]


def test_train_and_eval_splits_differ_for_the_same_seed():
    assert generate("cluttered", 5, split="train").obstacles != generate("cluttered", 5, split="eval").obstacles


def test_warehouse_has_31_obstacles():
    for seed in range(5):
        assert len(generate("warehouse", seed, 1.0).obstacles) == 31


def test_a_wider_robot_gets_a_warehouse_with_fewer_crates_and_the_gaps_it_needs():
    """Crates that find no place with a robot's gap are left out; shelves and pillars stay."""
    template = Scenario(robot=RobotProfile(radius=0.35))
    for seed in range(20):
        scenario = generate("warehouse", seed, 1.0, template=template)
        heights = [obstacle.height for obstacle in scenario.obstacles]
        assert heights[:11] == [1.8] * 6 + [3.0] * 5 and set(heights[11:]) <= {0.6} and len(heights) < 31
        assert _min_gap(scenario) >= 2 * 0.35 - 0.02


def test_an_optional_step_leaves_out_what_finds_no_place_and_each_shape_keeps_its_height():
    from common.layouts import BOX, CRATE, PILLAR, Step, lay_out

    world = (0.0, 0.0, 6.0, 6.0)
    crowded = (Step(CRATE, 40, tries=3, side=(0.5, 0.9), height=0.6, optional=True), Step(PILLAR, 3, height=3.0))
    layout = lay_out(np.random.default_rng(1), world, 3.0, crowded, 0.2)
    assert 3 < len(layout.kinds) < 43
    np.testing.assert_array_equal(layout.heights, np.where(layout.kinds == BOX, 0.6, 3.0))
    strict = (crowded[0]._replace(optional=False), crowded[1])
    assert lay_out(np.random.default_rng(1), world, 3.0, strict, 0.2) is None


def _dense_outline(obstacle) -> np.ndarray:
    """256 points along a circle's or a box's boundary: finer than the generator's own check."""
    t = np.linspace(0.0, 1.0, 64, endpoint=False)[:, None]
    if isinstance(obstacle, CircleObstacle):
        angles = 2 * np.pi * np.linspace(0.0, 1.0, 256, endpoint=False)
        return np.column_stack([obstacle.x + obstacle.radius * np.cos(angles), obstacle.y + obstacle.radius * np.sin(angles)])
    corners = obstacle.corners()
    return np.concatenate([a + t * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0))])


def _min_gap(scenario: Scenario) -> float:
    """Smallest distance between two obstacles, measured on one's outline against the other's SDF."""
    gaps = []
    for i, a in enumerate(scenario.obstacles):
        for b in scenario.obstacles[i + 1:]:
            gaps.append(min(b.sdf(_dense_outline(a)).min(), a.sdf(_dense_outline(b)).min()))
    return min(gaps)


@pytest.mark.parametrize("kind", ["sparse", "cluttered", "warehouse"])
def test_generated_obstacles_do_not_overlap_and_leave_the_robot_a_gap(kind):
    for seed in range(5):
        scenario = generate(kind, seed)
        # The outline is sampled, so allow the sagitta of its sampling.
        assert _min_gap(scenario) >= 2 * scenario.robot.bounding_radius - 0.02


def test_start_and_goal_are_clear_of_obstacles():
    for kind in KINDS:
        for seed in range(5):
            s = generate(kind, seed)
            assert s.signed_distance(np.array([s.start[:2]]))[0] >= s.robot.bounding_radius
            assert s.signed_distance(np.array([s.goal]))[0] > 0


def test_difficulty_adds_obstacles():
    easy = np.mean([len(generate("cluttered", s, 0.0).obstacles) for s in range(5)])
    hard = np.mean([len(generate("cluttered", s, 1.0).obstacles) for s in range(5)])
    assert hard > easy


def test_trap_blocks_the_straight_line_to_the_goal():
    for seed in range(10):
        s = generate("trap", seed)
        line = np.linspace(s.start[:2], s.goal, 200)
        assert (s.signed_distance(line) < s.robot.radius).any(), "the trap must sit on the direct route"


def test_unreachable_goal_is_detected():
    wall = BoxObstacle(x=5, y=5, length=0.2, width=10.0)  # splits the walled world in two
    scenario = Scenario(start=(2, 5, 0), goal=(8, 5), obstacles=[wall])
    assert not goal_reachable(scenario)
    assert goal_reachable(scenario.model_copy(update={"goal": (3, 8)}))


def test_path_exists_agrees_with_labelling_the_free_cells():
    # The goal-ward depth-first fill must answer as the 8-connected labelling it replaced.
    rng = np.random.default_rng(1)
    answers = []
    for trial in range(300):
        grid = OccupancyGrid(occupied=rng.random((30, 40)) < rng.uniform(0.3, 0.6), origin=(-1.0, 2.0), resolution=0.25)
        start, goal = rng.uniform((-1, 2), (9, 9.5)), rng.uniform((-1, 2), (9, 9.5))
        threshold = rng.choice([0.0, 0.3, 0.8])
        rows, cols = np.nonzero(grid.free_component(*start))
        centres = np.column_stack([-1.0 + (cols + 0.5) * 0.25, 2.0 + (rows + 0.5) * 0.25])
        expected = bool(np.any(np.hypot(*(centres - goal).T) <= threshold))
        assert path_exists(grid, start, goal, threshold) == expected, trial
        answers.append(expected)
    assert 0.2 < np.mean(answers) < 0.8  # both answers well represented


def test_grid_marks_inflated_obstacles_and_walls():
    scenario = Scenario(obstacles=[CircleObstacle(x=5, y=5, radius=1.0)])
    grid = scenario_grid(scenario, resolution=0.2)
    assert grid.occupied.shape == (50, 50)
    assert grid.occupied[grid.cell_of(5, 5)]
    assert grid.occupied[grid.cell_of(6.1, 5)]  # within radius + inflation
    assert not grid.occupied[grid.cell_of(6.5, 5)]
    assert grid.occupied[grid.cell_of(0.05, 5)]  # the wall, inflated


def test_the_grid_is_the_one_measuring_every_cell_would_give():
    # scenario_grid measures only the cells near each obstacle; no cell may come out differently.
    rng = np.random.default_rng(0)
    for trial in range(40):
        obstacles = [
            CircleObstacle(x=rng.uniform(-1, 9), y=rng.uniform(-1, 7), radius=rng.uniform(0.05, 1.5)),
            BoxObstacle(x=rng.uniform(-1, 9), y=rng.uniform(-1, 7), length=rng.uniform(0.05, 3), width=rng.uniform(0.05, 2),
                        yaw=rng.uniform(-4, 4)),
            PolygonObstacle(vertices=[(3, 1), (4.5, 1.2), (4, 2.5)]),
            SegmentObstacle(points=[tuple(rng.uniform(0, 8, 2)), tuple(rng.uniform(0, 6, 2)), tuple(rng.uniform(0, 8, 2))]),
            CircleObstacle(x=4, y=3, radius=0.8, unobstructed=True),
        ]
        world = {"width": 8.0, "height": 6.0, "offset": (rng.uniform(-2, 2), rng.uniform(-2, 2)), "walls": trial % 2 == 0}
        scenario = Scenario(world=world, start=(1, 1, 0), goal=(7, 5), obstacles=obstacles)
        resolution, inflation = rng.choice([0.05, 0.1, 0.2, 0.33]), rng.choice([0.0, 0.2, 0.45])
        grid = scenario_grid(scenario, resolution, inflation)
        rows, cols = grid.occupied.shape
        xs = scenario.world.offset[0] + (np.arange(cols) + 0.5) * resolution
        ys = scenario.world.offset[1] + (np.arange(rows) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        every = (scenario.signed_distance(np.column_stack([gx.ravel(), gy.ravel()])) < inflation).reshape(rows, cols)
        if scenario.world.walls:
            x0, y0 = scenario.world.offset
            every |= (gx - x0 < inflation) | (x0 + 8.0 - gx < inflation) | (gy - y0 < inflation) | (y0 + 6.0 - gy < inflation)
        assert np.array_equal(grid.occupied, every), trial


def test_suites_are_reproducible_and_shifted_by_seed():
    suite = get_suite("sparse")
    first = list(suite.scenarios(count=3))
    assert first == list(suite.scenarios(count=3))
    shifted = list(suite.scenarios(count=3, seed=1))
    assert shifted[0] == first[1]
    assert set(KINDS) <= set(SUITES) and {suite.kind for suite in SUITES.values()} == set(KINDS)


def test_unknown_suite_and_kind_name_the_allowed_values():
    with pytest.raises(ConfigError, match="allowed: open, sparse"):
        get_suite("nope")
    with pytest.raises(ConfigError, match="kind"):
        generate("nope", 0)


def test_check_rejects_goal_inside_obstacle_and_start_outside_world():
    with pytest.raises(ConfigError, match="goal.*inside an obstacle"):
        Scenario(goal=(5, 5), obstacles=[CircleObstacle(x=5, y=5, radius=1)]).check("f.yaml")
    with pytest.raises(ConfigError, match="start.*outside the world"):
        Scenario(start=(12, 1, 0)).check("f.yaml")
    with pytest.raises(ConfigError, match="start.*robot's radius"):
        Scenario(start=(5, 5, 0), obstacles=[CircleObstacle(x=5.3, y=5, radius=0.2)]).check()


def test_box_corners_follow_yaw():
    # A yaw with no symmetry, so turning the wrong way shows: the corner ahead-left first, counter-clockwise.
    yaw = 0.3
    box = BoxObstacle(x=1.0, y=2.0, length=2, width=1, yaw=yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    expected = [(1.0 + u * c - v * s, 2.0 + u * s + v * c) for u, v in ((1, 0.5), (-1, 0.5), (-1, -0.5), (1, -0.5))]
    np.testing.assert_allclose(box.corners(), expected, atol=1e-12)


def test_box_corner_table_is_the_rotation_formula_to_the_last_bit_and_counter_clockwise():
    # pymunk's boxes and the lidar's are built from these corners: a matrix product or a fused
    # multiply-add would round differently on another machine and move a contact by an ulp.
    rng = np.random.default_rng(0)
    rows, expected = [], []
    for x, y, length, width, yaw in rng.uniform((-50, -50, 0.01, 0.01, -4), (50, 50, 5, 5, 4), (500, 5)).tolist():
        c, s = math.cos(yaw), math.sin(yaw)
        rows.append((x, y, c, s, 0.5 * length, 0.5 * width))
        expected.append([(x + u * c - v * s, y + u * s + v * c) for u, v in
                         ((0.5 * length, 0.5 * width), (-0.5 * length, 0.5 * width),
                          (-0.5 * length, -0.5 * width), (0.5 * length, -0.5 * width))])
    corners = box_corner_table(np.array(rows))
    assert np.array_equal(corners, np.array(expected))
    edges = np.roll(corners, -1, axis=1) - corners
    turns = edges[:, :-1, 0] * edges[:, 1:, 1] - edges[:, :-1, 1] * edges[:, 1:, 0]
    assert (turns > 0).all()  # every turn to the left


def test_the_vertices_of_all_polygons_and_polylines_are_capped():
    from common.scenario import MAX_TOTAL_VERTICES, PolygonObstacle, SegmentObstacle

    ring = [(5.0 + 3.0 * math.cos(a), 5.0 + 3.0 * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 1000, endpoint=False)]
    line = [(x, 1.0) for x in np.linspace(0.5, 9.5, 1000)]
    world = {"world": {"width": 100.0, "height": 100.0}}
    Scenario.model_validate({**world, "obstacles": [PolygonObstacle(vertices=ring)] * 5 + [SegmentObstacle(points=line)] * 5})
    with pytest.raises(ValueError, match=f"11,000 vertices in all; allowed: at most {MAX_TOTAL_VERTICES:,}"):
        Scenario.model_validate({**world, "obstacles": [PolygonObstacle(vertices=ring)] * 6 + [SegmentObstacle(points=line)] * 5})


@pytest.mark.parametrize(("fields", "message"), [
    ({"shape": "compound"}, "a compound footprint takes its parts"),
    ({"parts": ({"radius": 0.2},)}, "a compound footprint takes its parts"),
    ({"shape": "compound", "parts": ({"radius": 0.2, "vertices": ((0, 0), (1, 0), (0, 1))},)}, "not both or neither"),
    ({"shape": "compound", "parts": ({"center": (0.1, 0.0)},)}, "not both or neither"),
    ({"shape": "compound", "parts": ({"vertices": ((0, 0), (1, 1), (1, 0), (0, 1))},)}, "crosses itself"),
    ({"shape": "compound", "parts": ({"radius": 0.2},), "footprint_offset": 0.1}, "allowed: footprint_offset 0"),
    ({"shape": "compound", "parts": ({"vertices": tuple((math.cos(a), math.sin(a)) for a in
                                                        np.linspace(0, 6, 600))},) * 2}, "at most 1000"),
])
def test_a_compound_footprint_is_parts_and_only_parts(fields, message):
    with pytest.raises(ValueError, match=message):
        RobotProfile(**fields)


def test_a_compound_footprint_reaches_as_far_as_its_farthest_part():
    robot = RobotProfile(shape="compound", parts=({"vertices": ((-0.3, -0.1), (0.3, -0.1), (0.3, 0.1), (-0.3, 0.1))},
                                                  {"center": (0.0, 0.4), "radius": 0.2}))
    assert robot.bounding_radius == pytest.approx(0.6)
    assert [part.radius for part in robot.outline] == [None, 0.2]


def test_a_copied_profile_outlines_its_own_footprint_not_the_original_s():
    robot = RobotProfile()
    assert robot.outline[0].radius == 0.2 and robot.width_across == pytest.approx(0.4)
    wider = robot.model_copy(update={"shape": "box", "length": 0.5, "width": 0.45})
    assert wider.outline[0].radius is None and wider.width_across == pytest.approx(0.45)


@pytest.mark.parametrize("field", ["radius", "length", "width"])
def test_a_robot_smaller_than_a_millimetre_is_refused_where_it_is_written(field, tmp_path):
    """A 1e-7 m box passed validation, then the env failed building its outline (a raw pydantic error)."""
    from common.scenario import load_scenario

    shape = "circle" if field == "radius" else "box"
    (tmp_path / "s.yaml").write_text(f"robot: {{shape: {shape}, {field}: 1.0e-7}}\nstart: [1, 1, 0]\ngoal: [9, 9]\n")
    with pytest.raises(ConfigError, match=rf"s\.yaml: robot\.{field}: Input should be greater than or equal to 0\.001"):
        load_scenario(tmp_path / "s.yaml")
    RobotProfile(shape=shape, **{field: 0.001}).outline  # the smallest allowed is built


def test_a_file_mixing_the_two_formats_names_the_keys_of_each(tmp_path):
    """An IR-SIM key under world: made the file an IR-SIM world, and the scenario's start an unknown key."""
    from common.world_file import WorldFile

    (tmp_path / "mixed.yaml").write_text("world: {width: 10, height: 10, gravity: 9.8}\nstart: [1, 1, 0]\ngoal: [9, 9]\n")
    with pytest.raises(ConfigError, match=r"mixed\.yaml: goal: a project scenario's key, in a file that world\.gravity "
                                          r"marks as an IR-SIM world; allowed: one format per file"):
        WorldFile(tmp_path / "mixed.yaml")


def test_a_start_within_the_robot_s_radius_of_a_wall_is_refused_where_written(tmp_path):
    """It passed validation and collided on the first step; generated worlds keep their own rule."""
    from common.scenario import load_scenario

    (tmp_path / "s.yaml").write_text("start: [0.05, 5, 0]\ngoal: [9, 9]\n")
    with pytest.raises(ConfigError, match=r"s\.yaml: start: \(0\.05, 5\) is 0\.05 m from the world's boundary wall; "
                                          r"allowed: at least 0\.2 m"):
        load_scenario(tmp_path / "s.yaml")
    (tmp_path / "s.yaml").write_text("start: [0.05, 5, 0]\ngoal: [9, 9]\nworld: {walls: false}\n")
    assert load_scenario(tmp_path / "s.yaml").start[0] == 0.05
    (tmp_path / "s.yaml").write_text("start: [0.2, 9.8, 0]\ngoal: [9, 9]\n")  # exactly the radius: allowed
    load_scenario(tmp_path / "s.yaml")


def test_a_goal_within_its_radius_of_the_start_is_refused_where_written(tmp_path):
    """The episode was a success before the robot moved (+100 at step 1)."""
    from common.scenario import load_scenario

    (tmp_path / "s.yaml").write_text("start: [5, 5, 0]\ngoal: [5.1, 5]\n")
    with pytest.raises(ConfigError, match=r"s\.yaml: goal: \(5\.1, 5\.0\) is within goal_threshold \(0\.3 m\) of the start"):
        load_scenario(tmp_path / "s.yaml")
    (tmp_path / "s.yaml").write_text("start: [5, 5, 0]\ngoal: [5.31, 5]\n")
    load_scenario(tmp_path / "s.yaml")


def test_a_static_obstacle_wholly_outside_the_walled_world_is_refused(tmp_path):
    """Behind the walls nothing ever meets it: it was accepted, and the world was not the one meant."""
    from common.scenario import load_scenario

    base = "start: [1, 1, 0]\ngoal: [9, 9]\n"
    (tmp_path / "s.yaml").write_text(base + "obstacles: [{type: circle, x: 5, y: 5, radius: 0.5},"
                                            " {type: box, x: 15, y: 5, length: 1, width: 1}]\n")
    with pytest.raises(ConfigError, match=r"s\.yaml: obstacles\.1: lies entirely outside the world \[0, 10\] x \[0, 10\]"):
        load_scenario(tmp_path / "s.yaml")
    # Touching the world's edge, beyond walls that are not there, or moving in: each meant, each kept.
    for obstacle in ("{type: box, x: 10.5, y: 5, length: 1, width: 1}", "{type: box, x: 15, y: 5, length: 1, width: 1}",
                     "{type: circle, x: 12, y: 5, radius: 0.3, motion: {goals: [[8, 5]]}}"):
        walls = "world: {walls: false}\n" if "x: 15" in obstacle else ""
        (tmp_path / "s.yaml").write_text(base + walls + f"obstacles: [{obstacle}]\n")
        assert len(load_scenario(tmp_path / "s.yaml").obstacles) == 1


@pytest.mark.parametrize("text, field, allowed", [
    ("world: {width: true}\n", "world.width", "a number"),
    ("start: [1, true, 0]\n", "start.1", "a number"),
    ("robot: {radius: false}\n", "robot.radius", "a number"),
    ("lidar: {beams: true}\n", "lidar.beams", "a number"),
    # Quoted numbers and flags that are not true or false were read as what they look like.
    ("world: {width: '10'}\n", "world.width", "a number"),
    ("start: ['1', 1, 0]\n", "start.0", "a number"),
    ("lidar: {beams: '36'}\n", "lidar.beams", "a number"),
    ("obstacles: [{type: circle, x: 5, y: 5, radius: '0.5'}]\n", "obstacles.0.radius", "a number"),
    ("obstacles: [{type: circle, x: 5, y: 5, radius: 0.3, motion: {goals: [['6', 6]]}}]\n", "obstacles.0.motion.goals.0.0",
     "a number"),
    ("world: {walls: 0}\n", "world.walls", "true or false"),
    ("lidar: {repeat_end_beam: 1}\n", "lidar.repeat_end_beam", "true or false"),
    ("obstacles: [{type: circle, x: 5, y: 5, radius: 0.3, unobstructed: 'yes'}]\n", "obstacles.0.unobstructed",
     "true or false"),
])
def test_a_value_pydantic_would_misread_is_refused(tmp_path, text, field, allowed):
    from common.scenario import load_scenario

    (tmp_path / "s.yaml").write_text("start: [1, 1, 0]\ngoal: [8, 8]\n" + text if "start" not in text
                                     else text + "goal: [8, 8]\n")
    with pytest.raises(ConfigError, match=rf"s\.yaml: {re.escape(field)}: .*; allowed: {allowed}$"):
        load_scenario(tmp_path / "s.yaml")
    # Text where text belongs stays text, even when it reads as a number (a group's name).
    (tmp_path / "t.yaml").write_text("start: [1, 1, 0]\ngoal: [8, 8]\nobstacles: [{type: circle, x: 5, y: 5, "
                                     "radius: 0.3, motion: {goals: [[6, 6]], group: '2', behavior: {name: orca}}}]\n")
    assert load_scenario(tmp_path / "t.yaml").obstacles[0].motion.group == "2"


@pytest.mark.parametrize("text, expected", [
    ("obstacles: [{x: 5, y: 5, radius: 0.5}]\n", "obstacles.0.type: missing; allowed: circle, box, polygon, segment"),
    ("obstacles: [{type: cirle, x: 5, y: 5, radius: 0.5}]\n",
     "obstacles.0.type: 'cirle' (did you mean 'circle'?); allowed: circle, box, polygon, segment"),
    # pydantic puts the union member's tag in the path: no one wrote a key "box".
    ("obstacles: [{type: box, x: 5, y: 5, width: 0.5}]\n", "obstacles.0.length: Field required"),
    ("obstacles: [{type: circle, x: 5, y: 5, radius: 0.5, motion: {goals: [[1, 1]], behavior: {name: sfm, vmaxx: 1}}}]\n",
     "obstacles.0.motion.behavior.vmaxx: unknown key (did you mean 'vmax'?); allowed: force_factor_desired"),
    ("obstacles: [{type: circle, x: 5, y: 5, radius: 0.5, motion: {goals: [[1, 1]], behavior: {name: sfn}}}]\n",
     "obstacles.0.motion.behavior.name: 'sfn' (did you mean 'sfm'?); allowed: dash, rvo, orca, sfm"),
    ("goal: [9.0]\n", "goal: too few values (got [9.0]); item 1 is missing"),
    # A key spelt like a tag, where no tag stands, is the user's key and stays in the path.
    ("obstacles: [{type: circle, x: 5, y: 5, radius: 0.5, circle: 1}]\n", "obstacles.0.circle: unknown key; allowed:"),
    ("obstacles: [{type: 3, x: 5, y: 5, radius: 0.5}]\n", "obstacles.0.type: 3; allowed: circle, box"),
    ("robot:\n\tradius: 0.3\n", "line 4: not valid YAML: found character that cannot start any token (a tab; YAML "
                                "indents with spaces)"),
])
def test_a_mistyped_scenario_is_told_in_the_words_of_its_file(tmp_path, text, expected):
    from common.scenario import load_scenario

    head = "start: [1, 1, 0]\n" if text.startswith("goal") else "start: [1, 1, 0]\ngoal: [8, 8]\n"
    (tmp_path / "s.yaml").write_text(head + text)
    with pytest.raises(ConfigError) as error:
        load_scenario(tmp_path / "s.yaml")
    assert str(error.value).startswith(f"{tmp_path / 's.yaml'}: {expected}"), str(error.value)


def test_a_boolean_in_a_robot_mapping_is_refused_where_a_number_belongs_and_kept_for_a_flag():
    from common.robots import robot_profile

    with pytest.raises(ConfigError, match=r"^robot\.radius: got true; allowed: a number$"):
        robot_profile({"radius": True})
    assert robot_profile({"radius": 0.3, "static": True}).static


@pytest.mark.parametrize("env_id", ["flatland/Nav-v0", "physics3d/WarehouseNav-v0"])
def test_a_scenario_written_in_python_with_its_goal_outside_the_world_is_refused(env_id):
    """Such a goal trained until every episode's truncation without a word."""
    import gymnasium as gym

    import flatland  # noqa: F401
    import physics3d  # noqa: F401

    with pytest.raises(ConfigError, match=r"^world\.goal: scenario 'scenario': \(12, 5\) lies outside the world \[0, 10\] x \[0, 10\]$"):
        gym.make(env_id, world=Scenario(goal=(12.0, 5.0)))
    with pytest.raises(ConfigError, match=r"^world\.1\.start: .* \(-1, 2\) lies outside the world"):
        gym.make(env_id, world=[Scenario(), Scenario(start=(-1.0, 2.0, 0.0))])
    # A generator's scenarios are left to their own acceptance rule (every suite stays as it was).
    generated = next(iter(get_suite("sparse").scenarios(count=1, seed=0)))
    gym.make(env_id, world=generated.model_copy(update={"goal": (12.0, 5.0)})).close()


@pytest.mark.parametrize("env_id", ["flatland/Nav-v0", "physics3d/WarehouseNav-v0"])
def test_a_difficulty_out_of_range_is_named_alike_in_both_tiers(env_id):
    """The 3D tier reported it as a kind it does not build, with nothing allowed."""
    import gymnasium as gym

    import flatland  # noqa: F401
    import physics3d  # noqa: F401

    for world in ("warehouse", {"sparse": 1, "cluttered": 1}):
        with pytest.raises(ConfigError, match=r"^difficulty: got 3; allowed: a number from 0 to 1$"):
            gym.make(env_id, world=world, difficulty=3)
