"""The older lower bound over pieces of the regions (``method="pieces"``, ``"exact"`` or
``"lagrangian"`` of :func:`urpt_gcs.bound.lower_bound.lower_bound`).

Each region's outer star (a set that contains it) is cut into *pieces*, annular sectors
``{c + s (cos t, sin t) : r0 <= s <= r1, t0 <= t <= t1}`` whose union covers the star, and the
depot is a piece of its own. A tour enters region ``i`` at some point, which lies in one of
``i``'s pieces; listing those points in the order the tour reaches them gives a closed
polyline no longer than the tour whose legs join pieces of consecutive regions. So, with
``c(P, Q)`` any lower bound of the distance between two pieces' points, the *relaxed*
problem -- pick one piece per region and a cyclic order, minimising the sum of ``c`` -- has
an optimum no longer than any tour. Here ``c(P, Q)`` is the larger of the distance between
the pieces' enclosing circles and that between their regions' enclosing discs, both less
than or equal to the distance between any point of ``P`` and any point of ``Q``.

The relaxed problem is a generalized TSP. Its bound:

- ``exact``: Held-Karp over (regions visited, last piece) -- the relaxed optimum itself; for
  a few regions only.
- ``lagrangian``: for multipliers ``mu`` on the pieces, every tour has
  ``sum c = sum_edges (c(P, Q) + mu_P + mu_Q) - 2 sum_i mu_(piece of i)``; replacing each
  edge's weight by its least value over the two regions' pieces and each ``mu`` of a chosen
  piece by its region's largest, and the cycle by a minimum 1-tree (a cycle is a 1-tree),
  only lowers it. That holds for every ``mu``; subgradient ascent picks good ones.

Between rounds the pieces where the bound's 1-tree sits are split in two, so the bound rises
where the tour is decided; that stops at the gap target, the time limit or a piece budget.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
import numpy.typing as npt

from urpt_gcs.arrays import FloatArray
from urpt_gcs.problem.regions import OuterStar, RegionSet

__all__ = [
    "EXACT_WORK",
    "ROUND_ITERATIONS",
    "Pieces",
    "Row",
    "exact_relaxed",
    "exact_work",
    "lagrangian",
    "near_lists",
    "piece_costs",
    "skipped_regions",
    "split",
    "star_discs",
    "start_pieces",
    "touches_boundary",
]

I64 = npt.NDArray[np.int64]

# Per region: the nearest regions whose piece pairs the Lagrangian weighs exactly.
_NEAR = 12
# Pieces per region at the start: sectors x radial bands.
_START_SECTORS = 8
_START_BANDS = 2
# Cap on the pieces over all regions (memory and time of a round grow with their square).
_MAX_PIECES_PER_REGION = 96
# Most work (starts x subsets x pieces^2) for one exact relaxed optimum.
EXACT_WORK = 3e8
# Subgradient iterations per round.
ROUND_ITERATIONS = 3000


@dataclass(frozen=True, slots=True)
class Pieces:
    """Annular sectors covering every region's outer star, sorted by region; the depot (if
    any) is region ``n`` with one point piece. Angles are radians in ``[0, 2 pi]``."""

    region: I64
    cx: FloatArray
    cy: FloatArray
    r0: FloatArray
    r1: FloatArray
    t0: FloatArray
    t1: FloatArray

    @property
    def n(self) -> int:
        return int(self.region.size)

    def circles(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """An enclosing circle per piece: centre at mid-radius and mid-angle, radius its
        distance to the farthest corner (or the whole disc for a sector wider than pi)."""
        tm = 0.5 * (self.t0 + self.t1)
        rm = 0.5 * (self.r0 + self.r1)
        mx = self.cx + rm * np.cos(tm)
        my = self.cy + rm * np.sin(tm)
        rho = np.zeros(self.n)
        for r in (self.r0, self.r1):
            for t in (self.t0, self.t1):
                px, py = self.cx + r * np.cos(t), self.cy + r * np.sin(t)
                rho = np.maximum(rho, np.hypot(px - mx, py - my))
        wide = (self.t1 - self.t0) > math.pi
        mx, my = np.where(wide, self.cx, mx), np.where(wide, self.cy, my)
        rho = np.where(wide, self.r1, rho)
        # A hair more than the exact figure, so that rounding cannot make a bound too large.
        return mx, my, rho * (1.0 + 1e-12) + 1e-12


def touches_boundary(regions: RegionSet) -> bool:
    """Whether every tour meets every region's boundary (bar the regions holding the depot).

    From a depot outside a region, a tour's first point in the (closed) region is on its
    boundary. Without a depot, a closed tour not inside region ``i`` meets its boundary, and
    no tour can be inside a region that misses another region altogether.
    """
    if regions.depot_xy is not None:
        return True
    cx, cy, cr = star_discs(regions)
    apart = np.hypot(cx[:, None] - cx[None, :], cy[:, None] - cy[None, :]) > cr[:, None] + cr
    return bool(apart.any(axis=1).all())


def star_discs(regions: RegionSet) -> tuple[FloatArray, FloatArray, FloatArray]:
    cx = np.asarray([s.center_xy[0] for s in regions.outer])
    cy = np.asarray([s.center_xy[1] for s in regions.outer])
    cr = np.asarray([float(s.reach_m.max()) for s in regions.outer])
    return cx, cy, cr


def skipped_regions(regions: RegionSet) -> npt.NDArray[np.bool_]:
    """Regions that hold the depot: every tour is in them, so the bound leaves them out."""
    if regions.depot_xy is None:
        return np.zeros(regions.n, dtype=np.bool_)
    if regions.depot_inside is not None:
        return np.asarray(regions.depot_inside, dtype=np.bool_)
    depot = np.tile(np.asarray(regions.depot_xy, dtype=np.float64), (regions.n, 1))
    return regions.contains(depot, np.arange(regions.n, dtype=np.int64))


Row = tuple[int, float, float, float, float, float, float]


def start_pieces(regions: RegionSet, sectors: int = _START_SECTORS) -> tuple[Pieces, bool]:
    """Every outer star as ``sectors`` sectors x bands (empty ones left out), numbered
    densely over the regions kept (see :func:`skipped_regions`), the depot last.

    When every tour meets every kept region's boundary (:func:`touches_boundary`), a piece
    need only cover the boundary, which lies between the star's inner and outer reach; the
    flag says which was done."""
    boundary = touches_boundary(regions)
    skip = skipped_regions(regions)
    rows: list[Row] = []
    kept = 0
    for i, star in enumerate(regions.outer):
        if skip[i]:
            continue
        cx, cy = star.center_xy
        for k in range(sectors):
            t0, t1 = 2.0 * math.pi * k / sectors, 2.0 * math.pi * (k + 1) / sectors
            reach = star.reach_over(t0, t1)
            low = star.inner_over(t0, t1) if boundary else 0.0
            bands = 1 if reach - low <= 1e-9 * max(reach, 1.0) else _START_BANDS
            for b in range(bands):
                r0 = low + (reach - low) * b / bands
                r1 = low + (reach - low) * (b + 1) / bands
                rows.append((kept, cx, cy, r0, r1, t0, t1))
        kept += 1
    if regions.depot_xy is not None:
        dx, dy = regions.depot_xy
        rows.append((kept, dx, dy, 0.0, 0.0, 0.0, 2.0 * math.pi))
    return _pieces(rows), boundary


def _pieces(rows: list[Row]) -> Pieces:
    a = np.asarray(rows, dtype=np.float64).reshape(-1, 7)
    return Pieces(a[:, 0].astype(np.int64), *(np.ascontiguousarray(a[:, k]) for k in range(1, 7)))


def split(
    pieces: Pieces,
    chosen: npt.NDArray[np.bool_],
    stars: list[OuterStar | None],
    boundary: bool,
) -> tuple[Pieces, I64]:
    """Split each chosen piece in two across its longer side (arc length or band depth); the
    halves take their star's reach over their own angles, and empty halves are left out.
    ``stars[i]`` is piece region ``i``'s star (None for the depot). Returns the new pieces
    and, per new piece, the old piece it came from."""
    rows: list[Row] = []
    parent: list[int] = []
    counts = np.bincount(pieces.region, minlength=len(stars))
    for k in range(pieces.n):
        i = int(pieces.region[k])
        cx, cy = float(pieces.cx[k]), float(pieces.cy[k])
        t0, t1 = float(pieces.t0[k]), float(pieces.t1[k])
        r0, r1 = float(pieces.r0[k]), float(pieces.r1[k])
        star = stars[i]
        if not chosen[k] or star is None or counts[i] >= _MAX_PIECES_PER_REGION:
            rows.append((i, cx, cy, r0, r1, t0, t1))
            parent.append(k)
            continue
        counts[i] += 1
        if r1 * (t1 - t0) >= r1 - r0:
            tm = 0.5 * (t0 + t1)
            for a, b in ((t0, tm), (tm, t1)):
                reach = min(r1, star.reach_over(a, b))
                low = max(r0, star.inner_over(a, b)) if boundary else r0
                if reach >= low:
                    rows.append((i, cx, cy, low, reach, a, b))
                    parent.append(k)
        else:
            rm = 0.5 * (r0 + r1)
            rows.append((i, cx, cy, r0, rm, t0, t1))
            rows.append((i, cx, cy, rm, r1, t0, t1))
            parent.extend((k, k))
    # Old pieces are sorted by region and each keeps its place, so the rows are sorted too.
    return _pieces(rows), np.asarray(parent, dtype=np.int64)


def _region_circles(pieces: Pieces, m: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per region: its star's centre and the largest reach of its pieces."""
    cx = np.zeros(m)
    cy = np.zeros(m)
    cr = np.zeros(m)
    cx[pieces.region] = pieces.cx
    cy[pieces.region] = pieces.cy
    np.maximum.at(cr, pieces.region, pieces.r1)
    return cx, cy, cr


def piece_costs(pieces: Pieces, m: int) -> FloatArray:
    """The full piece-by-piece matrix of ``c(P, Q)`` (small instances only)."""
    mx, my, rho = pieces.circles()
    cx, cy, cr = _region_circles(pieces, m)
    g = pieces.region
    circle = np.hypot(mx[:, None] - mx[None, :], my[:, None] - my[None, :])
    circle -= rho[:, None] + rho[None, :]
    region = np.hypot(cx[g][:, None] - cx[g][None, :], cy[g][:, None] - cy[g][None, :])
    region -= cr[g][:, None] + cr[g][None, :]
    cost: FloatArray = np.maximum(np.maximum(circle, region), 0.0)
    return cost


def exact_relaxed(pieces: Pieces, m: int) -> tuple[float, npt.NDArray[np.bool_]]:
    """The relaxed optimum by Held-Karp over (regions visited, last piece), ``m`` regions (the
    last is the start: the depot, if any), and which pieces its best cycle uses."""
    used = np.zeros(pieces.n, dtype=np.bool_)
    if m <= 1:
        return 0.0, used
    cost = piece_costs(pieces, m)
    g = pieces.region
    live = g < m - 1
    cols = np.flatnonzero(live)
    bit = np.where(live, 1 << np.minimum(g, 62), 0).astype(np.int64)
    full = (1 << (m - 1)) - 1
    best, best_cycle = math.inf, [0]
    for s in np.flatnonzero(g == m - 1):
        dp = np.full((full + 1, pieces.n), math.inf)
        back = np.full((full + 1, pieces.n), -1, dtype=np.int64)
        dp[bit[cols], cols] = cost[s, cols]
        back[bit[cols], cols] = s
        for mask in range(1, full):
            row = dp[mask]
            if not np.isfinite(row).any():
                continue
            fresh = cols[(bit[cols] & mask) == 0]
            cand = row[:, None] + cost[:, fresh]
            arg = cand.argmin(axis=0)
            val = cand[arg, np.arange(fresh.size)]
            tgt = mask | bit[fresh]
            better = val < dp[tgt, fresh]
            dp[tgt[better], fresh[better]] = val[better]
            back[tgt[better], fresh[better]] = arg[better]
        close = dp[full] + cost[:, s]
        last = int(close.argmin())
        if close[last] < best:
            best = float(close[last])
            cycle, mask, p = [int(s)], full, last
            while p != s:
                cycle.append(p)
                q = int(back[mask, p])
                mask &= ~int(bit[p])
                p = q
            best_cycle = cycle
    used[best_cycle] = True
    return best, used


@nb.njit(cache=True)
def lagrangian(
    region: I64,
    start: I64,
    mx: FloatArray,
    my: FloatArray,
    rho: FloatArray,
    dreg: FloatArray,
    near_ptr: I64,
    near: I64,
    mu: FloatArray,
    upper: float,
    iterations: int,
    used: npt.NDArray[np.bool_],
) -> float:
    m = start.size - 1
    npc = region.size
    w = np.empty((m, m))
    ap = np.empty((m, m), dtype=np.int64)
    amin = np.empty(m, dtype=np.int64)
    amax = np.empty(m, dtype=np.int64)
    deg = np.zeros(npc)
    g = np.zeros(npc)
    g_prev = np.zeros(npc)
    best_mu = mu.copy()
    best = -np.inf
    lam = 1.0
    stall = 0
    key = np.empty(m)
    parent = np.empty(m, dtype=np.int64)
    done = np.empty(m, dtype=np.bool_)
    for it in range(iterations):
        for i in range(m):
            lo, hi = start[i], start[i + 1]
            bi, bx = lo, lo
            for p in range(lo, hi):
                if mu[p] < mu[bi]:
                    bi = p
                if mu[p] > mu[bx]:
                    bx = p
            amin[i] = bi
            amax[i] = bx
        for i in range(m):
            w[i, i] = np.inf
            for j in range(i + 1, m):
                v = dreg[i, j] + mu[amin[i]] + mu[amin[j]]
                w[i, j] = v
                w[j, i] = v
                ap[i, j] = amin[i]
                ap[j, i] = amin[j]
        for i in range(m):
            for k in range(near_ptr[i], near_ptr[i + 1]):
                j = near[k]
                if j <= i:
                    continue
                bv = np.inf
                bp, bq = -1, -1
                for p in range(start[i], start[i + 1]):
                    for q in range(start[j], start[j + 1]):
                        d = math.hypot(mx[p] - mx[q], my[p] - my[q]) - rho[p] - rho[q]
                        if d < dreg[i, j]:
                            d = dreg[i, j]
                        v = d + mu[p] + mu[q]
                        if v < bv:
                            bv, bp, bq = v, p, q
                w[i, j] = bv
                w[j, i] = bv
                ap[i, j] = bp
                ap[j, i] = bq
        # Minimum 1-tree: a spanning tree of regions 0..m-2, and region m-1 joined twice.
        for p in range(npc):
            deg[p] = 0.0
        total = 0.0
        s = m - 1
        for i in range(m):
            key[i] = np.inf
            done[i] = False
            parent[i] = -1
        done[s] = True
        key[0] = 0.0
        for _ in range(m - 1):
            u = -1
            for i in range(m):
                if not done[i] and (u < 0 or key[i] < key[u]):
                    u = i
            done[u] = True
            if parent[u] >= 0:
                total += w[parent[u], u]
                deg[ap[parent[u], u]] += 1.0
                deg[ap[u, parent[u]]] += 1.0
            for i in range(m):
                if not done[i] and w[u, i] < key[i]:
                    key[i] = w[u, i]
                    parent[i] = u
        a, b = -1, -1
        for i in range(s):
            if a < 0 or w[s, i] < w[s, a]:
                b = a
                a = i
            elif b < 0 or w[s, i] < w[s, b]:
                b = i
        for j in (a, b):
            total += w[s, j]
            deg[ap[s, j]] += 1.0
            deg[ap[j, s]] += 1.0
        for i in range(m):
            total -= 2.0 * mu[amax[i]]
        if it == 0 or total > best + 1e-12 * abs(best):
            best = total
            stall = 0
            for p in range(npc):
                best_mu[p] = mu[p]
                used[p] = deg[p] > 0.0
            for i in range(m):
                used[amax[i]] = True
        else:
            stall += 1
            if stall >= 30:
                # Halve the step and go back to the best multipliers.
                lam *= 0.5
                stall = 0
                for p in range(npc):
                    mu[p] = best_mu[p]
                    g_prev[p] = 0.0
                continue
        if lam < 1e-5:
            break
        norm = 0.0
        for p in range(npc):
            g[p] = deg[p]
        for i in range(m):
            g[amax[i]] -= 2.0
        for p in range(npc):
            g[p] = 0.7 * g[p] + 0.3 * g_prev[p]
            g_prev[p] = g[p]
            norm += g[p] * g[p]
        if norm == 0.0:
            break
        if best >= upper:
            break
        # Aim a little above the best bound so far, not at the tour: far below the tour,
        # steps aimed at it overshoot.
        aim = min(upper, best + 0.05 * abs(best) + 1e-9 * upper)
        step = lam * (aim - total) / norm
        if step <= 0.0:
            step = lam * 1e-3 * upper / norm
        for p in range(npc):
            mu[p] += step * g[p]
    for p in range(npc):
        mu[p] = best_mu[p]
    return best


def near_lists(pieces: Pieces, m: int) -> tuple[FloatArray, I64, I64]:
    cx, cy, cr = _region_circles(pieces, m)
    dreg = np.hypot(cx[:, None] - cx[None, :], cy[:, None] - cy[None, :])
    dreg = np.maximum(dreg - cr[:, None] - cr[None, :], 0.0)
    k = min(_NEAR, m - 1)
    # Nearest by centre, not by the (often zero) distance between the discs.
    masked = np.hypot(cx[:, None] - cx[None, :], cy[:, None] - cy[None, :])
    masked += np.diag(np.full(m, np.inf))
    nearest = np.argpartition(masked, k - 1, axis=1)[:, :k] if k > 0 else np.zeros((m, 0))
    pairs = {(min(i, int(j)), max(i, int(j))) for i in range(m) for j in nearest[i]}
    adj: list[list[int]] = [[] for _ in range(m)]
    for i, j in pairs:
        adj[i].append(j)
        adj[j].append(i)
    ptr = np.zeros(m + 1, dtype=np.int64)
    np.cumsum([len(a) for a in adj], out=ptr[1:])
    flat = np.asarray([j for a in adj for j in sorted(a)], dtype=np.int64)
    return np.ascontiguousarray(dreg), ptr, flat


def exact_work(pieces: Pieces, m: int) -> float:
    starts = int(np.count_nonzero(pieces.region == m - 1))
    return float(starts) * float(1 << (m - 1)) * float(pieces.n) ** 2
