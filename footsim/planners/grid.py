"""Grid costmap and grid searches shared by both baselines.

* ``Costmap``: an occupancy grid built from a scene's circular obstacles (the known map, as the
  thesis's global costmap), inflated by the robot's footprint radius plus an inflation margin
  with ``scipy.ndimage.distance_transform_edt`` (navigation2's obstacle + inflation layers).
* ``plan_path``: A*, Theta* or Lazy Theta* (any-angle A*, thesis 4.2) on the 8-connected grid,
  with line of sight checked on the inflated grid.  A start or goal inside the inflated area is
  connected to its nearest free cell, so the robot can always leave or reach a pose the
  sampler put close to an obstacle (the goal sits 0.125 m from the ball's surface).
* ``distance_to_goal_map``: 2D Dijkstra distance (8-connected, scipy's csgraph) from the goal
  over the free cells, the footstep planner's heuristic.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from footsim.scene import Obstacle

SQRT2 = math.sqrt(2.0)
_NEIGHBOURS = (
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, SQRT2),
    (1, -1, SQRT2),
    (-1, 1, SQRT2),
    (-1, -1, SQRT2),
)


@dataclass
class Costmap:
    """An inflated occupancy grid over a rectangle; cell (i, j) is x index i, y index j.

    ``clearance[i, j]``: distance [m] from the cell centre to the nearest obstacle surface
    (half a cell accuracy); ``blocked``: clearance < ``inflated_radius``.
    """

    origin: tuple[float, float]  # world (x, y) of cell (0, 0)'s centre
    resolution: float
    clearance: np.ndarray
    inflated_radius: float

    def __post_init__(self) -> None:
        self.blocked = self.clearance < self.inflated_radius
        self.shape = self.clearance.shape
        self._nearest_free: np.ndarray | None = None
        self._flat: list[bool] | None = None

    @classmethod
    def from_obstacles(
        cls,
        obstacles: tuple[Obstacle, ...],
        points: list[tuple[float, float]],
        resolution: float = 0.05,
        inflated_radius: float = 0.2,
        margin: float = 1.0,
    ) -> Costmap:
        """Grid covering ``points`` (start, goal, …) and the obstacles, plus ``margin`` metres.

        The circles are rasterised (cells whose centre lies inside) and the clearance is the
        Euclidean distance transform of the free cells (``scipy.ndimage.distance_transform_edt``)
        less half a cell, the rasterisation error.
        """
        if not (resolution > 0 and math.isfinite(resolution)):
            raise ValueError(f"costmap resolution must be > 0, got {resolution!r}")
        xs = [p[0] for p in points] + [o.x for o in obstacles]
        ys = [p[1] for p in points] + [o.y for o in obstacles]
        x0, y0 = min(xs) - margin, min(ys) - margin
        nx = int(math.ceil((max(xs) + margin - x0) / resolution)) + 1
        ny = int(math.ceil((max(ys) + margin - y0) / resolution)) + 1
        if not obstacles:
            return cls((x0, y0), resolution, np.full((nx, ny), np.inf), inflated_radius)
        gx = x0 + resolution * np.arange(nx)
        gy = y0 + resolution * np.arange(ny)
        occupied = np.zeros((nx, ny), dtype=bool)
        for o in obstacles:
            occupied |= (gx[:, None] - o.x) ** 2 + (gy[None, :] - o.y) ** 2 <= o.r * o.r
            occupied[
                min(max(int(round((o.x - x0) / resolution)), 0), nx - 1),
                min(max(int(round((o.y - y0) / resolution)), 0), ny - 1),
            ] = True  # thin ones too
        costmap = cls.from_mask(occupied, (x0, y0), resolution, inflated_radius)
        return costmap

    @classmethod
    def from_mask(
        cls, occupied: np.ndarray, origin: tuple[float, float], resolution: float, inflated_radius: float
    ) -> Costmap:
        """From an occupancy mask (True = obstacle): clearance by ``distance_transform_edt``."""
        occupied = np.asarray(occupied, dtype=bool)
        clearance = np.maximum(ndimage.distance_transform_edt(~occupied) * resolution - 0.5 * resolution, 0.0)
        clearance[occupied] = 0.0
        return cls(origin, resolution, clearance, inflated_radius)

    # -- coordinates ------------------------------------------------------------------------
    def cell(self, x: float, y: float) -> tuple[int, int]:
        i = int(round((x - self.origin[0]) / self.resolution))
        j = int(round((y - self.origin[1]) / self.resolution))
        return min(max(i, 0), self.shape[0] - 1), min(max(j, 0), self.shape[1] - 1)

    def world(self, i: float, j: float) -> tuple[float, float]:
        return self.origin[0] + i * self.resolution, self.origin[1] + j * self.resolution

    def inside(self, x: float, y: float) -> bool:
        i = (x - self.origin[0]) / self.resolution
        j = (y - self.origin[1]) / self.resolution
        return -0.5 <= i <= self.shape[0] - 0.5 and -0.5 <= j <= self.shape[1] - 0.5

    def nearest_free(self, cell: tuple[int, int]) -> tuple[int, int] | None:
        """The nearest unblocked cell (itself when free); None when the whole grid is blocked."""
        if not self.blocked[cell]:
            return cell
        if self.blocked.all():
            return None
        if self._nearest_free is None:
            _, self._nearest_free = ndimage.distance_transform_edt(self.blocked, return_indices=True)
        return int(self._nearest_free[0][cell]), int(self._nearest_free[1][cell])

    # -- line of sight ----------------------------------------------------------------------
    def line_of_sight(self, a: tuple[int, int], b: tuple[int, int]) -> bool:
        """No blocked cell touched by the segment between the centres of cells a and b.

        Amanatides–Woo grid traversal (every cell the segment passes through; at an exact corner
        crossing both side cells count), in plain Python: lines are short and numpy's per-call
        overhead would dominate.
        """
        if self._flat is None:
            self._flat = self.blocked.ravel().tolist()
        flat, ny = self._flat, self.shape[1]
        i, j = a
        if flat[i * ny + j]:
            return False
        di, dj = b[0] - i, b[1] - j
        n = abs(di) + abs(dj)
        si, sj = (1 if di > 0 else -1), (1 if dj > 0 else -1)
        # Parametric distances (scaled by |di|·|dj| to stay in integers) to the next cell borders.
        adi, adj = abs(di), abs(dj)
        ti: float
        tj: float
        ti, tj = adj, adi  # = 0.5 / |d| scaled by 2|di||dj|
        step_i, step_j = 2 * adj, 2 * adi
        if adi == 0:
            ti = math.inf
        if adj == 0:
            tj = math.inf
        while n > 0:
            if ti < tj:
                i += si
                ti += step_i
                n -= 1
            elif tj < ti:
                j += sj
                tj += step_j
                n -= 1
            else:  # through a corner: both neighbours must be free
                if flat[(i + si) * ny + j] or flat[i * ny + j + sj]:
                    return False
                i += si
                j += sj
                ti += step_i
                tj += step_j
                n -= 2
            if flat[i * ny + j]:
                return False
        return True


@dataclass
class GridPath:
    cells: list[tuple[int, int]]
    points: np.ndarray  # (n, 2) world coordinates, start and goal exact
    length: float  # [m]
    expanded: int
    algorithm: str


def _octile(a, b) -> float:
    dx, dy = abs(a[0] - b[0]), abs(a[1] - b[1])
    return (SQRT2 - 1.0) * min(dx, dy) + max(dx, dy)


def _euclid(a, b) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def grid_search(
    costmap: Costmap,
    start: tuple[int, int],
    goal: tuple[int, int],
    algorithm: str = "theta_star",
    max_expansions: int = 200_000,
) -> tuple[list[tuple[int, int]] | None, int]:
    """A* (``astar``), Theta* (``theta_star``) or Lazy Theta* (``lazy_theta_star``) between free cells.

    Returns ``(cells from start to goal or None, expansions)``.  Costs in cells; Theta* variants
    use the Euclidean heuristic, A* the octile one (both consistent).
    """
    if algorithm not in ("astar", "theta_star", "lazy_theta_star"):
        raise ValueError(f"unknown grid planner {algorithm!r}; valid: astar, theta_star, lazy_theta_star")
    blocked = costmap.blocked
    if blocked[start] or blocked[goal]:
        return None, 0
    nx, ny = blocked.shape
    heur = _octile if algorithm == "astar" else _euclid
    los = costmap.line_of_sight
    g = {start: 0.0}
    parent = {start: start}
    closed = set()
    counter = 0
    open_heap = [(heur(start, goal), counter, start)]
    expanded = 0
    lazy = algorithm == "lazy_theta_star"
    while open_heap:
        _, _, s = heapq.heappop(open_heap)
        if s in closed:
            continue
        if lazy and parent[s] != s and not los(parent[s], s):
            # Lazy Theta*: the assumed line of sight failed; take the best closed neighbour.
            best, best_g = None, math.inf
            for di, dj, c in _NEIGHBOURS:
                n = (s[0] + di, s[1] + dj)
                if n in closed and g[n] + c < best_g:
                    best, best_g = n, g[n] + c
            assert best is not None  # the cell whose expansion queued s is a closed neighbour
            parent[s], g[s] = best, best_g
        closed.add(s)
        expanded += 1
        if s == goal:
            break
        if expanded > max_expansions:
            return None, expanded
        gs, ps = g[s], parent[s]
        for di, dj, c in _NEIGHBOURS:
            n = (s[0] + di, s[1] + dj)
            if not (0 <= n[0] < nx and 0 <= n[1] < ny) or blocked[n] or n in closed:
                continue
            if algorithm == "astar":
                cand_g, cand_p = gs + c, s
            elif lazy:
                cand_g, cand_p = g[ps] + _euclid(ps, n), ps
            elif ps != s and los(ps, n):
                cand_g, cand_p = g[ps] + _euclid(ps, n), ps
            else:
                cand_g, cand_p = gs + c, s
            if cand_g < g.get(n, math.inf) - 1e-12:
                g[n], parent[n] = cand_g, cand_p
                counter += 1
                heapq.heappush(open_heap, (cand_g + heur(n, goal), counter, n))
    else:
        return None, expanded
    if goal not in closed:
        return None, expanded
    cells = [goal]
    while cells[-1] != start:
        cells.append(parent[cells[-1]])
    cells.reverse()
    return cells, expanded


def plan_path(
    costmap: Costmap, start_xy: tuple[float, float], goal_xy: tuple[float, float], algorithm: str = "theta_star"
) -> GridPath | None:
    """Plan between world points; start/goal inside the inflated area go via their nearest free cell."""
    s_cell, g_cell = costmap.cell(*start_xy), costmap.cell(*goal_xy)
    s_free, g_free = costmap.nearest_free(s_cell), costmap.nearest_free(g_cell)
    if s_free is None or g_free is None:
        return None
    cells, expanded = grid_search(costmap, s_free, g_free, algorithm)
    if cells is None:
        return None
    pts: list[tuple[float, ...]] = [costmap.world(*c) for c in cells]
    pts[0] = tuple(start_xy) if s_free == s_cell else pts[0]
    if s_free != s_cell:
        pts.insert(0, tuple(start_xy))
    if g_free != g_cell:
        pts.append(tuple(goal_xy))
    else:
        pts[-1] = tuple(goal_xy)
    points = np.asarray(pts, dtype=float)
    length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0
    return GridPath(cells, points, length, expanded, algorithm)


def densify(points: np.ndarray, spacing: float) -> np.ndarray:
    """Resample a polyline at ``spacing`` (the path points a carrot counts ahead along)."""
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return points.copy()
    out = [points[0]]
    for a, b in zip(points[:-1], points[1:]):
        seg = float(np.hypot(*(b - a)))
        n = max(int(math.ceil(seg / spacing)), 1)
        for k in range(1, n + 1):
            out.append(a + (b - a) * (k / n))
    return np.asarray(out)


def cell_path_length(costmap: Costmap, cells: list[tuple[int, int]]) -> float:
    return sum(_euclid(a, b) for a, b in zip(cells[:-1], cells[1:])) * costmap.resolution


def distance_to_goal_map(costmap: Costmap, goal_xy: tuple[float, float]) -> np.ndarray:
    """Shortest 8-connected distance [m] from every cell to the goal over free cells (inf: unreachable).

    The goal cell (or, when it is blocked, its nearest free cell) is the source.
    """

    nx, ny = costmap.shape
    free = ~costmap.blocked
    idx = np.arange(nx * ny).reshape(nx, ny)
    rows, cols, weights = [], [], []
    for di, dj, c in _NEIGHBOURS[::2]:  # (1, 0), (0, 1), (1, 1), (-1, 1): one direction per pair
        sa = (slice(max(0, -di), nx - max(0, di)), slice(max(0, -dj), ny - max(0, dj)))
        sb = (slice(max(0, di), nx + min(0, di)), slice(max(0, dj), ny + min(0, dj)))
        ok = free[sa] & free[sb]
        ia, ib = idx[sa][ok], idx[sb][ok]
        rows.append(ia)
        cols.append(ib)
        weights.append(np.full(ia.size, c * costmap.resolution))
    graph = coo_matrix(
        (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(nx * ny, nx * ny)
    ).tocsr()
    g_cell = costmap.nearest_free(costmap.cell(*goal_xy))
    if g_cell is None:
        return np.full((nx, ny), np.inf)
    dist = dijkstra(graph, directed=False, indices=int(idx[g_cell]))
    return dist.reshape(nx, ny)
