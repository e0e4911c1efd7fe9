r"""The outline of a convex mesh seen from a point: its vertices extreme along the directions of a chart.

The cosine kernels' fan of affine maps (:mod:`sphere3d.reparam.shading_affine`) carries the hull of
its anchor points' gnomonic charts. A convex mesh's image from a shading point x is the hull of all
its vertices' charts, so with every vertex an anchor the fan carries the whole outline; a mesh of
more vertices than :data:`DIRECTIONS` is followed instead through the vertices of its outline found
here, per kernel, at a cost that does not grow with the kernel count times the vertex count.

In the chart about the kernel's centre c (frame t, b), a vertex's chart coordinate along the chart
direction $e_j = \cos φ_j\, t + \sin φ_j\, b$ ($φ_j = 2πj/D$, D = :data:`DIRECTIONS`) is

    $g_j(v) = e_j·(v - x) / c·(v - x)$,

a ratio of two linear functions of v with a positive denominator (every vertex in front of the
chart): its superlevel sets are half-spaces, so on the vertex graph of a convex polytope a vertex
none of whose neighbours has a larger $g_j$ is its maximum over the whole mesh (the simplex
method's argument for a linear objective, applied to $e_j·(v - x) - g\, c·(v - x)$). Each of the D
searches climbs from the vertex extreme along $e_j$ seen from afar (a table over
:data:`TABLE_SUBDIVISIONS`'s icosphere of directions, once per state) to that maximum, a few steps.
The D maxima are vertices of the outline's hull in the chart; an outline vertex is found wherever
its exterior angle (the range of directions it is extreme along) exceeds $2π/D$. The outline's
edges are the mesh's edges, so a vertex missed between two found ones is a neighbour of one of
them: the anchors are the maxima and all their neighbours (inner ones fall inside the hull the fan
takes), and the outline is whole wherever no three of its vertices in a row turn it by less than
$2π/D$ together (a convex mesh's outline turns by 2π in all). A run of three missed vertices
leaves a chord in their place: biased by the sliver it cuts off.

Assumes a convex mesh (a non-convex one's image is not its hull; the climb may stop at a local
maximum) whose vertices all lie in front of the chart's plane. Cost: once per state O(V log V +
V · M) for M table directions; per kernel D k-d tree queries and D climbs of a few steps over the
vertices' neighbours.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from flatland.core.dual import Dual, detach
from sphere3d.shapes import icosphere

__all__ = ["DIRECTIONS", "MeshGraph", "chart_extremes", "mesh_graph", "outline_candidates"]

DIRECTIONS = 32
"""D: chart directions per kernel along which an outline vertex is sought (the anchors of the fan)."""
TABLE_SUBDIVISIONS = 2
"""The icosphere (162 directions) over which each mesh's extreme vertices are tabled for the climbs'
starts: any start is correct; a near one makes the climbs short."""
CHUNK = 4096
"""Kernels per pass of the climbs (their working arrays: CHUNK × D × valence × 3 floats)."""


@dataclass(frozen=True)
class MeshGraph:
    """The vertex graphs of a few meshes, flat: the distinct ``vertices`` (Dual (V, 3)), their
    ``neighbours`` (V, valence) as indices into the same arrays (padded by the vertex itself), and per
    mesh its ``table`` (meshes, M) of the vertex extreme along each table direction ``directions``
    (M, 3), with a k-d tree over those."""

    vertices: Any
    neighbours: np.ndarray
    table: np.ndarray
    directions: np.ndarray
    tree: cKDTree


def mesh_graph(meshes: list[Any]) -> MeshGraph:
    """The graph of each of ``meshes`` (Dual corner arrays (3F, 3), triangle by triangle): distinct
    vertices by position, neighbours across the triangles' edges, the table of extreme vertices."""
    ball = icosphere(1.0, TABLE_SUBDIVISIONS).vertices
    directions = ball / np.linalg.norm(ball, axis=1)[:, None]
    values, tangents, pairs, tables, offset = [], [], [], [], 0
    for corners in meshes:
        plain = np.asarray(detach(corners))
        _, first, inverse = np.unique(plain, axis=0, return_index=True, return_inverse=True)
        faces = inverse.reshape(-1, 3) + offset
        pairs.append(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]))
        values.append(plain[first])
        tangents.append(corners[first].tangent)
        tables.append(offset + np.argmax(directions @ plain[first].T, axis=1))
        offset += first.size
    edges = np.unique(np.sort(np.concatenate(pairs), axis=1), axis=0)
    both = np.concatenate([edges, edges[:, ::-1]])  # each edge from either end
    both = both[np.argsort(both[:, 0], kind="stable")]
    valence = np.bincount(both[:, 0], minlength=offset)
    start = np.concatenate([[0], np.cumsum(valence)[:-1]])
    neighbours = np.repeat(np.arange(offset)[:, None], valence.max(), axis=1)  # padded by the vertex itself
    slot = np.arange(len(both)) - start[both[:, 0]]
    neighbours[both[:, 0], slot] = both[:, 1]
    k = meshes[0].k
    tangent = np.concatenate(tangents, axis=0 if k is None else 1)
    vertices = Dual(np.concatenate(values), tangent, k)
    return MeshGraph(vertices, neighbours, np.array(tables), directions, cKDTree(directions))


def chart_extremes(
    graph: MeshGraph, mesh: np.ndarray, x: np.ndarray, c: np.ndarray, t: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """Per kernel (n rows: its mesh's index in ``graph`` ``mesh``, shading point ``x``, chart centre ``c``
    and frame ``t``, ``b``, each (n, 3)): the D vertices (n, D) of its mesh extreme along the chart's
    directions (module docstring), as indices into ``graph.vertices``."""
    phi = 2.0 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
    out = np.zeros((len(mesh), DIRECTIONS), dtype=np.intp)
    for lo in range(0, len(mesh), CHUNK):  # the kernels in chunks, each vectorized over its rows
        s = slice(lo, lo + CHUNK)
        e = np.cos(phi)[None, :, None] * t[s, None] + np.sin(phi)[None, :, None] * b[s, None]  # (r, D, 3)
        _, near = graph.tree.query(e.reshape(-1, 3))  # the climbs' starts: extreme seen from afar
        start = graph.table[np.repeat(mesh[s], DIRECTIONS), near].reshape(len(e), DIRECTIONS)
        out[s] = _climb(graph, start, x[s], c[s], e)
    return out


def _climb(graph: MeshGraph, cur: np.ndarray, x: np.ndarray, c: np.ndarray, e: np.ndarray) -> np.ndarray:
    """From the vertices ``cur`` (r, D), to a neighbour with a larger $g_j$ (module docstring) until none
    has one: the maxima (r, D). Each step strictly raises some $g_j$, so the climbs end."""
    points = np.asarray(graph.vertices.value)

    def score(v: np.ndarray) -> np.ndarray:  # g_j = e_j . (v - x) / c . (v - x) at vertices v (r, D, m)
        y = points[v] - x[:, None, None]
        return np.sum(y * e[:, :, None], axis=-1) / np.sum(y * c[:, None, None], axis=-1)

    best = score(cur[..., None])[..., 0]
    while True:
        around = graph.neighbours[cur]  # (r, D, valence)
        values = score(around)
        pick = np.argmax(values, axis=2)[..., None]
        top = np.take_along_axis(values, pick, axis=2)[..., 0]
        up = top > best
        if not up.any():
            return cur
        cur = np.where(up, np.take_along_axis(around, pick, axis=2)[..., 0], cur)
        best = np.where(up, top, best)


def outline_candidates(
    graph: MeshGraph, mesh: np.ndarray, x: np.ndarray, c: np.ndarray, t: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """The anchors of the kernels of :func:`chart_extremes`: its D maxima and their neighbours
    (n, D (1 + valence)), as indices into ``graph.vertices`` (module docstring)."""
    found = chart_extremes(graph, mesh, x, c, t, b)
    return np.concatenate([found, graph.neighbours[found].reshape(len(found), -1)], axis=1)
