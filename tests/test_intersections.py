"""Self-crossing surfaces: the exact-where-certain triangle test against exact arithmetic, and
what mesh() and check_mesh do with a surface that intersects itself."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import paroct
from paroct import ParoctError, load_surface
from paroct.check import check_mesh
from paroct.intersections import crossing_triangles

from . import naive

DATA = Path(__file__).resolve().parent.parent / "data"


@pytest.mark.parametrize("seed, scale", [(0, None), (1, None), (2, 1.0), (3, 1e-7)])
def test_crossings_match_exact_arithmetic(seed, scale):
    """Pairs of triangles with no common vertex: small integer corners (many touching, coplanar
    and degenerate pairs, all exact in float64) or random real ones."""
    rng = np.random.default_rng(seed)
    n = 400
    if scale is None:
        corners = rng.integers(-3, 4, size=(n, 2, 3, 3)).astype(np.float64)
    else:
        corners = rng.normal(scale=scale, size=(n, 2, 3, 3)) + 5.0 * scale
    vertices = corners.reshape(-1, 3)
    faces = np.arange(vertices.shape[0]).reshape(-1, 3)
    for k in range(n):
        pair = faces[2 * k:2 * k + 2]
        want = naive.triangles_cross(corners[k, 0], corners[k, 1])
        got = crossing_triangles(vertices, pair, np.array([0, 1]))
        assert (got[0] == 1) == want and (got[1] == 0) == want, (k, corners[k])


def _icosphere_spike():
    """An icosphere whose vertex 0 is pulled through the ball and out the far side: its fan
    crosses triangles there, and every row may miss it."""
    surface = load_surface(_sphere())
    vertices = surface.vertices.copy()
    top = int(np.argmax(vertices[:, 2]))
    vertices[top] = [0.05, 0.03, -1.2]
    return vertices, surface.faces


def _sphere():
    import manifold3d

    return manifold3d.Manifold.sphere(1.0, 24)


def test_check_finds_a_spike_through_the_far_side():
    vertices, faces = _icosphere_spike()
    surface = load_surface((vertices, faces))
    crossing = crossing_triangles(surface.vertices, surface.faces, np.arange(surface.faces.shape[0]))
    assert (crossing >= 0).sum() >= 2
    for f in np.flatnonzero(crossing >= 0):  # each pair really crosses
        assert naive.triangles_cross(surface.vertices[surface.faces[f]], surface.vertices[surface.faces[crossing[f]]])
    result = paroct.mesh(surface, divisions=12)
    report = check_mesh(result.mesh.points, result.mesh.tets, surface)
    assert not report.ok and "the surface intersects itself" in report.problems()[-1]


@pytest.mark.parametrize("name", ["angle_block.stl", "bunny.stl", "xyz_cube.stl"])
def test_good_surfaces_cross_nowhere(name):
    surface = load_surface(DATA / name)
    assert (crossing_triangles(surface.vertices, surface.faces, np.arange(surface.faces.shape[0])) < 0).all()


def test_mesh_refuses_a_surface_crossing_itself_where_the_mesh_misses_it():
    """A unit box whose top holds a 0.02-wide square, the apex of its four-triangle fan pulled
    down through the bottom to z = -1.5: a needle no lattice row need cross, whose long
    triangles the mesh misses; the test of those triangles finds where they cross the bottom."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
                  [0.49, 0.49, 1], [0.51, 0.49, 1], [0.51, 0.51, 1], [0.49, 0.51, 1], [0.5, 0.5, -1.5]], float)
    f = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6],
                  [3, 0, 4], [3, 4, 7],  # bottom and sides
                  [4, 5, 9], [4, 9, 8], [5, 6, 10], [5, 10, 9], [6, 7, 11], [6, 11, 10], [7, 4, 8], [7, 8, 11],  # top
                  [8, 9, 12], [9, 10, 12], [10, 11, 12], [11, 8, 12]])  # the needle
    surface = load_surface((v, f))
    assert surface.volume > 0.99
    with pytest.raises(ParoctError, match=r"the surface intersects itself: its triangle \d+ \(centre"):
        paroct.mesh(surface, divisions=12)
