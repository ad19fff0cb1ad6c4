"""Pinch repair against a dictionary twin (tests/naive.py), and the boundary it updates
against one computed from scratch."""

import numpy as np
import pytest

from paroct import repair
from paroct.lattice import leaf_tets
from paroct.repair import local_repair, remove_pinches, stuffed_boundary
from paroct.topology import boundary_faces, keep_rows, match_faces, nonmanifold_vertices, surface_topology

from . import naive


def _pinched_block_points(seed: int, n: int = 10):
    """The lattice points of _pinched_block's vertices, with the block, as (V, 3) float64."""
    g = np.arange(n)
    anchors = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, _ = leaf_tets(anchors, np.ones(len(anchors), dtype=np.int64))
    return coords.astype(np.float64)


def _pinched_block(seed: int, n: int = 10, keep: float = 0.55, within: int | None = None):
    """Kuhn tets of an n^3 block with random tets of its outer cell layers dropped (pinches
    appear where the remaining tets touch at a vertex or edge), only those within ``within``
    cells of the block's first corner if given, and the core mask: vertices on no boundary
    face, so a face of three core vertices is interior."""
    rng = np.random.default_rng(seed)
    g = np.arange(n)
    anchors = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = leaf_tets(anchors, np.ones(len(anchors), dtype=np.int64))
    centre = coords[tets].mean(axis=1)
    outer = (np.minimum(centre, n - centre) < 2).any(axis=1)
    if within is not None:
        outer &= (centre < within).all(axis=1)
    tets = np.ascontiguousarray(tets[~outer | (rng.random(len(tets)) < keep)])
    core = np.ones(len(coords), dtype=bool)
    core[boundary_faces(tets, match_faces(tets)[0]).ravel()] = False
    return tets, core


def _face_set(faces):
    """Faces as a set of rotations to the smallest vertex first (orientation kept)."""
    out = set()
    for f in faces.tolist():
        i = f.index(min(f))
        out.add(tuple(f[i:] + f[:i]))
    return out


@pytest.mark.parametrize("seed", range(8))
def test_local_repair_matches_a_dictionary_twin(seed):
    tets, core = _pinched_block(seed)
    faces = boundary_faces(tets, match_faces(tets)[0])
    bad = np.nonzero(nonmanifold_vertices(faces, len(core)))[0]
    assert bad.size  # every seed has pinches to repair
    whole_alive = naive.repair_pinches(tets, bad)
    out, removed, out_faces, topology = remove_pinches(tets.copy(), core.copy())
    assert removed == int((~whole_alive).sum()) > 0
    assert np.array_equal(out, tets[whole_alive])
    # The updated boundary is the result's boundary, closed and manifold.
    assert _face_set(out_faces) == _face_set(boundary_faces(out, match_faces(out)[0]))
    assert not nonmanifold_vertices(out_faces, len(core)).any() and not naive.nonmanifold_vertices(out_faces, len(core)).any()
    assert topology == surface_topology(out_faces, len(core)) and topology.manifold


@pytest.mark.parametrize("n, dropped", [(0, 0.0), (1, 1.0), (50, 0.0), (50, 1.0), (1000, 0.01), (1000, 0.5)])
def test_keep_rows_is_compress_in_place(n, dropped):
    rng = np.random.default_rng(n)
    rows = rng.integers(0, 99, (n, 4)).astype(np.int32)
    keep = rng.random(n) >= dropped
    moved = rows.copy()
    count = keep_rows(moved, keep)
    assert count == keep.sum() and np.array_equal(moved[:count], np.compress(keep, rows, axis=0))


@pytest.mark.parametrize("seed", range(4))
def test_ranks_in_orders_are_lexsorts_of_the_signed_coordinates(seed):
    """Each order's ranks are numpy's lexsort of sign * the coordinates in its axes order
    (equal points by id), on points with many equal coordinates and repeated points, over
    every point or only the used ones (the others rank 0)."""
    rng = np.random.default_rng(seed)
    points = rng.integers(-2, 3, size=(200, 3)).astype(np.float64)
    points[rng.integers(200, size=30)] = points[rng.integers(200, size=30)]
    points[rng.integers(200, size=10)] *= -1.0  # -0.0 equals 0.0
    used = np.flatnonzero(rng.random(200) < 0.6)
    for chosen in (None, used):
        ranks = repair._ranks_in_orders(points, chosen)
        ids = np.arange(200) if chosen is None else chosen
        for (axes, sign), rank in zip(repair.PINCH_ORDERS, ranks):
            want = np.zeros(200, dtype=np.int64)
            want[ids[np.lexsort((sign * points[ids][:, list(axes)]).T[::-1])]] = np.arange(ids.size)
            assert np.array_equal(rank, want)


@pytest.mark.parametrize("seed", range(4))
def test_star_partners_match_a_pairwise_twin(seed):
    """Face partners in the stars of a pinched block's vertices, and of random parts of them
    (tets dropped, order shuffled), against every pair compared."""
    tets, _ = _pinched_block(seed, n=6)
    rng = np.random.default_rng(seed)
    for v in rng.choice(np.unique(tets), 60, replace=False):
        star = np.flatnonzero((tets == v).any(axis=1))
        if seed % 2:
            star = rng.permutation(star)[: max(1, int(rng.integers(1, star.size + 1)))]
        partner = np.full(4 * star.size, -2, dtype=np.int64)
        repair._star_partners(tets, star, star.size, v, partner, np.empty(3 * star.size, dtype=np.int64),
                               np.empty(3 * star.size, dtype=np.int64))
        want = naive.star_partners(tets, star.tolist(), int(v))
        assert {key: int(partner[4 * key[0] + key[1]]) for key in want} == want


@pytest.mark.parametrize("seed", range(8))
def test_local_repair_gives_the_whole_repair_from_any_ring(seed, monkeypatch):
    """The repair on the stars within 0, 1 or 2 rings of the bad vertices, falling back to
    the whole mesh where the worklist leaves them, removes the tets the dictionary twin does
    on the whole mesh.  At ring 0 every removal leaves the stars (the fallback runs); at
    ring 2 the first try, on part of the mesh, holds the whole repair (the pinches lie in one
    corner of the block)."""
    tets, core = _pinched_block(seed, n=14, within=5)
    faces = boundary_faces(tets, match_faces(tets)[0])
    bad = np.nonzero(nonmanifold_vertices(faces, len(core)))[0]
    whole_alive = naive.repair_pinches(tets, bad)
    assert not whole_alive.all()
    tries = []

    def spy(sub, *args):
        alive, ok = repair_kernel(sub, *args)
        tries.append((len(sub), ok))
        return alive, ok

    repair_kernel = repair._repair
    monkeypatch.setattr(repair, "_repair", spy)
    for rings in range(3):
        tries.clear()
        assert np.array_equal(local_repair(tets, bad, len(core), rings), whole_alive)
        if rings == 0:
            assert [ok for _, ok in tries] == [False, True] and tries[1][0] == len(tets)
        if rings == 2:
            assert len(tries) == 1 and tries[0][1] and tries[0][0] < len(tets) // 2


@pytest.mark.parametrize("seed", range(8))
def test_stuffed_boundary_and_its_fans_match_dictionary_twins(seed):
    """The boundary from the faces without a core vertex, matched among themselves, against
    matching every face; the fans' verdicts against link walks by dictionaries.  Some cores
    are random (faces of core vertices without a neighbour are not boundary faces), and some
    tets doubled (a face in three or more tets: all but the first two are unmatched)."""
    tets, core = _pinched_block(seed)
    rng = np.random.default_rng(seed)
    if seed % 2:
        core = rng.random(len(core)) < 0.3
    if seed % 4 == 3:
        tets = np.concatenate([tets, tets[rng.integers(len(tets), size=40)]])
    faces = stuffed_boundary(tets, core)
    want = naive.stuffed_boundary(tets, core)
    assert faces.shape[0] > 0 and np.array_equal(faces, want)
    assert np.array_equal(nonmanifold_vertices(faces, len(core)), naive.nonmanifold_vertices(faces, len(core)))
    topology = surface_topology(faces, len(core))
    assert (topology.n_edges, topology.n_vertices, topology.bad_edges) == naive.surface_edges(faces)
    assert topology.bad_vertices == naive.nonmanifold_vertices(faces, len(core)).sum()
    assert topology.components == naive.face_components(faces)


@pytest.mark.parametrize("seed", range(6))
def test_components_of_random_triangles_match_a_set_twin(seed):
    """Components from a search over the links against merged vertex sets, on triangles of a
    few random vertices (isolated vertices, repeated and degenerate-free soups, one face)."""
    rng = np.random.default_rng(seed)
    n_vertices = int(rng.integers(3, 60))
    n_faces = 1 if seed == 0 else int(rng.integers(1, 40))
    faces = np.array([rng.choice(n_vertices, 3, replace=False) for _ in range(n_faces)])
    topology = surface_topology(faces, n_vertices + 5)
    assert topology.components == naive.face_components(faces) >= 1


def _best_order_twin(tets, bad, points, within=None):
    """naive.repair_pinches in each of PINCH_ORDERS of the points' coordinates, the least
    volume removed kept (ties: the first), among the orders whose worklist checks only
    vertices in ``within`` (a set; None: any): the alive mask (M,), or None if no order does."""
    best = None
    for axes, sign in repair.PINCH_ORDERS:
        rank = np.empty(len(points), dtype=np.int64)
        rank[np.lexsort((sign * points[:, list(axes)]).T[::-1])] = np.arange(len(points))
        checked: set = set()
        alive = naive.repair_pinches(tets, bad, rank, checked)
        volume = sum(abs(naive._det3(points[t[1:]] - points[t[0]])) for t in tets[~alive]) / 6  # as repair._removed_volumes
        if (within is None or checked <= within) and (best is None or volume < best[0]):
            best = (volume, alive)
    return None if best is None else best[1]


def _cluster_twin(tets, bad, points):
    """local_repair with points, by the twins: each cluster (naive.pinch_clusters) in its best
    order among those whose worklist stays within one ring of its bad vertices; if some
    cluster has none, every bad vertex in the one best order on the whole mesh."""
    want = np.ones(len(tets), dtype=bool)
    for cluster in naive.pinch_clusters(tets, bad, repair.PINCH_RINGS):
        ring = set(tets[np.isin(tets, cluster).any(axis=1)].ravel().tolist())
        alive = _best_order_twin(tets, np.array(cluster), points, within=ring)
        if alive is None:
            return _best_order_twin(tets, bad, points)
        want &= alive
    return want


@pytest.mark.parametrize("seed", range(4))
def test_whole_mesh_repair_by_points_is_the_best_order_twins(seed):
    """At ring 0 every removal leaves the stars, so local_repair with points repairs the whole
    mesh in the one order that removes the least volume: the twin's, with points the tets do
    not use (ranked apart, as the stuffed mesh's lattice vertices outside the solid) at random
    places among them, some on used points."""
    tets, core = _pinched_block(seed, n=8)
    points = _pinched_block_points(seed, n=8)
    rng = np.random.default_rng(seed)
    unused = np.concatenate([rng.uniform(-1.0, 9.0, (40, 3)), points[rng.integers(len(points), size=10)]])
    points = np.concatenate([points, unused])
    faces = boundary_faces(tets, match_faces(tets)[0])
    bad = np.nonzero(nonmanifold_vertices(faces, len(points)))[0]
    got = local_repair(tets, bad, len(points), rings=0, points=points)
    want = _best_order_twin(tets, bad, points)
    assert not got.all() and np.array_equal(got, want)


@pytest.mark.parametrize("seed", range(4))
def test_each_pinch_cluster_keeps_its_own_best_order(seed):
    """Two blocks pinched near one corner each, apart: local_repair repairs each cluster of
    bad vertices (naive.pinch_clusters) in the order that removes the least volume there, so
    the result is the twin's cluster by cluster, never more volume than the one order best
    over both, and a cluster's repair needs nothing from the other (as a partition's would)."""
    tets_a, core_a = _pinched_block(seed, n=8, within=4)
    tets_b, core_b = _pinched_block(100 + seed, n=8, within=4)
    points_a = _pinched_block_points(seed, n=8)
    n = len(points_a)
    points_b = points_a[:, [1, 2, 0]] * np.array([1.0, -1.0, 1.0]) + np.array([20.0, 0.0, 0.0])  # turned, apart
    tets = np.concatenate([tets_a, tets_b + n]).astype(np.int32)
    core = np.concatenate([core_a, core_b])
    points = np.concatenate([points_a, points_b])
    faces = boundary_faces(tets, match_faces(tets)[0])
    bad = np.nonzero(nonmanifold_vertices(faces, len(core)))[0]
    assert len(naive.pinch_clusters(tets, bad, repair.PINCH_RINGS)) >= 2
    want = _cluster_twin(tets, bad, points)
    got = local_repair(tets, bad, len(core), points=points)
    assert np.array_equal(got, want) and not got.all()
    alone = _best_order_twin(tets, bad, points)  # one order for both blocks

    def volume(alive):
        return sum(abs(naive._det3(points[t[1:]] - points[t[0]])) / 6 for t in tets[~alive])

    assert volume(got) <= volume(alone) + 1e-12


@pytest.mark.parametrize("seed", range(6))
def test_pinch_repair_follows_the_points_not_the_numbering(seed):
    """With the points given, the worklist's order and its ties follow their coordinates (in
    each of PINCH_ORDERS, the least volume removed kept for each cluster): the repair of the pinched block
    against the dictionary twin ranking the vertices so, and the same tets removed (as point
    sets) however the vertices are numbered and the tets ordered.
    Ranges of a Morton partition number the points their own way (a gyroid sheet meshed in
    ranges lost other tets than in one pass before)."""
    tets, core = _pinched_block(seed)
    points = _pinched_block_points(seed)
    faces = boundary_faces(tets, match_faces(tets)[0])
    bad = np.nonzero(nonmanifold_vertices(faces, len(core)))[0]
    want = _cluster_twin(tets, bad, points)
    out, removed, _, _ = remove_pinches(tets.copy(), core.copy(), points)
    assert removed == int((~want).sum()) > 0 and np.array_equal(out, tets[want])
    rng = np.random.default_rng(100 + seed)
    new_id = rng.permutation(len(points))
    shuffled = new_id[tets][rng.permutation(len(tets))]
    moved_points = np.empty_like(points)
    moved_points[new_id] = points
    moved_core = np.empty_like(core)
    moved_core[new_id] = core
    out2, removed2, _, _ = remove_pinches(shuffled.copy(), moved_core, moved_points)
    assert removed2 == removed

    def as_point_sets(t, p):
        return sorted(tuple(sorted(map(tuple, p[row].tolist()))) for row in t)

    assert as_point_sets(out2, moved_points) == as_point_sets(out, points)


@pytest.mark.parametrize("seed", range(6))
def test_pinches_repaired_in_ranges_are_the_whole_meshs(seed):
    """The two pinched blocks' tets cut into ranges at random rows, each range's points
    numbered its own way and each point owned by a random range: the boundary and pinches the
    owners find (range_pinches.pinches_by_owners) are the whole mesh's, and the repair in
    ranges keeps exactly the tets that remove_pinches keeps of the whole mesh."""
    from paroct.range_pinches import (RangeTets, boundary_by_owners, fans_by_owners, pinches_by_owners,
                                      range_boundary, repair_pinches_in_ranges)

    rng = np.random.default_rng(seed)
    tets_a, core_a = _pinched_block(seed, n=8, within=5)
    tets_b, core_b = _pinched_block(50 + seed, n=8)
    points_a = _pinched_block_points(seed, n=8)
    points_b = points_a[:, [2, 0, 1]] + np.array([0.0, 12.0, 0.0])
    n = len(points_a)
    tets = np.concatenate([tets_a, tets_b + n]).astype(np.int32)
    core = np.concatenate([core_a, core_b])
    points = np.concatenate([points_a, points_b])
    cuts = np.sort(rng.choice(np.arange(1, len(tets)), size=int(rng.integers(1, 7)), replace=False))
    owner_of = rng.integers(0, len(cuts) + 1, size=len(points))  # a function of the point
    parts = []
    for rows in np.split(np.arange(len(tets)), cuts):
        ids = rng.permutation(np.unique(tets[rows]))
        local = np.argsort(ids)[np.searchsorted(ids[np.argsort(ids)], tets[rows])].astype(np.int32)
        parts.append(RangeTets(ids.astype(np.int64), local, core[ids], points[ids], owner_of[ids]))
    boundaries = [range_boundary(p, r) for r, p in enumerate(parts)]
    whole = stuffed_boundary(tets, core)
    joined = np.concatenate([b.faces for b in boundaries])
    assert _face_set(naive.unshared_faces(joined)) == _face_set(whole)  # the ranges' boundaries hold the mesh's
    bad = np.flatnonzero(naive.nonmanifold_vertices(whole, len(core)))
    owned = boundary_by_owners(boundaries, len(parts))
    assert bad.size and np.array_equal(pinches_by_owners(fans_by_owners(owned, len(parts))), bad)
    kept = repair_pinches_in_ranges(parts, len(parts))
    assert kept is not None
    out, removed, _, _ = remove_pinches(tets.copy(), core.copy(), points)
    got = np.concatenate([p.ids[p.tets[k]] for p, k in zip(parts, kept)])
    assert removed > 0 and np.array_equal(got, out)


@pytest.mark.parametrize("seed", range(4))
def test_local_vertex_ids_number_by_first_use_dense_or_hashed(seed):
    """topology.local_vertex_ids against a dict numbering each id at its first use: for ids
    packed closely (an array over them) and spread far wider than the rows (hashed), int32
    and int64, with repeats."""
    from paroct.topology import local_vertex_ids

    rng = np.random.default_rng(seed)
    for spread in (50, 10**12):
        for dtype in (np.int32, np.int64):
            ids = rng.integers(0, min(spread, np.iinfo(dtype).max), size=(int(rng.integers(0, 300)), 3)).astype(dtype)
            ids[1::4] = ids[::4][: len(ids[1::4])]  # repeated rows and ids
            first: dict = {}
            for v in ids.ravel().tolist():
                first.setdefault(v, len(first))
            local, vertex_of = local_vertex_ids(ids)
            assert local.dtype == ids.dtype and local.shape == ids.shape
            assert vertex_of.tolist() == list(first)
            assert local.ravel().tolist() == [first[v] for v in ids.ravel().tolist()]
