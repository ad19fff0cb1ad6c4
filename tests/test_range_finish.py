"""The finish of a mesh held in ranges (paroct.range_finish) against mesher's on the joined
mesh: the boundary's topology, the missed parts and the compaction, on random splits with
random owners (whole meshes in ranges: tests/test_partition.py)."""

from pathlib import Path

import numpy as np
import pytest

import paroct
from paroct import mesher
from paroct.range_finish import compact_by_owners, misses_by_owners, topology_by_owners
from paroct.range_pinches import BoundaryFaces, RangeTets, boundary_by_owners, fans_by_owners
from paroct.repair import remove_pinches
from paroct.topology import boundary_faces, match_faces, surface_topology, vertex_fans

from .test_repair import _pinched_block, _pinched_block_points

DATA = Path(__file__).resolve().parent.parent / "data"


def _random_ranges(rng, n_rows: int, n_ranges: int) -> list[np.ndarray]:
    """Rows 0..n_rows-1 dealt into n_ranges ranges at random (some empty)."""
    deal = rng.integers(0, n_ranges, size=n_rows)
    return [np.flatnonzero(deal == r) for r in range(n_ranges)]


def _owned(faces: np.ndarray, owner_of: np.ndarray, rng, n_ranges: int) -> list[BoundaryFaces]:
    """The faces dealt at random into ranges, each once, then held by their owners (each
    range numbering the points as the whole: local ids are mesh ids)."""
    sent = [BoundaryFaces(faces[rows], owner_of[faces[rows]], np.full(rows.shape[0], r, dtype=np.int32), faces[rows])
            for r, rows in enumerate(_random_ranges(rng, faces.shape[0], n_ranges))]
    return boundary_by_owners(sent, n_ranges)


@pytest.mark.parametrize("seed", range(8))
def test_topology_by_owners_is_the_whole_boundarys(seed):
    """Pinched boundaries (vertices whose faces are several fans: the edges are counted), the
    same repaired (one fan each: 3 F / 2 edges) and two blocks side by side (two components),
    their vertices owned by random ranges: topology_by_owners gives surface_topology's
    counts, components, Euler characteristic and genus."""
    rng = np.random.default_rng(700 + seed)
    tets, core = _pinched_block(seed)
    points = _pinched_block_points(seed)
    pinched = boundary_faces(tets, match_faces(tets)[0])
    repaired = remove_pinches(tets.copy(), core.copy())[2]
    n = points.shape[0]
    two = np.concatenate([repaired, pinched + n])
    cases = [(pinched, points), (repaired, points), (two, np.concatenate([points, points + 20.0]))]
    several_fans = False
    for faces, at in cases:
        n_ranges = int(rng.integers(1, 9))
        owner_of = rng.integers(0, n_ranges, size=at.shape[0])
        owned = _owned(faces, owner_of, rng, n_ranges)
        got = topology_by_owners(owned, fans_by_owners(owned, n_ranges))
        assert got == surface_topology(faces, at.shape[0])
        several_fans |= bool(vertex_fans(np.ascontiguousarray(faces, dtype=np.int64), at.shape[0]).min() < 0)
    assert several_fans  # the edge-counting path ran


@pytest.mark.parametrize("seed", range(4))
def test_misses_by_owners_are_the_whole_boundarys(seed):
    """Random triangles near part of bunny's surface, dealt into ranges with random owners:
    the surface vertices and long triangles they miss are mesher.boundary_misses' of the
    triangles joined."""
    rng = np.random.default_rng(800 + seed)
    surface = paroct.load_surface(DATA / "bunny.stl")
    size = surface.diagonal / float(rng.choice([60, 100, 150]))
    near = surface.vertices[rng.choice(surface.vertices.shape[0], size=15, replace=False)]
    points = np.concatenate([near, near + rng.normal(scale=size, size=near.shape)])
    faces = rng.integers(0, points.shape[0], size=(25, 3))
    n_ranges = int(rng.integers(1, 7))
    owner_of = rng.integers(0, n_ranges, size=points.shape[0])
    want_vertices, want_faces = mesher.boundary_misses(surface, points[np.unique(faces)], size)
    assert 0 < want_vertices.shape[0] < surface.vertices.shape[0] and want_faces.size
    parts = [RangeTets(np.arange(points.shape[0]), np.zeros((0, 4), dtype=np.int32), np.zeros(points.shape[0], dtype=bool),
                       points, owner_of)] * n_ranges  # each range holds every point: positions read by local id
    missed_vertices, missed_faces = misses_by_owners(_owned(faces, owner_of, rng, n_ranges), parts, surface, size)
    assert np.array_equal(missed_vertices, want_vertices)
    assert np.array_equal(missed_faces, want_faces)


@pytest.mark.parametrize("seed", range(6))
def test_compaction_by_owners_is_the_joined_meshs(seed):
    """Tets of a pinched block dealt into ranges, their points numbered as number_ranges
    numbers them (by owner, then key: lattice vertices, then cut points) with unused ones
    among them: compact_by_owners and the ranges' renumbering give mesher._compact's points,
    point triangles and tets of the ranges' tets joined in range order."""
    rng = np.random.default_rng(900 + seed)
    tets, _ = _pinched_block(seed)
    points = _pinched_block_points(seed)
    n_ranges = int(rng.integers(1, 7))
    n = points.shape[0]
    owner_of = rng.integers(0, n_ranges, size=n)
    is_vertex = rng.random(n) < 0.7
    order = np.lexsort((rng.random(n), owner_of, ~is_vertex))  # vertices by owner, then cut points by owner
    mesh_id = np.empty(n, dtype=np.int64)
    mesh_id[order] = np.arange(n)
    n_vertices = int(is_vertex.sum())
    faces_of = rng.integers(-1, 50, size=n).astype(np.int32)
    parts, faces = [], []
    for rows in _random_ranges(rng, tets.shape[0], n_ranges):
        held = np.unique(np.concatenate([tets[rows].ravel(), rng.integers(0, n, size=5)]))  # some unused
        held = rng.permutation(held)
        local = np.argsort(held)[np.searchsorted(held, tets[rows], sorter=np.argsort(held))].astype(np.int32)
        parts.append(RangeTets(mesh_id[held], local.reshape(-1, 4), np.zeros(held.shape[0], dtype=bool),
                               points[held], owner_of[held]))
        faces.append(faces_of[held])
    compaction = compact_by_owners(parts, faces, n_vertices, n_ranges)
    renumbered = []
    for part, new_id in zip(parts, compaction.new_ids):
        unused = np.setdiff1d(np.arange(part.ids.shape[0]), part.tets)
        assert np.all(new_id[unused] == -1)
        renumbered.append(new_id[part.tets])
    by_id = np.empty(n, dtype=np.int64)
    by_id[mesh_id] = np.arange(n)  # the point of each mesh id
    joined = np.concatenate([p.ids[p.tets] for p in parts]).astype(np.int32)
    want_points, want_tets, new_id = mesher._compact(points[by_id], joined)
    assert np.array_equal(compaction.points, want_points)
    assert np.array_equal(np.concatenate(renumbered), want_tets)
    assert np.array_equal(compaction.point_faces, faces_of[by_id][new_id >= 0])


def test_compaction_refuses_ranges_that_place_a_shared_point_differently():
    """Two ranges holding the same mesh point at two positions: an AssertionError, not a mesh
    with one of them."""
    tets = np.array([[0, 1, 2, 3]], dtype=np.int32)
    points = np.eye(4, 3)
    moved = points.copy()
    moved[2] += 1e-12
    parts = [RangeTets(np.arange(4), tets, np.zeros(4, dtype=bool), at, np.zeros(4, dtype=np.int64))
             for at in (points, moved)]
    faces = [np.full(4, -1, dtype=np.int32)] * 2
    assert np.array_equal(compact_by_owners(parts[:1] * 2, faces, 4, 1).points, points)
    with pytest.raises(AssertionError, match="place a point they share differently"):
        compact_by_owners(parts, faces, 4, 1)
