"""Occupancy grid maps (IR-SIM's ``obstacle_map``): read as IR-SIM reads an image or a generator
spec, seen and collided with in flatland as in IR-SIM, known to the planners' ground truth, and
refused in one line where they cannot be built."""

from __future__ import annotations

import math
import os
import struct
import zlib

import numpy as np
import pytest
import yaml
from PIL import Image

from common.errors import ConfigError
from common.grid_maps import GridMap, occupied_boxes, occupancy
from common.occupancy import scenario_grid
from common.scenario import Scenario
from tests.conftest import optional


def _image(tmp_path, pixels: np.ndarray, name: str = "map.png") -> str:
    path = tmp_path / name
    Image.fromarray(pixels.astype(np.uint8)).save(path)
    return str(path)


def test_an_image_is_read_with_its_top_row_at_the_top_of_the_world(tmp_path):
    pixels = np.full((2, 4), 255)  # 2 rows, 4 columns, white
    pixels[0, 0] = 0  # black: the top-left pixel
    grid = GridMap(image=_image(tmp_path, pixels))
    occupied = occupancy(grid, 8.0, 4.0)
    assert occupied.shape == (4, 2) and occupied.sum() == 1 and occupied[0, 1]  # x index 0, the upper row
    # On an 8 m x 4 m world every cell is 2 m square; the cell's centre is (1, 3).
    assert occupied_boxes(grid, 8.0, 4.0, (0.0, 0.0)).tolist() == [[1.0, 3.0, 2.0, 2.0]]
    assert occupied_boxes(grid, 8.0, 4.0, (10.0, 20.0))[0, :2].tolist() == [11.0, 23.0]


def test_the_occupied_cells_become_few_boxes_that_cover_exactly_them(tmp_path):
    pixels = np.full((6, 6), 255)
    pixels[1:4, 1:4] = 0  # a 3 x 3 block: one box
    pixels[5, 0:6] = 0  # the bottom row: one box
    pixels[2:5, 5] = 0  # and a bar down the right side, touching it: a box of its own
    grid = GridMap(image=_image(tmp_path, pixels))
    boxes = occupied_boxes(grid, 6.0, 6.0, (0.0, 0.0))
    assert len(boxes) == 3
    # Painted back cell by cell, the boxes are the occupied cells, no more and no fewer.
    painted = np.zeros((6, 6), dtype=bool)
    for x, y, width, height in boxes:
        painted[int(x - width / 2):int(x + width / 2), int(y - height / 2):int(y + height / 2)] = True
    assert np.array_equal(painted, occupancy(grid, 6.0, 6.0))


def test_the_planners_ground_truth_holds_the_map(tmp_path):
    pixels = np.full((10, 10), 255)
    pixels[:, 5] = 0  # a wall across the world at x = 5..6
    scenario = Scenario(grid_map=GridMap(image=_image(tmp_path, pixels)), start=(1.0, 5.0, 0.0), goal=(9.0, 5.0))
    grid = scenario_grid(scenario, resolution=0.1, inflation=0.0)
    row = grid.occupied[50]
    assert row[52] and row[57] and not row[45] and not row[65]


def test_a_scenario_file_takes_a_map_image_beside_it(tmp_path):
    from common.scenario import load_scenario

    pixels = np.full((10, 10), 255)
    pixels[:, 5] = 0
    _image(tmp_path, pixels, "wall.png")
    (tmp_path / "scenario.yaml").write_text("grid_map: {image: wall.png}\nstart: [1, 5, 0]\ngoal: [9, 5]\n")
    scenario = load_scenario(tmp_path / "scenario.yaml")
    assert occupancy(scenario.grid_map, 10.0, 10.0)[5].all()
    (tmp_path / "bad.yaml").write_text("grid_map: {image: gone.png}\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: grid_map: \S*gone\.png: no such file"):
        load_scenario(tmp_path / "bad.yaml")
    (tmp_path / "both.yaml").write_text("grid_map: {}\n")
    with pytest.raises(ConfigError, match=r"both\.yaml: grid_map: a grid map comes from an image or a generator"):
        load_scenario(tmp_path / "both.yaml")
    # A name of 5,000 characters filled the message's 1,000 before its problem: cut in its middle, the problem shows.
    (tmp_path / "long.yaml").write_text(f"grid_map: {{image: {'a' * 5000}.png}}\n")
    with pytest.raises(ConfigError, match=r"long\.yaml: grid_map: \S*a\.\.\.a+\.png: cannot be read \(file name too "
                                          r"long\); expected an image file$"):
        load_scenario(tmp_path / "long.yaml")


def _world_file(tmp_path, obstacle_map, **world) -> str:
    data = {"world": {"width": 50, "height": 50, "obstacle_map": obstacle_map, **world},
            "robot": [{"kinematics": {"name": "diff"}, "shape": {"name": "circle", "radius": 0.5},
                       "state": [8, 8, 0.5], "goal": [40, 40, 0], "vel_max": [3, 1.5],
                       "sensors": [{"name": "lidar2d", "range_max": 12, "angle_range": 2 * math.pi, "number": 120}]}]}
    path = tmp_path / "map.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


@pytest.mark.parametrize("obstacle_map, world", [
    ("cave.png", {"mdownsample": 2}),  # IR-SIM's own cave, found among its maps
    ({"name": "perlin", "resolution": 0.25, "complexity": 0.1, "fill": 0.3, "fractal": 1, "attenuation": 0.5,
      "seed": 5}, {}),
], ids=["image", "perlin"])
def test_a_grid_map_is_seen_and_collided_with_as_irsim_does(obstacle_map, world, tmp_path):
    irsim = optional("irsim")
    import flatland

    path = _world_file(tmp_path, obstacle_map, **world)
    ours = flatland.load_world(path, seed=0)
    env = irsim.make(path, display=False, log_level="ERROR", seed=0)
    rng = np.random.default_rng(3)
    collided = -1
    try:
        ours.reset()
        for k in range(400):
            command = (rng.uniform(0.5, 3.0), rng.uniform(-1.5, 1.5))
            readings = ours.step(*command)
            env.step(np.array(command).reshape(2, 1))
            pose = np.asarray(env.get_robot_state()[:3, 0], dtype=float)
            np.testing.assert_allclose(readings.pose[:2], pose[:2], rtol=0, atol=1e-9, err_msg=f"step {k}")
            close = np.abs(readings.lidar - env.get_lidar_scan()["ranges"]) <= 0.02
            assert close.mean() >= 0.95, f"step {k}: {close.mean():.0%} of beams within 2 cm"
            assert readings.collided == bool(env.robot.collision_flag), f"collision flag, step {k}"
            if readings.collided:
                collided = k
                break
    finally:
        env.end(0)
    assert collided >= 0, "the drive never met the map: its contact was not compared"


def _png_header(width: int, height: int) -> bytes:
    """A tiny PNG file whose header claims ``width`` x ``height`` grey pixels (a decompression bomb's header)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0\0")) + chunk(b"IEND", b"")


def test_grid_maps_are_refused_in_one_line_where_they_cannot_be_read_or_built(tmp_path):
    from common.world_file import read_world_file
    from physics3d.world import World

    with pytest.raises(ConfigError, match=r"world\.obstacle_map: image 'nowhere\.png' not found"):
        read_world_file(_world_file(tmp_path, "nowhere.png"))
    huge = _image(tmp_path, np.zeros((4100, 4100)), "huge.png")
    with pytest.raises(ConfigError, match=r"world\.obstacle_map: 4100 x 4100 pixels; allowed: at most"):
        read_world_file(_world_file(tmp_path, huge))
    Image.new("L", (8, 8)).save(tmp_path / "photo.jpg")
    jpeg = (tmp_path / "photo.jpg").read_bytes()  # PIL's PNG reader, forced by the name, raised SyntaxError on it
    for name, content, problem in (("junk.png", b"not an image", "unreadable image data"),
                                   ("jpeg.png", jpeg, "unreadable image data"),
                                   ("bomb.png", _png_header(60000, 60000), r"Image size \(3600000000 pixels\) exceeds limit of \d+ pixels")):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(ConfigError, match=rf"world\.obstacle_map: {problem}; allowed: a PNG or another image"):
            read_world_file(_world_file(tmp_path, str(tmp_path / name)))
    # A FIFO is refused, not waited on for a writer (the test would hang).
    os.mkfifo(tmp_path / "fifo.png")
    with pytest.raises(ConfigError, match=r"a FIFO \(named pipe\), not a regular file; expected an image file"):
        read_world_file(_world_file(tmp_path, str(tmp_path / "fifo.png")))
    with pytest.raises(ConfigError, match=r"world\.obstacle_map\.name: expected a string \(got 3\)"):
        read_world_file(_world_file(tmp_path, {"name": 3}))
    with pytest.raises(ConfigError, match=r"world\.obstacle_map\.name: got 'labyrinth'; allowed: maze, perlin"):
        read_world_file(_world_file(tmp_path, {"name": "labyrinth", "resolution": 0.1}))
    scenario = Scenario(grid_map=GridMap(image=_image(tmp_path, np.full((4, 4), 255))))
    with pytest.raises(ConfigError, match="grid_map: an occupancy grid map is not built in the 3D tier"):
        World(scenario)


def test_a_map_whose_cells_or_columns_would_take_minutes_is_refused_in_one_line(tmp_path):
    """A 2 KB checkerboard PNG asked for 524,288 bodies (minutes, gigabytes); a 16,000,000 x 1
    image for a Python step per column. Both refused as the file is read, naming it."""
    from common.world_file import read_world_file

    checker = (np.indices((600, 600)).sum(axis=0) % 2) * 255
    path = _world_file(tmp_path, _image(tmp_path, checker, "checker.png"))
    with pytest.raises(ConfigError) as error:
        read_world_file(path)
    assert str(error.value) == (f"{path}: world.obstacle_map: more than 65,536 boxes of occupied cells; allowed: at "
                                "most 65,536 (a coarser map, or downsample)")
    wide = _image(tmp_path, np.full((1, 9000), 255), "wide.png")
    with pytest.raises(ConfigError, match=r"world\.obstacle_map: 9000 x 1 pixels; allowed: at most 16,777,216 pixels, "
                                          r"8,192 along either side"):
        read_world_file(_world_file(tmp_path, wide))
    # IR-SIM's largest shipped map merges into 14,236 boxes; a map of wide stripes into few.
    stripes = np.zeros((1000, 1000))
    stripes[::2] = 255
    assert len(occupied_boxes(GridMap(image=_image(tmp_path, stripes, "stripes.png")), 50.0, 50.0, (0.0, 0.0))) == 500


PERLIN = {"name": "perlin", "resolution": 0.1, "complexity": 0.12, "fill": 0.32, "fractal": 1, "attenuation": 0.5, "seed": 48}


@pytest.mark.parametrize("change, field, problem", [
    # IR-SIM would ask for 4e12 cells (terabytes), index out of its array, or overflow after seconds.
    ({"resolution": 1e-3}, "resolution", "0.001 m makes 400,000,000 cells over the 20 x 20 m world; allowed: at most 4,194,304 cells"),
    ({"resolution": 0}, "resolution", "got 0; allowed: a length from 0.001 to 1000 m"),
    ({"resolution": -1}, "resolution", "got -1; allowed: a length from 0.001 to 1000 m"),
    ({"resolution": 1e-320}, "resolution", "got 1e-320; allowed: a length from 0.001 to 1000 m"),  # overflowed the cell count
    ({"complexity": 1e300}, "complexity", "got 1e+300; allowed: a number above 0, at most 1000"),  # NaN noise, an empty map
    ({"fill": 5}, "fill", "got 5; allowed: a number from 0 to 1"),
    ({"fractal": 100000}, "fractal", "got 100000; allowed: a whole number from 1 to 16"),
    # Noise is computed over every cell once per octave: 16 octaves of the largest grid ran for minutes.
    ({"resolution": 0.01, "fractal": 2}, "fractal", "2 octaves over 4,000,000 cells; allowed: at most 4,194,304 cells times octaves"),
    ({"complexity": float("nan")}, "complexity", "got nan; allowed: a number above 0, at most 1000"),
    ({"complexity": "abc"}, "complexity", "got 'abc'; allowed: a number above 0, at most 1000"),
    ({"seed": -3}, "seed", "got -3; allowed: a whole number from 0, or null"),
    ({"bogus": 48}, "bogus", "unknown key of the perlin generator; allowed: resolution, complexity, fill, attenuation, fractal, seed"),
    ({"resolution": None}, "resolution", "missing; the perlin generator needs resolution"),
])
def test_a_generator_spec_is_checked_before_anything_is_built(tmp_path, change, field, problem):
    from common.world_file import read_world_file

    spec = {key: value for key, value in {**PERLIN, **change}.items() if value is not None}
    with pytest.raises(ConfigError) as error:
        read_world_file(_world_file(tmp_path, spec, width=20, height=20))
    assert str(error.value) == f"{tmp_path / 'map.yaml'}: world.obstacle_map.{field}: {problem}"


def test_a_project_files_maze_spec_is_checked_by_its_own_keys(tmp_path):
    from common.scenario import load_scenario

    path = tmp_path / "maze.yaml"
    path.write_text("start: [1, 1, 0]\ngoal: [8, 8]\n"
                    "grid_map: {generator: [[name, maze], [resolution, 0.1], [passage, 1.0], [loops, 2], [seed, 1]]}\n")
    with pytest.raises(ConfigError, match=r"maze\.yaml: grid_map\.generator\.loops: got 2; allowed: a number from 0 to 1$"):
        load_scenario(path)
    path.write_text("start: [1, 1, 0]\ngoal: [8, 8]\ngrid_map: {generator: [[name, maze], [resolution, 0.1], "
                    "[passage, 1.0e+308], [loops, 0.1], [seed, 1]]}\n")  # overflowed the maze's lattice
    with pytest.raises(ConfigError, match=r"grid_map\.generator\.passage: got 1e\+308; allowed: a length from 0\.001"):
        load_scenario(path)
    path.write_text("start: [1, 1, 0]\ngoal: [8, 8]\ngrid_map: {generator: [[name, maze], [resolution, 0.1], "
                    "[passage, 1.0], [loops, 0.1], [seed, 1], [seed, 2]]}\n")  # the last seed won, silently
    with pytest.raises(ConfigError, match=r"grid_map: generator: 'seed' given twice; allowed: each key once$"):
        load_scenario(path)


def test_a_maze_is_drawn_from_its_seed_and_every_room_is_reachable():
    from common.generators import generate
    from common.grid_maps import maze_occupancy, maze_rooms
    from common.occupancy import path_exists, scenario_grid

    first, again, other = (maze_occupancy(seed, 10.0, 10.0, 0.1, 1.0, 0.0) for seed in (4, 4, 5))
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    # Without shortcuts the doors are a spanning tree: every room reaches every other, one way.
    scenario = generate("maze", 0, difficulty=1.0)
    grid = scenario_grid(scenario, resolution=0.1, inflation=scenario.robot.bounding_radius)
    rooms = maze_rooms(10.0, 10.0, 0.1, 1.0)
    assert all(path_exists(grid, (*rooms[0], 0.0), tuple(room), 0.1) for room in rooms[1:])
    open_cells = int((maze_occupancy(0, 10.0, 10.0, 0.1, 1.0, 0.0) < 50).sum())
    assert int((maze_occupancy(0, 10.0, 10.0, 0.1, 1.0, 1.0) < 50).sum()) > open_cells  # loops open more walls
