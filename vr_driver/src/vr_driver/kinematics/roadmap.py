"""The paths of earlier plans, kept as a graph of the free space for the plans to come: a cell is
static between scene changes, and a single-query search (OMPL's RRTConnect) starts from nothing at
every call. ROS-free, no optional library.

    roadmap = Roadmap(weights)                   # joint_weights: the sweep bound as the distance
    roadmap.keep(key)                            # the cell's key (scene, padding, box): another drops it
    route = roadmap.route(q0, goal, motion_free) # [q0, ..., goal] or None
    roadmap.add(path)                            # a plan's geometric path, start to goal

A route is a **hint**, never a verdict: the start and the goal are joined to the nearest vertices
(``NEIGHBOURS`` each) and the shortest way between them (Dijkstra, the sweep bound sum_i w_i |dq_i|
as the length) is looked for -- and every motion of it, old edges included, is checked again by
``motion_free`` (the plan's own motion check, its validity now) before the route is returned; an
edge that fails is dropped and the next way tried (``ROUTE_TRIES`` in all). What the planner makes
of a route (simplification, timing) is checked as any path. A new key (another scene, padding or
box: :meth:`keep`) drops every path: kept verdicts of another cell would cost checks and find
nothing. Not thread-safe: one per planning process (the plan action's core keeps it).
"""
from __future__ import annotations

import heapq
from typing import Any, Callable, Dict, Hashable, List, Optional, Sequence, Set, Tuple

import numpy as np

__all__ = ["Roadmap", "NEIGHBOURS", "ROUTE_TRIES", "MAX_VERTICES"]

#: the nearest vertices the start and the goal are each joined to (a straight motion each, checked)
NEIGHBOURS = 4
#: routes tried at most per query (an edge found blocked is dropped before the next)
ROUTE_TRIES = 4
#: vertices kept at most (the oldest paths dropped first)
MAX_VERTICES = 3000


class Roadmap:
    """The vertices and edges of the paths added (see the module text). ``weights`` [m/rad]: the
    joints' lever arms (``planner.joint_weights``), the distance is sum_i w_i |dq_i|."""

    def __init__(self, weights: Sequence[float]) -> None:
        self.weights = np.asarray(weights, dtype=float)
        self.key: Hashable = None
        self._vertices: List[Tuple[float, ...]] = []
        self._edges: Dict[int, Set[int]] = {}
        self._array: Optional[np.ndarray] = None
        #: what the roadmap did: routes found, routes tried in vain, edges dropped, drops by a new key
        self.counts = {"routes": 0, "misses": 0, "blocked": 0, "dropped": 0}

    def __len__(self) -> int:
        return len(self._vertices)

    def keep(self, key: Hashable) -> None:
        """Keep the roadmap for ``key`` (what the validity depends on); another key drops it."""
        if key != self.key:
            if self._vertices:
                self.counts["dropped"] += 1
            self.key = key
            self.clear()

    def clear(self) -> None:
        self._vertices, self._edges, self._array = [], {}, None

    def _distance(self, q: Sequence[float]) -> np.ndarray:
        if self._array is None:
            self._array = np.array(self._vertices, dtype=float).reshape(-1, len(self.weights))
        return np.abs(self._array - np.asarray(q, dtype=float)) @ self.weights

    def add(self, path: Sequence[Sequence[float]]) -> None:
        """A plan's geometric path (start to goal): its vertices, each next to the one before."""
        if len(path) < 2:
            return
        if len(self._vertices) + len(path) > MAX_VERTICES:
            self.clear()
        ids = []
        for q in path:
            q = tuple(float(v) for v in q)
            if self._vertices:
                d = self._distance(q)
                k = int(np.argmin(d))
                if d[k] < 1e-9:              # a vertex already there (a path through an old one)
                    ids.append(k)
                    continue
            self._vertices.append(q)
            self._edges[len(self._vertices) - 1] = set()
            self._array = None
            ids.append(len(self._vertices) - 1)
        for a, b in zip(ids, ids[1:]):
            if a != b:
                self._edges[a].add(b)
                self._edges[b].add(a)

    def route(self, q0: Sequence[float], goal: Sequence[float],
              motion_free: Callable[[Sequence[float], Sequence[float]], bool]) -> Optional[List[Tuple[float, ...]]]:
        """[q0, the route's vertices ..., goal], every motion of it found free by ``motion_free``
        now, or None (no vertices, no free join, no way through the graph)."""
        if not self._vertices:
            return None
        q0, goal = tuple(float(v) for v in q0), tuple(float(v) for v in goal)
        d0, dg = self._distance(q0), self._distance(goal)
        joined0 = {int(k): float(d0[k]) for k in np.argsort(d0)[:NEIGHBOURS] if motion_free(q0, self._vertices[k])}
        if not joined0:
            self.counts["misses"] += 1
            return None
        joinedg = {int(k): float(dg[k]) for k in np.argsort(dg)[:NEIGHBOURS]
                   if motion_free(self._vertices[k], goal)}
        checked: Set[Tuple[int, int]] = set()
        for _ in range(ROUTE_TRIES if joinedg else 0):
            way = self._shortest(joined0, joinedg)
            if way is None:
                break
            blocked = None
            for a, b in zip(way, way[1:]):
                edge = (min(a, b), max(a, b))
                if edge in checked:
                    continue
                if not motion_free(self._vertices[a], self._vertices[b]):
                    blocked = edge
                    break
                checked.add(edge)
            if blocked is None:
                self.counts["routes"] += 1
                return [q0] + [self._vertices[k] for k in way] + [goal]
            self.counts["blocked"] += 1
            self._edges[blocked[0]].discard(blocked[1])
            self._edges[blocked[1]].discard(blocked[0])
        self.counts["misses"] += 1
        return None

    def _shortest(self, starts: Dict[int, float], ends: Dict[int, float]) -> Optional[List[int]]:
        """The vertices of the shortest way from one of ``starts`` to one of ``ends`` (each with
        its join's length), Dijkstra over the edges; None when none joins them."""
        best: Dict[Any, float] = dict(starts)
        before: Dict[int, Optional[int]] = {k: None for k in starts}
        heap = [(d, k) for k, d in starts.items()]
        heapq.heapify(heap)
        done: Set[int] = set()
        found, found_len = None, float("inf")
        while heap:
            d, k = heapq.heappop(heap)
            if k in done or d > best.get(k, float("inf")):
                continue
            if d >= found_len:
                break
            done.add(k)
            if k in ends and d + ends[k] < found_len:
                found, found_len = k, d + ends[k]
            qk = np.asarray(self._vertices[k])
            for j in self._edges[k]:
                nd = d + float(np.abs(np.asarray(self._vertices[j]) - qk) @ self.weights)
                if nd < best.get(j, float("inf")):
                    best[j], before[j] = nd, k
                    heapq.heappush(heap, (nd, j))
        if found is None:
            return None
        way = [found]
        while before[way[-1]] is not None:
            way.append(before[way[-1]])
        return way[::-1]
