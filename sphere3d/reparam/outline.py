r"""One step along an occluder's outline: the silhouette edges that meet a found one at its ends.

The emitter strategy's field (:mod:`sphere3d.reparam.emitter_field`) keeps the shadow edges its
probes find by bisection. A shadow crossing the light holds more edges than pairs of probes straddle:
the shadow of a triangle larger than the light's gaps between probes, or of a box's corner. Seen from
the shading point x, the occluder's silhouette is a chain of mesh edges; at each end V of a found
silhouette edge the chain continues along another edge incident to V that is a silhouette edge from x
(Loubet et al. 2019, Sec. 4.3: a refinement of the heuristic, the probes' edge extended by the mesh's
adjacency): a boundary edge (one face: a single triangle's other edges), or an edge between a face
turned towards x and one turned away, $\mathrm{sign}(n_1·(V - x)) \ne \mathrm{sign}(n_2·(V - x))$.

:func:`outline_table` welds the state's triangles into vertices and edges once per state
(:func:`~sphere3d.boundary.edges.state_edges`) and lists each vertex's edges; :func:`next_edges`
gives, per found edge, the first silhouette edge at each of its ends (other than itself). The cost per
row is the two vertices' valences, whatever the mesh's size. An edge that a neighbour's test finds is a
silhouette edge from x; its shadow is a discontinuity of the light where it lies in front of it and
nothing else hides it, and a line of the field elsewhere (which only constrains the map: no bias).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np

from flatland.core.dual import detach
from sphere3d.boundary.edges import row_ids, state_edges
from sphere3d.state import SceneState
from sphere3d.tables import per_state

__all__ = ["NextEdges", "OutlineTable", "next_edges", "outline_chain", "outline_edges", "outline_table"]


@dataclass(frozen=True)
class OutlineTable:
    """Per state: each triangle corner's vertex ``vid`` (T, 3) and each triangle edge's id ``edge_of``
    (T, 3; edge k from slot k to slot k + 1); per edge its first face, its slots there, its second face
    (-1: none) and the faces' unit normals; per vertex its edges, ``incident[start[v]:start[v + 1]]``."""

    vid: np.ndarray
    edge_of: np.ndarray
    face: np.ndarray
    ia: np.ndarray
    ib: np.ndarray
    other: np.ndarray
    n1: np.ndarray
    n2: np.ndarray
    start: np.ndarray
    incident: np.ndarray


@per_state
def outline_table(state: SceneState) -> OutlineTable:
    """The state's vertices, edges and their incidence, once per state. O(T log T)."""
    edges = state_edges(state)
    tri = np.asarray(detach(state.triangles), dtype=np.float64)
    vid = row_ids(tri.reshape(-1, 3)).reshape(len(tri), 3)  # the ids mesh_edges welds by (exact position)
    a, b = vid[edges.face, edges.ia], vid[edges.face, edges.ib]
    count = int(vid.max(initial=-1)) + 1
    key = np.minimum(a, b) * count + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    # every half-edge of every triangle: its edge by its key
    ha, hb = vid, np.roll(vid, -1, axis=1)
    half = np.minimum(ha, hb) * count + np.maximum(ha, hb)
    at = np.clip(np.searchsorted(key[order], half), 0, max(len(key) - 1, 0))
    edge_of = np.where(key[order][at] == half, order[at], -1) if len(key) else np.full(vid.shape, -1)
    # each vertex's edges (both ends), in CSR
    ends = np.concatenate([a, b])
    ids = np.concatenate([np.arange(len(a)), np.arange(len(a))])
    by = np.argsort(ends, kind="stable")
    start = np.concatenate([[0], np.cumsum(np.bincount(ends, minlength=count))])
    table = OutlineTable(
        vid, edge_of, edges.face, edges.ia, edges.ib, edges.other, edges.n1, edges.n2, start, ids[by]
    )
    for f in fields(table):  # shared by every caller: read-only
        getattr(table, f.name).setflags(write=False)
    return table


@dataclass(frozen=True)
class NextEdges:
    """Per found edge and end (r, 2): the next silhouette edge's face and its slots there (``face``,
    ``ia``, ``ib``), and whether there is one (``found``)."""

    face: np.ndarray
    ia: np.ndarray
    ib: np.ndarray
    found: np.ndarray


def next_edges(state: SceneState, x: np.ndarray, triangle: np.ndarray, slots: np.ndarray) -> NextEdges:
    """At both ends of the edges ``slots`` (r, 2: vertex slots) of ``triangle`` (r,), the first other edge
    that is a silhouette edge seen from the points ``x`` (plain, (r, 3)) (module docstring)."""
    table = outline_table(state)
    own = _edge_id(table, triangle, slots[:, 0], slots[:, 1])
    ends = table.vid[triangle[:, None], slots]  # (r, 2)
    position = np.asarray(detach(state.triangles))[triangle[:, None], slots]  # (r, 2, 3)
    first = _first_silhouette(
        table, np.repeat(x, 2, axis=0), ends.ravel(), position.reshape(-1, 3), np.repeat(own, 2)
    )
    return _next(table, first, (len(triangle), 2))


def _first_silhouette(
    table: OutlineTable, x: np.ndarray, v: np.ndarray, position: np.ndarray, own: np.ndarray
) -> np.ndarray:
    """Per vertex ``v`` (n,) at ``position`` (n, 3): its first incident edge other than ``own`` (n,) that is
    a silhouette edge seen from ``x`` (n, 3); -1 where none is. The cost is the vertices' valences."""
    degree = table.start[v + 1] - table.start[v]
    rep = np.repeat(np.arange(v.size), degree)  # one entry per (vertex, incident edge)
    within = np.arange(rep.size) - np.repeat(np.cumsum(degree) - degree, degree)
    c = table.incident[table.start[v][rep] + within]
    to = (position - x)[rep]  # V - x, per vertex, then per incident edge
    s1 = np.einsum("nx,nx->n", table.n1[c], to)
    s2 = np.einsum("nx,nx->n", table.n2[c], to)
    silhouette = (table.other[c] < 0) | ((s1 > 0.0) != (s2 > 0.0))
    silhouette &= c != own[rep]
    # the first silhouette edge of each vertex
    first = np.full(v.size, -1, dtype=np.int64)
    hit = np.flatnonzero(silhouette)
    ends_hit = rep[hit]  # ascending: each vertex's entries together, its first one where the vertex changes
    at = np.flatnonzero(np.r_[True, ends_hit[1:] != ends_hit[:-1]]) if hit.size else hit
    first[ends_hit[at]] = c[hit[at]]
    return first


def _next(table: OutlineTable, first: np.ndarray, shape: tuple[int, ...]) -> NextEdges:
    """:class:`NextEdges` of the edges ``first`` (-1: none), in ``shape``."""
    e = np.maximum(first, 0)
    return NextEdges(
        table.face[e].reshape(shape),
        table.ia[e].reshape(shape),
        table.ib[e].reshape(shape),
        (first >= 0).reshape(shape),
    )


def outline_edges(state: SceneState, x: np.ndarray, triangle: np.ndarray, lines: np.ndarray) -> NextEdges:
    """Per followed snap (``lines`` (r, 2, 2): an edge of ``triangle`` twice, or a corner's two edges, the
    corner's slot first; :class:`~sphere3d.reparam.snaps.Snap`): a silhouette edge seen from ``x`` (plain,
    (r, 3)) through the followed point, to walk the outline from: the first of the snap's edges that is
    one, else the first silhouette edge at the corner's vertex (a mesh's corner snap holds the triangle's
    two edges there, of which the outline often takes one, or none); ``found`` False where none is."""
    table = outline_table(state)
    plain = np.asarray(detach(state.triangles))
    r = np.arange(len(triangle))
    face, ia, ib = triangle.copy(), lines[:, 0, 0].copy(), lines[:, 0, 1].copy()
    found = np.zeros(len(triangle), dtype=bool)
    for side in range(2):  # the snap's two edges (not a loop over samples)
        i, j = lines[:, side, 0], lines[:, side, 1]
        e = _edge_id(table, triangle, i, j)
        to = plain[triangle, i] - x  # V - x
        s1 = np.einsum("nx,nx->n", table.n1[e], to)
        s2 = np.einsum("nx,nx->n", table.n2[e], to)
        take = ~found & ((table.other[e] < 0) | ((s1 > 0.0) != (s2 > 0.0)))
        ia[take], ib[take], found[take] = i[take], j[take], True
    rest = np.flatnonzero(~found)
    if rest.size:  # at the corner's vertex, its first silhouette edge
        corner = lines[rest, 0, 0]
        first = _first_silhouette(
            table,
            x[rest],
            table.vid[triangle[rest], corner],
            plain[triangle[rest], corner],
            np.full(rest.size, -1),
        )
        at = _next(table, first, first.shape)
        face[rest], ia[rest], ib[rest], found[rest] = at.face, at.ia, at.ib, at.found
    return NextEdges(face, ia, ib, found & (r >= 0))


def _edge_id(table: OutlineTable, face: np.ndarray, ia: np.ndarray, ib: np.ndarray) -> np.ndarray:
    """The welded edge of each (face, slots ia, ib)."""
    return table.edge_of[face, np.where(ib == (ia + 1) % 3, ia, ib)]


def outline_chain(
    state: SceneState,
    x: np.ndarray,
    triangle: np.ndarray,
    slots: np.ndarray,
    near: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    steps: int,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Along the outline seen from ``x`` (plain, (r, 3)), from both ends of the edges ``slots`` (r, 2) of
    ``triangle`` (r,): the silhouette edges that follow, one step (:func:`next_edges`) at a time, while
    ``near(rows, face, ia, ib)`` holds for the last one (bool per row), up to ``steps`` a side; the first
    at each end always. A chain that comes back to the edge it started from stops. Returns per step and
    end (rows of the r, the edge's face, its slots there); each step costs the ends' valences."""
    table = outline_table(state)
    plain = np.asarray(detach(state.triangles))
    own = _edge_id(table, triangle, slots[:, 0], slots[:, 1])
    after = next_edges(state, x, triangle, slots)
    chains = []  # per end: the rows still walking, their last edge (face, slots) and the vertex behind
    for end in range(2):  # the edge's two ends (not a loop over samples)
        rows = np.flatnonzero(after.found[:, end])
        face, ia, ib = after.face[rows, end], after.ia[rows, end], after.ib[rows, end]
        chains.append([rows, face, ia, ib, table.vid[triangle[rows], slots[rows, end]]])
    out: tuple[list, list] = ([], [])
    walking = [0, 1]
    for step in range(steps):  # both ends' chains in one call a step (each row's result its own)
        for end in walking:
            out[end].append(tuple(chains[end][:4]))
        rows, face, ia, ib = (np.concatenate([chains[e][i] for e in walking]) for i in range(4))
        go = (_edge_id(table, face, ia, ib) != own[rows]) & near(rows, face, ia, ib)
        go = dict(
            zip(walking, np.split(go, np.cumsum([len(chains[e][0]) for e in walking])[:-1]), strict=True)
        )
        walking = [e for e in walking if step + 1 < steps and go[e].any()]
        if not walking:
            break
        for end in walking:
            rows, face, ia, ib, shared = (part[go[end]] for part in chains[end])
            far = np.where(table.vid[face, ia] == shared, 1, 0)  # the last edge's end away from it
            shared = np.where(far == 1, table.vid[face, ib], table.vid[face, ia])
            chains[end] = [rows, face, ia, ib, shared, far]
        rows, face, ia, ib, far = (np.concatenate([chains[e][i] for e in walking]) for i in (0, 1, 2, 3, 5))
        # the first silhouette edge at each last edge's far end, other than that edge
        tip = np.where(far == 1, ib, ia)
        first = _first_silhouette(
            table, x[rows], table.vid[face, tip], plain[face, tip], _edge_id(table, face, ia, ib)
        )
        nxt = _next(table, first, first.shape)
        start = 0
        for end in walking:
            rows, _, _, _, shared, _ = chains[end]
            n = start + np.arange(rows.size)
            start += rows.size
            f = nxt.found[n]
            chains[end] = [rows[f], nxt.face[n][f], nxt.ia[n][f], nxt.ib[n][f], shared[f]]
    return out[0] + out[1]
