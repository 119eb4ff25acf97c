"""A lower bound by branch and bound over visiting orders, each node certified by duality.

A node is a cyclic *sequence* of some of the regions (the depot, if any, is one of them). Any
tour enters every region; keeping one entry point per region of the sequence, in the order the
tour reaches them, gives a closed polyline no longer than the tour (triangle inequality) that
visits the sequence's regions in one cyclic order. So the shortest closed polyline visiting,
in the sequence's order, *convex supersets* ``C_i`` of those regions bounds every tour whose
restriction to them has that order. Inserting a further region at each position of the
sequence gives children that cover every such tour between them; the root is three regions
(one cyclic order, up to reversal, which leaves lengths alone).

The fixed-order problem ``min sum_i |p_(i+1) - p_i|, p_i in C_i`` is bounded by weak duality:
for any ``u_i`` with ``|u_i| <= 1``, ``|d| >= u . d`` gives

    ``sum_i |p_(i+1) - p_i| >= sum_i p_i . (u_(i-1) - u_i) >= sum_i min_(q in C_i) q . w_i``

with ``w_i = u_(i-1) - u_i``. Each ``C_i`` here is a convex polygon grown by a radius ``r_i``
(a disc is a point grown by its radius), so the minimum is ``min_v v . w_i - r_i |w_i|`` over
the polygon's vertices: a certificate that does not rely on the solver having converged. The
multipliers come from a primal-dual (Chambolle-Pock) iteration on the saddle problem.

A region's superset is the convex hull of its outer star (exact for a disc); for a star that
is not convex, when the node's point for it lies in the hull but outside the star, the node is
branched on which angular half of the star piece holds the tour's entry point.

The bound is the least certified value over the nodes not pruned when the search stops, so it
holds whenever it stops. Nodes whose certified value reaches the known tour length are pruned.
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString, Point, Polygon

from urpt_gcs.arrays import FloatArray
from urpt_gcs.bound._order_kernels import I64, _far_regions, _insert_all, _meets_star, solve_order
from urpt_gcs.bound.star_hull import in_star, is_disc, shape_hull, star_hull
from urpt_gcs.problem.regions import OuterStar

__all__ = ["OrderBound", "order_bound", "prepare"]

# Primal-dual iterations per node (the kernels' _CHECK_EVERY says how often the certificate
# is evaluated).
_NODE_ITERATIONS = 4000
# Regions tried for insertion at each branching (the farthest from the node's polyline).
_STRONG = 1
# Open nodes kept at most (memory); past it the search stops.
_MAX_OPEN = 250_000


class _Sets:
    """Convex supersets, numbered: per region its whole star's hull and, on demand, hulls of
    star pieces ``(region, first sector, sector count)``."""

    def __init__(
        self,
        stars: list[OuterStar | None],
        depot_xy: tuple[float, float] | None,
        shapes: list[Polygon | None] | None = None,
    ):
        self.stars = stars
        self.depot_xy = depot_xy
        self.shapes = shapes or [None] * len(stars)
        self.key: dict[tuple[int, int, int], int] = {}
        self.piece: list[tuple[int, int, int]] = []
        self.verts: list[FloatArray] = []
        self.radius: list[float] = []
        self.region_of = np.zeros(0, dtype=np.int64)
        # Regions from this one on are the depot's copies (order_bound's ``returns``).
        self.copies_from = len(stars)
        self._arrays: tuple[I64, FloatArray, FloatArray, FloatArray] | None = None
        for i in range(len(stars)):
            self.get(i, 0, self.sectors(i))

    def sectors(self, region: int) -> int:
        star = self.stars[region]
        return 1 if star is None else int(star.reach_m.size)

    def get(self, region: int, k0: int, count: int) -> int:
        key = (region, k0, count)
        if key in self.key:
            return self.key[key]
        star = self.stars[region]
        if star is None:
            assert self.depot_xy is not None
            verts, r = np.asarray([self.depot_xy], dtype=np.float64), 0.0
        elif self.shapes[region] is not None:
            verts, r = shape_hull(self.shapes[region], star, k0, count)
        elif is_disc(star):
            verts, r = np.asarray([star.center_xy], dtype=np.float64), float(star.reach_m[0])
        else:
            verts, r = star_hull(star, k0, count), 0.0
        self.key[key] = len(self.piece)
        self.piece.append(key)
        self.verts.append(verts)
        self.radius.append(r)
        self.region_of = np.append(self.region_of, region)
        self._arrays = None
        return self.key[key]

    def holds(self, region: int, x: float, y: float, slack: float) -> bool:
        """Whether the region's star (or shape) holds the point, to ``slack``."""
        shape, star = self.shapes[region], self.stars[region]
        if shape is not None:
            return bool(shape.distance(Point(x, y)) <= slack)
        return star is None or in_star(star, x, y, slack)

    def met_by(self, region: int, px: FloatArray, py: FloatArray, slack: float) -> bool:
        """Whether the closed polyline through ``p`` meets the region's star (or shape)."""
        shape, star = self.shapes[region], self.stars[region]
        if shape is not None:
            ring = LineString(np.column_stack([np.append(px, px[0]), np.append(py, py[0])]))
            return bool(shape.distance(ring) <= slack)
        if star is None or is_disc(star):
            return True
        return bool(_meets_star(px, py, *star.center_xy, star.reach_m, slack))

    def arrays(self) -> tuple[I64, FloatArray, FloatArray, FloatArray]:
        if self._arrays is None:
            ptr = np.zeros(len(self.verts) + 1, dtype=np.int64)
            np.cumsum([len(v) for v in self.verts], out=ptr[1:])
            flat = np.vstack(self.verts)
            self._arrays = (
                ptr,
                np.ascontiguousarray(flat[:, 0]),
                np.ascontiguousarray(flat[:, 1]),
                np.asarray(self.radius, dtype=np.float64),
            )
        return self._arrays


@dataclass(frozen=True, slots=True)
class OrderBound:
    """The least certified value over the search's open ends, and how far it went."""

    value: float
    nodes: int
    open_nodes: int
    finished: bool
    seconds: float
    # The shortest closed polyline met that meets every set searched (the stars, or the
    # shapes where given; when the search met none, one a dive found): a real tour when
    # those are the regions themselves.
    leaf_length: float = math.inf
    # That polyline's points, in order.
    leaf_xy: FloatArray | None = None


@dataclass(slots=True)
class _Node:
    seq: I64  # set ids in cyclic order
    px: FloatArray
    py: FloatArray
    ux: FloatArray
    uy: FloatArray
    cert: float
    primal: float


def order_bound(
    stars: list[OuterStar | None],
    depot_xy: tuple[float, float] | None,
    upper: float,
    time_limit_s: float,
    gap_target: float = 1e-4,
    shapes: list[Polygon | None] | None = None,
    max_nodes: int | None = None,
    strong: int | None = None,
    returns: int = 0,
) -> OrderBound:
    """A lower bound of every closed tour entering every star (``None``: the depot point).

    ``shapes[i]``, where given, is region ``i`` itself (inside its star): its pieces are then
    hulls of the shape, not of the star. The search stops when its bound reaches
    ``upper * (1 - gap_target)``, when the open nodes reach (to half the gap target) the
    least value closed -- a polyline met that meets every set, or a pruned node -- past
    which the bound cannot rise, when nothing is left open, or at the time limit; the bound
    holds in every case (``finished`` in the first three). ``max_nodes`` also stops it after
    that many node solves; ``strong`` is how many regions each branching tries.

    ``returns`` (with a depot, the last star): the tours pass through the depot that many
    times more, as sorties from home joined at home do, ``returns + 1`` sorties at least.
    The depot's copies are regions of the sequence like the others, each a point; one that
    is missing is inserted before any other region (the lowest numbered first: they are
    interchangeable), at every position, two copies side by side allowed (an empty
    sortie), so the children still cover every such tour."""
    started = time.perf_counter()
    if returns > 0:
        if depot_xy is None or stars[-1] is not None:
            raise ValueError("order_bound: returns need the depot, as the last star")
        stars = [*stars, *([None] * returns)]
        if shapes is not None:
            shapes = [*shapes, *([None] * returns)]
    m = len(stars)
    if m <= 1:
        return OrderBound(0.0, 0, 0, True, 0.0)
    sets = _Sets(stars, depot_xy, shapes)
    sets.copies_from = m - returns
    cx = np.asarray([s.center_xy[0] if s else depot_xy[0] for s in stars])  # type: ignore[index]
    cy = np.asarray([s.center_xy[1] if s else depot_xy[1] for s in stars])  # type: ignore[index]
    cr = np.asarray([float(s.reach_m.max()) if s else 0.0 for s in stars])
    scale = float(np.abs(cx).max() + np.abs(cy).max() + cr.max() + 1.0)
    spread = float(np.hypot(cx - cx.mean(), cy - cy.mean()).mean() + cr.mean())
    step = max(0.15 * spread, 1e-9)
    prune_at = upper * (1.0 - 0.5 * gap_target)

    # The root: three regions far apart (the depot first, when there is one).
    first = (
        [m - 1 - returns]
        if depot_xy is not None
        else [int(np.argmax(np.hypot(cx - cx.mean(), cy - cy.mean()) + cr))]
    )
    while len(first) < min(3, m):
        gap = np.min([np.hypot(cx - cx[j], cy - cy[j]) - cr - cr[j] for j in first], axis=0)
        gap[first] = -np.inf
        gap[sets.copies_from :] = -np.inf
        first.append(int(np.argmax(gap)))
    seq = np.asarray([j for j in first], dtype=np.int64)
    root = _Node(
        seq, cx[seq].copy(), cy[seq].copy(), np.zeros(len(seq)), np.zeros(len(seq)), 0.0, 0.0
    )
    _solve(root, sets, step, prune_at, scale)

    closed = math.inf  # the least certified value of the nodes taken out for good
    heap: list[tuple[float, int, _Node]] = []
    counter = 0
    nodes = 1
    if root.cert >= prune_at:
        closed = root.cert
    else:
        heap.append((root.cert, 0, root))
    finished = True
    done = False  # stopped where searching on cannot raise the bound enough, nodes still open
    leaf = math.inf
    leaf_node: _Node | None = None
    while heap:
        # The bound is the least of the values closed and the open nodes': once the open
        # nodes reach the least closed (a polyline met that meets every set: the relaxation
        # is solved), searching on cannot raise it.
        if heap[0][0] >= min(prune_at, closed * (1.0 - 0.5 * gap_target)):
            done = True
            break
        over = max_nodes is not None and nodes >= max_nodes
        if over or time.perf_counter() - started >= time_limit_s or len(heap) >= _MAX_OPEN:
            finished = False
            break
        _, _, node = heapq.heappop(heap)
        ways = _branch(node, sets, m, _STRONG if strong is None else strong)
        if ways is None:
            # Every region met: this node's value bounds all its completions.
            closed = min(closed, node.cert)
            if node.primal < leaf:
                leaf, leaf_node = node.primal, node
            continue
        for way in ways:
            for child in way:
                _solve(child, sets, step, prune_at, scale)
            nodes += len(way)
        # Any way is a valid branching: take the one whose weakest child is strongest.
        children = max(ways, key=lambda w: min((c.cert for c in w), default=math.inf))
        for child in children:
            if child.cert >= prune_at:
                closed = min(closed, child.cert)
            else:
                counter += 1
                heapq.heappush(heap, (child.cert, counter, child))
    open_low = heap[0][0] if heap else math.inf
    value = min(closed, open_low, upper)
    if leaf_node is None and heap:
        # The dive may overrun the time limit by a quarter of it at most.
        deadline = max(started + time_limit_s, time.perf_counter()) + _DIVE_SHARE * time_limit_s
        leaf_node = _dive(heap[0][2], sets, m, step, scale, deadline)
        leaf = math.inf if leaf_node is None else leaf_node.primal
    seconds = time.perf_counter() - started
    leaf_xy = None if leaf_node is None else np.column_stack([leaf_node.px, leaf_node.py])
    return OrderBound(
        max(value, 0.0), nodes, len(heap), done or (finished and not heap), seconds, leaf,
        leaf_xy,
    )  # fmt: skip


# Node solves a dive for a polyline meeting every set may take at most (a dive inserts
# one region a step, a child per position: it is for a few tens of regions).
_DIVE_SOLVES = 400
_DIVE_SHARE = 0.25


def _dive(
    node: _Node, sets: _Sets, m: int, step: float, scale: float, deadline: float
) -> _Node | None:
    """From an open node, always into the child with the shortest polyline, until one meets
    every set (None when the dive's budget or ``deadline`` runs out first): a polyline for a
    tour to be read off when the search stopped before meeting one. It bounds nothing."""
    solves = 0
    while solves < _DIVE_SOLVES and time.perf_counter() < deadline:
        ways = _branch(node, sets, m, 1)
        if ways is None:
            return node
        children = ways[0]
        if not children or solves + len(children) > _DIVE_SOLVES:
            return None
        for child in children:
            if time.perf_counter() >= deadline:
                return None
            _solve(child, sets, step, math.inf, scale)
        solves += len(children)
        node = min(children, key=lambda c: c.primal)
    return None


def _solve(node: _Node, sets: _Sets, step: float, prune_at: float, scale: float) -> None:
    vptr, vx, vy, rad = sets.arrays()
    primal, cert = solve_order(
        node.seq, node.px, node.py, node.ux, node.uy, vptr, vx, vy, rad,
        step, prune_at, scale, _NODE_ITERATIONS,
    )  # fmt: skip
    node.primal, node.cert = primal, cert


def _branch(node: _Node, sets: _Sets, m: int, strong: int) -> list[list[_Node]] | None:
    """Ways to branch a node (each a list of children that cover its completions between
    them; up to ``strong`` regions to insert), or None when its polyline meets every set."""
    absent = np.ones(m, dtype=np.bool_)
    absent[sets.region_of[node.seq]] = False
    copies = np.flatnonzero(absent[sets.copies_from :])
    if copies.size:
        # The depot's copies first: the polyline meets the depot already, but must pass it
        # once more for each.
        return [_insertions(node, sets.copies_from + int(copies[0]), sets)]
    if sets.copies_from < m:
        # Two passes through the depot side by side: an empty sortie, which the shortest
        # flight does not fly (it would drop it). Some region not yet in the sequence comes
        # between them; a child for each, the first there (none left: no completion).
        home = sets.region_of[node.seq] >= sets.copies_from - 1
        side_by_side = np.flatnonzero(home & np.roll(home, -1))
        if side_by_side.size:
            between = np.flatnonzero(absent[: sets.copies_from - 1])
            at = int(side_by_side[0])
            return [[_insertion(node, int(j), at, sets) for j in between]]
    slack = 1e-9 * (1.0 + abs(node.primal))
    vptr, vx, vy, rad = sets.arrays()
    missing = np.flatnonzero(absent)
    if missing.size:
        dist = np.empty(missing.size)
        _far_regions(node.px, node.py, missing, vptr, vx, vy, rad, dist)
        far = np.argsort(-dist)[:strong]
        far = far[dist[far] > 1e-9 * (1.0 + abs(node.primal))]
        if far.size:
            return [_insertions(node, int(missing[f]), sets) for f in far]
        # The polyline meets every hull; a star it misses all the same (a crescent's notch).
        for j in missing:
            if not sets.met_by(int(j), node.px, node.py, slack):
                return [_insertions(node, int(j), sets)]
    # A point in its piece's hull but outside the star: split that piece.
    for pos, s in enumerate(node.seq):
        region, k0, count = sets.piece[int(s)]
        star = sets.stars[region]
        if star is None or count <= 1 or (is_disc(star) and sets.shapes[region] is None):
            continue
        if sets.holds(region, float(node.px[pos]), float(node.py[pos]), slack):
            continue
        half = count // 2
        out = []
        for a, c in ((k0, half), ((k0 + half) % sets.sectors(region), count - half)):
            child = _copy(node)
            child.seq[pos] = sets.get(region, a, c)
            if len(sets.verts[int(child.seq[pos])]):
                out.append(child)
        return [out]
    return None


def _copy(node: _Node) -> _Node:
    return _Node(
        node.seq.copy(),
        node.px.copy(),
        node.py.copy(),
        node.ux.copy(),
        node.uy.copy(),
        node.cert,
        node.primal,
    )


def _insertion(node: _Node, region: int, after: int, sets: _Sets) -> _Node:
    """The child inserting ``region`` after position ``after`` of the node's sequence."""
    return _insertions(node, region, sets)[after]


def _insertions(node: _Node, region: int, sets: _Sets) -> list[_Node]:
    """The children inserting ``region`` after each position of the node's sequence."""
    s = sets.get(region, 0, sets.sectors(region))
    vptr, vx, vy, rad = sets.arrays()
    seq, px, py, ux, uy = _insert_all(
        node.seq, node.px, node.py, node.ux, node.uy, s, vptr, vx, vy, rad
    )
    return [
        _Node(seq[c], px[c], py[c], ux[c], uy[c], node.cert, node.primal)
        for c in range(node.seq.size)
    ]


def prepare() -> None:
    """Compile the search's kernels (cached on disk) on a tiny instance, so that a first
    bound's time limit is not spent compiling."""
    disc = OuterStar((0.0, 0.0), np.ones(8))
    notch = OuterStar((5.0, 0.0), np.asarray([1.0, 1.0, 0.2, 1.0, 1.0, 1.0, 1.0, 1.0]))
    order_bound([disc, notch, None], (0.0, 5.0), 1e9, 1.0, max_nodes=20)
