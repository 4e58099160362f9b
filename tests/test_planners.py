"""Planners on grids with known answers, the scan-built grid against a known world."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage, sparse
from scipy.sparse import csgraph

from common.controllers.base import LidarGeometry
from common.generators import generate
from common.occupancy import OccupancyGrid, ScanMapper, inflate, scenario_grid
from common.planners import PLANNERS, RRT, AStar, path_length, shortcut
from common.planners.rrt import _bin, _nearest_k
from common.scenario import BoxObstacle, LidarSpec, Scenario
from flatland.world import World

SQRT2 = math.sqrt(2.0)


def open_grid(rows: int = 20, cols: int = 20, resolution: float = 0.5) -> OccupancyGrid:
    return OccupancyGrid(np.zeros((rows, cols), dtype=bool), (0.0, 0.0), resolution)


def centre(grid: OccupancyGrid, row: int, col: int) -> tuple[float, float]:
    return grid.centre_of(row, col)


def walled(gap_rows: int = 2) -> OccupancyGrid:
    """10 × 10 cells of 1 m with a wall at column 5, open only in the top ``gap_rows`` rows."""
    occupied = np.zeros((10, 10), dtype=bool)
    occupied[: 10 - gap_rows, 5] = True
    return OccupancyGrid(occupied, (0.0, 0.0), 1.0)


def assert_stays_free(grid: OccupancyGrid, path: np.ndarray, spacing: float | None = None) -> None:
    """Every point sampled densely along the path lies on the grid in a free cell."""
    spacing = spacing or grid.resolution / 20
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, math.ceil(np.hypot(*(b - a)) / spacing))
        for t in np.linspace(0.0, 1.0, n + 1):
            x, y = a + t * (b - a)
            assert grid.is_free(x, y), f"({x:.3f}, {y:.3f}) on segment {a} -> {b} is not free"


def dijkstra_length(grid: OccupancyGrid, start: tuple[int, int], goal: tuple[int, int]) -> float:
    """Shortest 8-connected, no-corner-cutting length between two cells, by scipy's Dijkstra."""
    occ = grid.occupied
    rows, cols = occ.shape
    src, dst, cost = [], [], []
    for r in range(rows):
        for c in range(cols):
            if occ[r, c]:
                continue
            for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)):
                nr, nc = r + dr, c + dc
                if not (0 <= nr < rows and 0 <= nc < cols) or occ[nr, nc]:
                    continue
                if dr and dc and (occ[r + dr, c] or occ[r, c + dc]):
                    continue
                src.append(r * cols + c)
                dst.append(nr * cols + nc)
                cost.append(math.hypot(dr, dc))
    graph = sparse.csr_matrix((cost, (src, dst)), shape=(rows * cols, rows * cols))
    return float(csgraph.dijkstra(graph, indices=start[0] * cols + start[1])[goal[0] * cols + goal[1]]) * grid.resolution


# A*


def test_astar_straight_line_is_the_row_of_centres():
    grid = open_grid()
    path = AStar().plan(grid, centre(grid, 2, 2), centre(grid, 2, 12))
    assert path is not None
    assert path_length(path) == pytest.approx(10 * grid.resolution)
    assert np.allclose(path[:, 1], centre(grid, 2, 2)[1])


def test_astar_diagonal_length_is_the_8_connected_optimum():
    grid = open_grid()
    path = AStar().plan(grid, centre(grid, 1, 1), centre(grid, 6, 9))
    dr, dc = 5, 8
    assert path_length(path) == pytest.approx(((dc - dr) + dr * SQRT2) * grid.resolution)


def test_astar_four_connected_length_is_manhattan():
    grid = open_grid()
    path = AStar(allow_diagonal=False).plan(grid, centre(grid, 1, 1), centre(grid, 6, 9))
    assert path_length(path) == pytest.approx(13 * grid.resolution)
    steps = np.abs(np.diff(path, axis=0))
    assert np.all((steps < 1e-9).any(axis=1))  # every move is along a row or a column


def test_astar_goes_round_a_wall_without_cutting_its_corner():
    grid = walled()
    path = AStar().plan(grid, centre(grid, 0, 2), centre(grid, 0, 8))
    # (0,2) -> (8,4) is 2 diagonals + 6 straight; then (8,4) -> (8,5) -> (8,6) straight, because a
    # diagonal past (7,5) would cut the wall's corner; then (8,6) -> (0,8) mirrors the first leg.
    assert path_length(path) == pytest.approx(2 * (6 + 2 * SQRT2) + 2)
    assert_stays_free(grid, path)


@pytest.mark.parametrize("seed", range(5))
def test_astar_matches_dijkstra_on_random_grids(seed):
    rng = np.random.default_rng(seed)
    grid = OccupancyGrid(rng.random((15, 18)) < 0.3, (-1.0, 2.0), 0.25)
    free = np.argwhere(~grid.occupied)
    for _ in range(10):
        a, b = free[rng.integers(len(free), size=2)]
        expected = dijkstra_length(grid, tuple(a), tuple(b))
        path = AStar().plan(grid, centre(grid, *a), centre(grid, *b))
        if math.isinf(expected):
            assert path is None
        else:
            assert path is not None and path_length(path) == pytest.approx(expected)
            assert_stays_free(grid, path)


def test_astar_path_keeps_exact_ends_and_same_cell_plan():
    grid = open_grid()
    start, goal = (1.13, 2.71), (7.42, 4.05)
    path = AStar().plan(grid, start, goal)
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert np.allclose(AStar().plan(grid, (1.1, 1.1), (1.3, 1.4)), [(1.1, 1.1), (1.3, 1.4)])


def test_astar_no_path_when_walled_off_or_ends_blocked():
    grid = walled(gap_rows=0)
    assert AStar().plan(grid, centre(grid, 0, 2), centre(grid, 0, 8)) is None
    assert AStar().plan(grid, centre(grid, 3, 5), centre(grid, 0, 8)) is None  # start occupied
    assert AStar().plan(grid, centre(grid, 0, 2), centre(grid, 3, 5)) is None  # goal occupied
    assert AStar().plan(grid, (-0.5, 1.0), centre(grid, 0, 2)) is None  # start off the grid
    assert AStar().plan(grid, centre(grid, 0, 2), (3.0, 10.0)) is None  # goal off the grid


def test_astar_never_enters_occupied_cells_on_a_warehouse():
    scenario = generate("warehouse", seed=3, difficulty=1.0)
    grid = scenario_grid(scenario)
    free = np.argwhere(grid.free_component(*scenario.start[:2]))
    rng = np.random.default_rng(0)
    for _ in range(10):
        a, b = free[rng.integers(len(free), size=2)]
        path = AStar().plan(grid, centre(grid, *a), centre(grid, *b))
        assert path is not None
        assert_stays_free(grid, path)


# RRT


def test_rrt_finds_a_free_path_in_an_open_grid():
    grid = open_grid()
    planner = RRT(step_size=0.3, seed=1)
    path = planner.plan(grid, (1.0, 1.0), (9.0, 8.0))
    assert path is not None
    assert np.allclose(path[0], (1.0, 1.0)) and np.allclose(path[-1], (9.0, 8.0))
    assert np.all(np.hypot(*np.diff(path, axis=0).T) <= 0.3 + 1e-9)
    assert_stays_free(grid, path)


def test_rrt_goes_round_a_wall():
    occupied = np.zeros((50, 50), dtype=bool)
    occupied[:40, 24:26] = True  # x in [4.8, 5.2], y below 8 m
    grid = OccupancyGrid(occupied, (0.0, 0.0), 0.2)
    path = RRT(seed=0).plan(grid, (2.0, 2.0), (8.0, 2.0))
    assert path is not None
    assert path[:, 1].max() > 8.0
    assert_stays_free(grid, path, spacing=0.1)  # RRT's own check samples at half a cell


@pytest.mark.parametrize("optimise", [False, True])
def test_rrt_is_deterministic_per_seed(optimise):
    grid = walled()
    plan = lambda seed: RRT(step_size=0.5, seed=seed, optimise=optimise).plan(grid, centre(grid, 0, 2),
                                                                             centre(grid, 0, 8))
    first = plan(4)
    assert first is not None
    assert np.array_equal(first, plan(4))
    assert not np.array_equal(first, plan(5))
    shared = RRT(step_size=0.5, rng=np.random.default_rng(4), optimise=optimise)
    assert np.array_equal(first, shared.plan(grid, centre(grid, 0, 2), centre(grid, 0, 8)))


def test_an_optimising_rrt_comes_near_the_shortest_path_round_a_wall():
    grid = walled()
    start, goal = centre(grid, 0, 2), centre(grid, 0, 8)
    # Up to the wall's end (x 5 to 6 below y = 8), along it, and down.
    shortest = 2.0 * math.hypot(2.5, 7.5) + 1.0
    plain = [path_length(RRT(step_size=0.5, seed=seed).plan(grid, start, goal)) for seed in range(3)]
    best = [path_length(RRT(step_size=0.5, seed=seed, optimise=True).plan(grid, start, goal)) for seed in range(3)]
    assert max(best) < 1.05 * shortest < min(plain)


def test_the_rrt_star_neighbour_bins_find_what_a_linear_scan_finds():
    rng = np.random.default_rng(0)
    x0, y0, side, rows, cols = -1.0, 2.0, 0.3, 12, 20
    nodes = np.column_stack([x0 + rng.random(300) * cols * side, y0 + rng.random(300) * rows * side])
    head, next_in_bin = np.full((rows, cols), -1, dtype=np.int64), np.empty(300, dtype=np.int64)
    for j, (x, y) in enumerate(nodes):
        _bin(head, next_in_bin, x0, y0, side, j, x, y)
    out, out_d = np.empty(300, dtype=np.int64), np.empty(300)
    queries = np.vstack([nodes[:5] + 0.01, rng.uniform((x0 - 3.0, y0 - 3.0), (x0 + 9.0, y0 + 7.0), (40, 2))])
    for qx, qy in queries:  # inside the binned area and beyond it
        d = np.hypot(nodes[:, 0] - qx, nodes[:, 1] - qy)
        for k, skip in ((1, -1), (1, int(np.argmin(d))), (25, -1)):
            found = _nearest_k(nodes, head, next_in_bin, x0, y0, side, qx, qy, k, skip, out, out_d)
            expected = [j for j in np.argsort(d) if j != skip][:k]
            assert found == k and out[:k].tolist() == expected
            assert np.allclose(out_d[:k], d[expected])


def test_rrt_no_path_when_walled_off_or_ends_blocked():
    grid = walled(gap_rows=0)
    rrt = RRT(step_size=0.5, max_iterations=2000, seed=0)
    assert rrt.plan(grid, centre(grid, 0, 2), centre(grid, 0, 8)) is None
    assert rrt.plan(grid, centre(grid, 3, 5), centre(grid, 0, 8)) is None
    assert rrt.plan(grid, centre(grid, 0, 2), (11.0, 0.5)) is None


def test_registry_planners_share_the_interface():
    grid = open_grid()
    for name, cls in PLANNERS.items():
        path = cls().plan(grid, (1.0, 1.0), (8.0, 6.0))
        assert cls.name == name
        assert path is not None and path.shape[1] == 2
        assert np.allclose(path[[0, -1]], [(1.0, 1.0), (8.0, 6.0)])


# Smoothing


def test_shortcut_straightens_a_zig_zag_in_the_open():
    grid = open_grid()
    zig = np.array([(1.0, 1.0), (2.0, 3.0), (3.0, 1.0), (4.0, 3.0), (5.0, 1.0)])
    assert np.allclose(shortcut(grid, zig), [(1.0, 1.0), (5.0, 1.0)])


def test_shortcut_is_shorter_and_stays_free_round_obstacles():
    grid = walled()
    path = RRT(step_size=0.5, seed=2).plan(grid, centre(grid, 0, 2), centre(grid, 0, 8))
    smooth = shortcut(grid, path)
    assert path_length(smooth) <= path_length(path) + 1e-9
    assert np.allclose(smooth[[0, -1]], path[[0, -1]])
    assert_stays_free(grid, smooth)

    scenario = generate("warehouse", seed=3, difficulty=1.0)
    grid = scenario_grid(scenario)
    path = AStar().plan(grid, scenario.start[:2], scenario.goal)
    smooth = shortcut(grid, path)
    assert len(smooth) < len(path) and path_length(smooth) < path_length(path)
    assert_stays_free(grid, smooth)


# Scan-built grids


def test_inflate_marks_the_disk_of_centres_within_the_radius():
    occupied = np.zeros((9, 9), dtype=bool)
    occupied[4, 4] = True
    disk = inflate(occupied, radius=0.4, resolution=0.2)  # two cells: 1 + 4 + 4 diagonals + 4 at distance 2
    assert disk.sum() == 13 and disk[4, 6] and not disk[5, 6]
    assert not inflate(np.zeros((3, 3), dtype=bool), 0.4, 0.2).any()


def test_inflate_marks_the_cells_a_distance_transform_puts_within_the_radius():
    """The disks stamped run by run mark exactly the cells whose distance transform (scipy's, the
    reference) is within the radius, radii that fall on a cell's distance included."""
    rng = np.random.default_rng(7)
    for _ in range(400):
        shape = tuple(int(n) for n in rng.integers(1, 30, 2))
        resolution = float(rng.choice([0.024, 0.05, 0.1, 0.2, 1 / 3]))
        occupied = rng.random(shape) < rng.choice([0.01, 0.05, 0.3, 0.9])
        radius = float(rng.choice([rng.uniform(0.0, 1.0), resolution * rng.integers(0, 6),
                                   resolution * np.sqrt(rng.integers(1, 30))]))
        expected = occupied.copy() if radius <= 0.0 or not occupied.any() else \
            ndimage.distance_transform_edt(~occupied, sampling=resolution) <= radius + 1e-9
        assert np.array_equal(inflate(occupied, radius, resolution), expected), (shape, resolution, radius)


def test_scan_mapper_marks_a_known_obstacle_and_not_free_space():
    box = BoxObstacle(x=5.0, y=5.0, length=1.0, width=1.0)
    scenario = Scenario(lidar=LidarSpec(beams=360), start=(2.0, 5.0, 0.3), goal=(9.0, 9.0), obstacles=[box])
    readings = World(scenario).reset()
    mapper = ScanMapper.for_scenario(scenario)
    assert mapper.add_scan(LidarGeometry(scenario.lidar), readings.lidar, readings.pose) > 0
    res = mapper.resolution

    # The box's face towards the robot (x = 4.5, y in [4.5, 5.5]) is marked cell by cell.
    for y in np.arange(4.6, 5.41, res):
        assert mapper.observed[mapper.grid.cell_of(4.5, y)]
    # Every marked cell holds a point of the box or of a wall: its centre is within half a cell's diagonal.
    rows, cols = np.nonzero(mapper.observed)
    centres = np.column_stack([(cols + 0.5) * res, (rows + 0.5) * res])
    wall = np.minimum(np.minimum(centres[:, 0], 10.0 - centres[:, 0]), np.minimum(centres[:, 1], 10.0 - centres[:, 1]))
    assert np.all(np.minimum(box.sdf(centres), wall) <= res * SQRT2 / 2 + 1e-9)
    # Inflation by the robot radius reaches one cell out from the face, not three.
    assert not mapper.grid.is_free(4.5 - res, 5.0)
    assert mapper.grid.is_free(4.5 - 3 * res, 5.0)
    # Free space around the robot and away from everything stays free.
    for x, y in [(2.0, 5.0), (3.0, 3.0), (3.0, 7.0), (1.5, 8.0), (7.0, 8.0)]:
        assert mapper.grid.is_free(x, y)
    # A planner can use the scanned grid directly.
    assert AStar().plan(mapper.grid, (2.0, 5.0), (8.0, 5.0)) is not None


def test_scan_mapper_clamps_boundary_returns_and_drops_far_ones():
    mapper = ScanMapper((0.0, 0.0, 2.0, 1.0), resolution=0.5)
    used = mapper.add_points(np.array([[2.0, 0.2], [2.1, 0.7], [-0.8, 0.3], [5.0, 0.5], [1.0, -3.0]]))
    assert used == 2
    assert mapper.observed[0, 3] and mapper.observed[1, 3] and mapper.observed.sum() == 2
    mapper.reset()
    assert not mapper.grid.occupied.any()


def test_line_of_sight_catches_corner_clips_that_sampling_misses():
    from common.planners.base import grid_arrays
    from common.planners.collision import line_of_sight, segment_free_sampled

    occupied = np.zeros((4, 4), dtype=bool)
    occupied[2, 1] = True  # the cell [1, 2] x [2, 3] of a 1 m grid
    args = grid_arrays(OccupancyGrid(occupied, (0.0, 0.0), 1.0))
    clip = (0.6, 2.45, 1.45, 1.6)  # cuts the cell's lower-left corner, 5 cm in
    assert segment_free_sampled(*args, *clip)  # samples 0.4 m apart fall either side of the corner
    assert not line_of_sight(*args, *clip)
    assert not line_of_sight(*args, 0.5, 2.5, 1.5, 1.5)  # exactly through the corner: no cutting
    assert line_of_sight(*args, 0.5, 0.5, 3.5, 0.5)
    assert not line_of_sight(*args, 0.5, 0.5, 4.5, 0.5)  # leaves the grid


def test_a_grid_of_a_huge_world_is_coarsened_to_a_bounded_size():
    # A 69-byte scenario may ask for a 1 km world: at 0.1 m its grid alone would take gigabytes.
    from common.occupancy import MAX_CELLS, ScanMapper, scenario_grid
    from common.scenario import CircleObstacle, Scenario, WorldSpec

    huge = Scenario(world=WorldSpec(width=1000.0, height=1000.0), start=(1.0, 1.0, 0.0), goal=(9.0, 9.0),
                    obstacles=[CircleObstacle(x=500.0, y=500.0, radius=5.0)])
    grid = scenario_grid(huge, 0.1)
    assert grid.occupied.size <= MAX_CELLS and grid.resolution == pytest.approx(0.5)
    assert grid.occupied[1000, 1000] and not grid.occupied[100, 100]  # the obstacle still drawn, the rest free
    assert ScanMapper.for_scenario(huge, 0.1).hits.size <= MAX_CELLS
    assert scenario_grid(Scenario(), 0.1).resolution == 0.1  # ordinary worlds keep their resolution


def test_polygons_and_polylines_are_rasterised_where_their_distance_is_below_the_inflation():
    # The scanline raster must mark exactly the cells whose centres the obstacle's signed distance
    # puts within the inflation (inside a polygon counts), as the distance to every edge would.
    from common.occupancy import scenario_grid
    from common.scenario import PolygonObstacle, Scenario, SegmentObstacle, WorldSpec

    rng = np.random.default_rng(7)
    checked = 0
    for case in range(40):
        k = int(rng.integers(3, 40))
        angles = np.sort(rng.uniform(0, 2 * np.pi, k))
        radii = rng.uniform(0.5, 3.0, k)
        centre = rng.uniform(3.0, 7.0, 2)
        ring = np.column_stack([centre[0] + radii * np.cos(angles), centre[1] + radii * np.sin(angles)])
        if case % 2:
            try:
                obstacle = PolygonObstacle(vertices=[tuple(p) for p in (ring if case % 4 == 1 else ring[::-1])])
            except ValueError:  # a sliver the scenario refuses
                continue
        else:
            obstacle = SegmentObstacle(points=[tuple(p) for p in ring[: max(2, k // 2)]])
        resolution, inflation = float(rng.uniform(0.05, 0.3)), float(rng.choice([0.0, rng.uniform(0.05, 0.5)]))
        scenario = Scenario(world=WorldSpec(width=10.0, height=10.0, walls=False), obstacles=[obstacle],
                            start=(0.2, 0.2, 0.0), goal=(9.8, 9.8))
        grid = scenario_grid(scenario, resolution, inflation)
        rows, cols = grid.occupied.shape
        centres = np.array([[(c + 0.5) * resolution, (r + 0.5) * resolution] for r in range(rows) for c in range(cols)])
        distance = obstacle.sdf(centres).reshape(rows, cols)
        expected = distance < inflation
        ties = np.abs(distance - inflation) < 1e-9
        assert np.array_equal(grid.occupied[~ties], expected[~ties]), f"case {case}"
        checked += 1
    assert checked >= 30
