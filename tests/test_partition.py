"""Meshing in Morton ranges (paroct.partition): the halo of a range against a naive search, and
the merged mesh against the one-process pass, tet for tet and bit for bit."""

import dataclasses
from functools import partial
from pathlib import Path

import manifold3d
import numpy as np
import pytest

import paroct
from paroct import mesher, octant
from paroct.stuffing import DIHEDRAL_BOUND
from paroct.check import canonical_form
from paroct.octree import balance
from paroct.partition import mesh_in_ranges, mesh_range, pack_coords, touching_leaves
from paroct.repair import remove_pinches

from . import naive

DATA = Path(__file__).resolve().parent.parent / "data"
ML = octant.MAX_LEVEL


def _random_tree(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 2:1-balanced octree refined around a few random octants, with some leaves dropped
    (as graded_leaves drops those outside the solid)."""
    rng = np.random.default_rng(seed)
    seeds_l = rng.integers(2, 6, size=4)
    seeds_k = [octant.morton_key(*(rng.integers(0, 1 << int(lev), size=3) * (1 << (ML - int(lev))))) for lev in seeds_l]
    keys, levels = balance(np.array(seeds_k, dtype=np.int64), seeds_l.astype(np.int8))
    kept = rng.random(keys.shape[0]) < 0.8
    return keys[kept], levels[kept]


@pytest.mark.parametrize("seed", range(8))
def test_touching_leaves_match_a_search_of_every_pair(seed):
    keys, levels = _random_tree(seed)
    rng = np.random.default_rng(1000 + seed)
    for _ in range(3):
        first = int(rng.integers(0, keys.shape[0]))
        end = int(rng.integers(first, min(first + 40, keys.shape[0]) + 1))
        got = touching_leaves(keys, levels, first, end)
        assert got.tolist() == naive.touching_leaves(keys, levels, first, end), (first, end)


def _canonical(result):
    return canonical_form(result.mesh.points, result.mesh.tets)


def _oriented_faces(points: np.ndarray, faces: np.ndarray) -> list:
    """Faces as sorted rows of their corners' coordinates, each turned to start at its
    smallest corner (an outward face keeps its orientation)."""
    rows = []
    for face in np.asarray(faces).tolist():
        corners = [tuple(points[v].tolist()) for v in face]
        k = corners.index(min(corners))
        rows.append(tuple(corners[k:] + corners[:k]))
    return sorted(rows)


def _assert_same_finish(ranged, whole, label) -> None:
    """The finish in ranges (range_finish) is mesher._finish's: the same mesh up to numbering,
    boundary faces, point triangles, quality, topology and missed parts; the volume to
    rounding."""
    for got, want in zip(_canonical(ranged), _canonical(whole)):
        assert np.array_equal(got, want), label
    a, b = ranged.report, whole.report
    for name in ("n_tets", "n_vertices", "min_dihedral", "max_dihedral", "min_radius_ratio", "fat_fraction",
                 "interior_min_dihedral", "interior_max_dihedral", "boundary_genus", "boundary_components",
                 "boundary_manifold", "repaired_tets"):
        assert getattr(a, name) == getattr(b, name) or (np.isnan(getattr(a, name)) and np.isnan(getattr(b, name))), \
            (label, name, getattr(a, name), getattr(b, name))
    assert np.array_equal(a.missed_vertices, b.missed_vertices) and np.array_equal(a.missed_faces, b.missed_faces)
    assert a.mesh_volume == pytest.approx(b.mesh_volume, rel=1e-12), label
    assert _oriented_faces(ranged.mesh.points, ranged.boundary_faces) == \
        _oriented_faces(whole.mesh.points, whole.boundary_faces), label
    got = sorted(zip(map(tuple, ranged.mesh.points.tolist()), ranged.point_faces.tolist()))
    assert got == sorted(zip(map(tuple, whole.mesh.points.tolist()), whole.point_faces.tolist())), label


@pytest.mark.parametrize("name, divisions, uniform", [("bunny", 20, False), ("bunny", 40, True),
                                                      ("angle_block", 25, False)])
def test_ranges_merge_into_the_one_process_mesh(name, divisions, uniform):
    surface = paroct.load_surface(DATA / f"{name}.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / divisions
    max_size = size if uniform else None
    whole = paroct.mesh(surface, size, max_size=max_size, thin_features=False)
    assert "warps" not in whole.report.stage_seconds  # no mending: its tets were in the bound at once
    want_points, want_tets = _canonical(whole)
    for n_parts in (1, 2, 5, whole.report.n_leaves + 3):  # more ranges than leaves: some empty
        ranged = mesh_in_ranges(surface, size, n_parts=n_parts, max_size=max_size, thin_features=False)
        points, tets = _canonical(ranged)
        assert np.array_equal(points, want_points) and np.array_equal(tets, want_tets), n_parts
        _assert_same_finish(ranged, whole, n_parts)


def test_ranges_cut_through_transition_leaves_and_share_points():
    """The ranges meet across leaves of different sizes (templates on both sides), read only
    the band pieces near them, and share lattice vertices and cut points, placed alike
    (merge_ranges checks)."""
    from paroct.partition import BandIndex, band_in_range, band_pieces_for, octree_in_range, range_bounds
    from paroct.sizing import size_field

    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 20
    frame, snapped, faces, _ = _pass_surface(surface, size)
    field = size_field(size)
    key_bounds = range_bounds(frame, snapped, 6, frame.levels - field.coarse_depth)
    band = [band_in_range(frame, snapped, faces, int(key_bounds[r]), int(key_bounds[r + 1])) for r in range(6)]
    surface_keys = np.concatenate([p.surface_keys for p in band])
    band_keys = np.concatenate([p.band_keys for p in band])
    octrees = [octree_in_range(frame, snapped, faces, surface, field, surface_keys, band_keys, int(key_bounds[r]),
                               int(key_bounds[r + 1])) for r in range(6)]
    keys = np.concatenate([k for k, _ in octrees])
    levels = np.concatenate([lev for _, lev in octrees])
    bounds = np.cumsum([0] + [k.shape[0] for k, _ in octrees])
    pieces, read_counts = [], []
    for r in range(6):
        first, end = int(bounds[r]), int(bounds[r + 1])
        rows = np.concatenate([np.arange(first, end), touching_leaves(keys, levels, first, end)])
        read = band_pieces_for(keys, levels, rows, frame.levels, key_bounds)
        read_counts.append(read.shape[0])
        pieces.append(mesh_range(frame, keys, levels, BandIndex.from_pieces([band[i] for i in read]), first, end))
    assert min(read_counts) < 6  # a range reads the band near it, not all of it
    mixed = 0
    for r in range(1, 6):
        around = touching_leaves(keys, levels, int(bounds[r]), int(bounds[r + 1]))
        mixed += len(set(levels[around].tolist()) | set(levels[bounds[r]:bounds[r + 1]].tolist())) > 1
    assert mixed > 0
    shared_vertices = np.intersect1d(pieces[0].vertex_keys, pieces[1].vertex_keys)
    shared_cuts = np.intersect1d(pieces[0].cut_keys, pieces[1].cut_keys)
    assert shared_vertices.size > 0 and shared_cuts.size > 0
    assert sum(p.tets.shape[0] for p in pieces) > 0


def _graded_pass_in_ranges(divisions, n_parts):
    """bunny's graded pass at diag/divisions (one process: finest_band, octree_around_band) and
    n_parts key ranges of its max_size octants: (frame, snapped, faces, band, keys, levels,
    key_bounds)."""
    from paroct.mesher import MeshReport, X_AXIS_DIRECTION, finest_band, octree_around_band
    from paroct.partition import range_bounds
    from paroct.sizing import size_field

    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / divisions
    frame, snapped, faces, crossings = _pass_surface(surface, size)
    field = size_field(size)
    band = finest_band(frame, snapped, faces, dict(crossings), MeshReport(size, frame.levels))
    keys, levels = octree_around_band(frame, crossings[X_AXIS_DIRECTION], surface, field, band.surface_keys, band.keys)
    return frame, snapped, faces, band, keys, levels, range_bounds(frame, snapped, n_parts,
                                                                   frame.levels - field.coarse_depth)


@pytest.mark.parametrize("n_parts", [1, 3])
def test_a_range_pass_that_needs_mending_mends_as_mesh_does(n_parts):
    """bunny at diag/30, uniform: a stuffed tet of 10.48 degrees, which mesh() mends by other
    warps over the whole mesh; the ranges' lattice tets, joined, are stuffed and mended the
    same: the same mesh, in the bound, with no warning of bad tets."""
    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 30
    whole = paroct.mesh(surface, size, max_size=size, thin_features=False)
    ranged = mesh_in_ranges(surface, size, n_parts=n_parts, max_size=size, thin_features=False)
    assert "warps" in whole.report.stage_seconds and "warps" in ranged.report.stage_seconds
    assert ranged.report.min_dihedral >= 10.7 and not any("degrees" in w for w in ranged.report.warnings)
    a, b = _canonical(whole), _canonical(ranged)
    assert all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(a, b))
    assert ranged.report.n_tets == whole.report.n_tets and ranged.report.repaired_tets == whole.report.repaired_tets


def test_joined_range_lattices_are_the_whole_octrees_lattice():
    """merge_range_lattices over 4 ranges of bunny at diag/20 (graded): the lattice tets,
    classes and warps of the one pass, named by coordinates, the face centres that are no
    leaf's corner numbered last; a piece that classes a shared vertex otherwise is refused."""
    from paroct.lattice import graded_tets, number_vertices
    from paroct.mesher import vertex_classes
    from paroct.octree import octant_lattice_anchors
    from paroct.partition import BandIndex, band_in_range, merge_range_lattices, range_lattice

    frame, snapped, faces, band, keys, levels, key_bounds = _graded_pass_in_ranges(20, 4)
    index = BandIndex.from_pieces([band_in_range(frame, snapped, faces, int(key_bounds[r]), int(key_bounds[r + 1]))
                                   for r in range(4)])
    bounds = np.searchsorted(keys, key_bounds)
    lattices = [range_lattice(frame, keys, levels, index, int(bounds[r]), int(bounds[r + 1])) for r in range(4)]
    assert min(p.tets.shape[0] for p in lattices) > 0
    coords, tets, inside, cuts, targets, first_centre = merge_range_lattices(lattices, index)

    vertices = number_vertices(octant_lattice_anchors(keys, frame),
                               np.int64(1) << (frame.levels - levels.astype(np.int64)), prefix=band.stuffing.coords,
                               eager=False)
    want_inside = vertex_classes(vertices, band.stuffing.inside)
    want = graded_tets(vertices, want_inside)

    def named(coords, tets):
        return sorted(tuple(sorted(map(tuple, coords[t].tolist()))) for t in tets)

    assert named(coords, tets) == named(vertices.coords, want)
    used = np.unique(want)
    centres = used[used >= vertices.first_centre]
    assert centres.size > 0
    assert sorted(map(tuple, coords[first_centre:].tolist())) == sorted(map(tuple, vertices.coords[centres].tolist()))
    by_point = {c: i for i, c in enumerate(map(tuple, coords.tolist()))}
    assert all(inside[by_point[c]] == want_inside[v] for v, c in zip(used, map(tuple, vertices.coords[used].tolist())))
    b = band.stuffing

    def warps(coords, starts, ends, targets):
        return {tuple(coords[v]): (tuple(coords[starts[e]]), tuple(coords[ends[e]]))
                for v, e in enumerate(targets.tolist()) if e >= 0 and tuple(coords[v]) in by_point}

    got = warps(coords, cuts.starts, cuts.ends, targets)
    assert got == warps(b.coords, b.cuts.starts, b.cuts.ends, b.targets) and len(got) > 0
    shared = np.intersect1d(pack_coords(lattices[0].coords), pack_coords(lattices[1].coords))
    assert shared.size > 0
    flipped = lattices[1].inside.copy()
    flipped[np.flatnonzero(pack_coords(lattices[1].coords) == shared[0])[0]] ^= True
    with pytest.raises(AssertionError, match="disagree on a shared lattice vertex"):
        merge_range_lattices([lattices[0], dataclasses.replace(lattices[1], inside=flipped)], index)


@pytest.mark.parametrize("seed", range(6))
def test_owned_ids_number_each_key_once_by_owner_then_key(seed):
    """owners.owned_ids against a dict of every (owner, key) pair: pieces with repeated keys,
    keys shared between pieces, owners with no key, an empty piece."""
    from paroct.owners import owned_ids

    rng = np.random.default_rng(seed)
    n_ranges = int(rng.integers(1, 7))
    universe = np.unique(rng.integers(0, 1 << 40, 300))
    owner_of = rng.integers(0, n_ranges, universe.shape[0])  # the owner is a function of the key
    pieces = [rng.choice(universe, size=int(rng.integers(0, 120))) for _ in range(int(rng.integers(1, 6)))]
    pieces.append(np.zeros(0, dtype=np.int64))
    owners = [owner_of[np.searchsorted(universe, k)] for k in pieces]
    ids, count = owned_ids(pieces, owners, n_ranges)
    want, want_count = naive.owned_ids(pieces, owners)
    assert count == want_count and all(got.tolist() == w for got, w in zip(ids, want))


def test_every_leaf_anchor_is_owned_by_the_leaf_range_and_packed_points_unpack():
    """point_owners: the lattice point at a leaf's minimum corner belongs to the range holding
    the leaf (its key is that of the finest cell there); unpack_coords inverts pack_coords."""
    from paroct.octree import octant_lattice_anchors
    from paroct.partition import point_owners, unpack_coords

    frame, _, _, _, keys, levels, key_bounds = _graded_pass_in_ranges(25, 5)
    leaf_range = np.searchsorted(key_bounds, keys, side="right") - 1
    anchors = octant_lattice_anchors(keys, frame)
    assert np.array_equal(point_owners(frame, anchors, key_bounds), leaf_range) and len(set(leaf_range.tolist())) > 2
    far = (np.int64(1) << frame.levels) * np.ones((1, 3), dtype=np.int64)  # a corner of the frame's far faces
    assert point_owners(frame, far, key_bounds)[0] == 4
    assert np.array_equal(unpack_coords(pack_coords(anchors)), anchors)


def test_a_range_share_holds_what_its_whole_pieces_would_give():
    """range_shares cuts each band piece a range reads to the corners of its finest leaves
    before joining them: the same index (vertices, classes, warps, cut edges and points) as
    joining the whole pieces and keeping what those corners read, and its leaves are its own
    and touching ones, numbered locally."""
    from paroct.frame import CUBE_CORNERS
    from paroct.octree import octant_lattice_anchors
    from paroct.partition import BandIndex, band_in_range, band_pieces_for, range_shares, touching_leaves

    frame, snapped, faces, _, keys, levels, key_bounds = _graded_pass_in_ranges(25, 5)
    pieces = [band_in_range(frame, snapped, faces, int(key_bounds[r]), int(key_bounds[r + 1])) for r in range(5)]
    leaf_bounds = np.searchsorted(keys, key_bounds)
    shares = list(range_shares(frame, keys, levels, key_bounds, pieces, leaf_bounds))
    assert len(shares) == 5
    for r, share in enumerate(shares):
        first, end = int(leaf_bounds[r]), int(leaf_bounds[r + 1])
        around = touching_leaves(keys, levels, first, end)
        rows = np.sort(np.concatenate([np.arange(first, end), around]))
        assert np.array_equal(share.keys, keys[rows]) and np.array_equal(share.keys[share.first:share.end],
                                                                         keys[first:end])
        assert np.array_equal(share.keys[share.around], keys[around])
        read = band_pieces_for(keys, levels, rows, frame.levels, key_bounds)
        # The corners of its finest leaves, listed: the band vertices it reads are among them.
        anchors = octant_lattice_anchors(keys[rows], frame)[levels[rows] == frame.levels]
        corners = (anchors[:, None, :] + CUBE_CORNERS[None, :, :]).reshape(-1, 3)
        whole = BandIndex.from_pieces([pieces[i] for i in read])
        want = whole.near(np.flatnonzero(np.isin(whole.vertex_keys, pack_coords(corners))))
        for name in ("vertex_keys", "coords", "inside", "target_keys", "keys", "starts", "ends", "directions",
                     "points", "faces"):
            assert np.array_equal(getattr(share.band, name), getattr(want, name)), (r, name)
        assert np.array_equal(share.band.fracs.view(np.int64), want.fracs.view(np.int64))
    assert sum(s.band.keys.shape[0] for s in shares) > 0


def test_a_part_thinner_than_the_lattice_is_kept_by_halving_the_band_in_ranges():
    """A plate a tenth of the size thick: every pass down to size / 4 drops it; the ranges
    halve the whole band as mesh() would (mesher.halve_whole_band) and keep it at size / 8,
    the whole band's floor.  Without thin_features the one pass has no tets: refused."""
    surface = paroct.load_surface(manifold3d.Manifold.cube([1.0, 1.0, 0.01]))
    ranged = mesh_in_ranges(surface, 0.1, n_parts=2)
    report = ranged.report
    assert report.size == 0.1 / 8 and report.n_tets > 0 and not report.warnings
    assert abs(report.volume_error) < 0.01 and (report.boundary_components, report.boundary_genus) == (1, 0)
    assert [note.split(":")[0] for note in report.notes] == ["boundary size 0.1 -> 0.05", "boundary size 0.05 -> 0.025",
                                                             "boundary size 0.025 -> 0.0125"]
    assert DIHEDRAL_BOUND[0] <= report.min_dihedral <= report.max_dihedral <= DIHEDRAL_BOUND[1]
    with pytest.raises(paroct.ParoctError, match="no tets"):
        mesh_in_ranges(surface, 0.1, n_parts=2, thin_features=False)


@pytest.mark.parametrize("options, match", [({"thin_features": "yes"}, "thin_features = 'yes': must be True or False"),
                                             ({"min_size": 1.0}, "min_size = 1 must be at most size"),
                                             ({"max_memory": -1}, "max_memory = -1: must be a positive number"),
                                             ({"max_memory": 10}, "more than the 10 bytes allowed")])
def test_ranges_refuse_bad_thin_feature_options_as_mesh_does(options, match):
    for mesher_call in (paroct.mesh, partial(mesh_in_ranges, n_parts=2)):
        with pytest.raises(paroct.ParoctError, match=match):
            mesher_call(DATA / "bunny.stl", divisions=10, **options)


def test_ranges_that_reach_the_whole_bands_floor_say_so():
    """A plate a fiftieth of the size thick loses its volume at every whole band down to size /
    8: the warning says the whole band went as far as it goes, not that refinement near thin
    places reached min_size (which mesh() does and the ranges do not)."""
    surface = paroct.load_surface(manifold3d.Manifold.cube([1.0, 1.0, 0.002]))
    with pytest.raises(paroct.ParoctError, match="the whole boundary refined to 0.0125, as far as it goes"):
        mesh_in_ranges(surface, 0.1, n_parts=2)


def test_ranges_halve_the_band_as_mesh_does_where_it_halves_the_whole_band():
    """Bunny at diag/30 loses 1.8 % of its volume; mesh() meshes the whole band at size / 2
    (estimated at fewer tets than refining near its thin places), and so do the ranges: the
    same mesh, boundary and report."""
    surface = paroct.load_surface(DATA / "bunny.stl")
    size = surface.diagonal / 30
    whole = paroct.mesh(surface, size)
    assert whole.report.size == size / 2 and "everywhere" in whole.report.notes[-1]
    for n_parts in (1, 4):
        ranged = mesh_in_ranges(surface, size, n_parts=n_parts)
        _assert_same_finish(ranged, whole, n_parts)
        assert ranged.report.notes[0].startswith(f"boundary size {size:.4g} -> {size / 2:.4g}")


def test_ranges_past_the_octants_the_surface_meets_are_dropped():
    """A million ranges of a 30 k-tet sphere: all but a few would be empty (ranges are whole
    coarse octants); they are dropped, so the pass takes about what a few ranges take (it took
    minutes, 0.6 ms a range), and the mesh is mesh()'s."""
    sphere = manifold3d.Manifold.sphere(1.0, 24)
    calls = []

    def counting_map(function, *iterables):
        results = list(map(function, *iterables))
        calls.append(len(results))
        return results

    ranged = mesh_in_ranges(sphere, 0.1, n_parts=10**6, mapper=counting_map, thin_features=False)
    whole = paroct.mesh(sphere, 0.1, thin_features=False)
    assert 1 <= max(calls) < 1000
    for got, want in zip(_canonical(ranged), _canonical(whole)):
        assert np.array_equal(got, want)
    # Past one range a surface vertex the bounds repeat: 10**30 ranges are those, with no
    # array of 10**30 bounds (numpy's "maximum allowed dimension exceeded" before).
    for got, want in zip(_canonical(mesh_in_ranges(sphere, 0.1, n_parts=10**30, thin_features=False)), _canonical(whole)):
        assert np.array_equal(got, want)


@pytest.mark.parametrize("mapper, match", [
    (lambda f, *its: list(map(f, *its))[::-1], "out of place"),  # completion order, say
    (lambda f, *its: list(map(f, *its))[:-1], r"returned 3 results for 4 ranges"),
    (lambda f, *its: list(map(f, *its)) * 2, r"returned 8 results for 4 ranges"),
    (lambda f, *its: [object() for _ in zip(*its)], "returned 'object' results where BandPiece was due"),
    (lambda f, *its: None, "mapper\\(function, \\*iterables\\) failed"),
    (lambda f: [], "mapper\\(function, \\*iterables\\) failed"),
])
def test_a_mapper_that_is_not_map_is_refused_in_one_line(mapper, match):
    """A mapper's results that are not map's (out of order, too few or many, not the results
    themselves: a Dask client's map without gather) gave AssertionErrors of the merge or
    TypeErrors from inside; now a ParoctError says what the mapper did."""
    with pytest.raises(paroct.ParoctError, match=match):
        mesh_in_ranges(DATA / "bunny.stl", divisions=15, n_parts=4, mapper=mapper)


def test_ranges_refuse_both_size_and_divisions_as_mesh_does():
    with pytest.raises(paroct.ParoctError, match=r"size = 0.1 and divisions = 10: give one"):
        mesh_in_ranges(DATA / "bunny.stl", 0.1, divisions=10, n_parts=2)


@pytest.mark.parametrize("n_parts", [0, -2, 2.5, True, "3"])
def test_a_range_count_that_is_no_whole_number_is_refused_in_one_line(n_parts):
    with pytest.raises(paroct.ParoctError, match=r"n_parts = .*: must be a whole number of ranges, at least 1"):
        mesh_in_ranges(DATA / "bunny.stl", n_parts=n_parts, divisions=10)


def _random_faces(seed: int, levels: int, bits: int, n_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Snapped vertices (some off the frame, some on cell planes) and random triangles."""
    rng = np.random.default_rng(seed)
    scale = 1 << (levels + bits)
    snapped = rng.integers(-scale // 8, scale + scale // 8, size=(3 * n_faces, 3)).astype(np.int64)
    snapped[::5] &= ~np.int64((1 << bits) - 1)  # on lattice planes
    faces = rng.integers(0, snapped.shape[0], size=(n_faces, 3)).astype(np.int64)
    faces[::7, 1] = faces[::7, 0]  # some small, degenerate triangles
    return snapped, faces


def _random_interval(rng, levels: int) -> tuple[int, int]:
    step = 1 << (3 * (ML - levels))
    cells = np.sort(rng.integers(0, 1 << (3 * levels), size=2))
    return int(cells[0]) * step, (int(cells[1]) + int(rng.integers(0, 2))) * step


@pytest.mark.parametrize("seed", range(6))
def test_faces_near_an_interval_match_a_search_of_every_cell(seed):
    from paroct.partition import _faces_near_interval

    levels, bits = 3, 4
    snapped, faces = _random_faces(seed, levels, bits, 60)
    rng = np.random.default_rng(2000 + seed)
    intervals = [_random_interval(rng, levels) for _ in range(4)] + [(0, 1 << (3 * ML)), (5, 5)]
    for first, end in intervals:
        for margin in (0, 2):
            got = np.flatnonzero(_faces_near_interval(snapped, faces, bits, levels, margin, first, end))
            assert got.tolist() == naive.faces_near_interval(snapped, faces, bits, levels, margin, first, end)


@pytest.mark.parametrize("seed", range(4))
def test_the_box_of_an_interval_is_the_box_of_its_cells(seed):
    from paroct.partition import _interval_box

    levels = 3
    rng = np.random.default_rng(5000 + seed)
    shift = ML - levels
    for first, end in [_random_interval(rng, levels) for _ in range(6)] + [(0, 1 << (3 * ML))]:
        cells = np.array([(x, y, z) for x in range(8) for y in range(8) for z in range(8)
                          if first <= naive.morton_key(x << shift, y << shift, z << shift) < end]).reshape(-1, 3)
        lo, hi = _interval_box(first, end, levels)
        if cells.size:
            assert lo.tolist() == cells.min(axis=0).tolist() and hi.tolist() == cells.max(axis=0).tolist()
        else:
            assert np.any(hi < lo)


@pytest.mark.parametrize("seed", range(4))
def test_cells_near_an_interval_match_a_search_of_every_cell(seed):
    """_octants_near_interval of finest cells, grown by one finest cell: the cells within
    Chebyshev distance one of a cell of the interval."""
    from paroct.partition import _octants_near_interval

    levels = 3
    rng = np.random.default_rng(3000 + seed)
    cells = rng.integers(0, 1 << levels, size=(80, 3))
    keys = octant.morton_keys(cells << (ML - levels))
    for first, end in [_random_interval(rng, levels) for _ in range(4)]:
        assert _octants_near_interval(keys, levels, levels, first, end).tolist() == \
            naive.cells_near_interval(cells, levels, first, end)


@pytest.mark.parametrize("seed", range(4))
def test_faces_over_rows_match_a_search_of_every_row(seed):
    from paroct.frame import EDGE_DIRECTIONS, row_basis
    from paroct.partition import faces_over_rows

    levels, bits = 3, 4
    snapped, faces = _random_faces(seed, levels, bits, 60)
    rng = np.random.default_rng(4000 + seed)
    for direction in range(EDGE_DIRECTIONS.shape[0]):
        points = rng.integers(0, (1 << levels) + 1, size=(int(rng.integers(1, 6)), 3)).astype(np.int64)
        got = faces_over_rows(snapped, faces, bits, direction, points)
        assert got.tolist() == naive.faces_over_rows(snapped, faces, bits, row_basis(direction), points)


def _pass_surface(surface, size):
    from paroct.frame import fat_frame
    from paroct.mesher import checked_x_rows

    frame = fat_frame(surface.bbox_min, surface.bbox_max, size)
    return (frame, *checked_x_rows(surface, frame))


def _same_band(a, b) -> None:
    assert np.array_equal(a.surface_keys, b.surface_keys) and np.array_equal(a.keys, b.keys)
    x, y = a.stuffing, b.stuffing
    for name in ("coords", "inside", "targets"):
        assert np.array_equal(getattr(x, name), getattr(y, name)), name
    for name in ("starts", "ends", "directions", "points", "faces"):
        assert np.array_equal(getattr(x.cuts, name), getattr(y.cuts, name)), name
    assert np.array_equal(x.cuts.fracs.view(np.int64), y.cuts.fracs.view(np.int64))
    assert all(np.array_equal(p, q) for p, q in zip(x.cuts.table, y.cuts.table))


_WAVY = manifold3d.Manifold.cylinder(2.0, 0.6, 0.25, 24).rotate([30, 50, 10]) + \
    manifold3d.Manifold.sphere(0.5, 24).translate([0.3, 0.2, 1.5]) - manifold3d.Manifold.cube([0.3, 0.3, 4.0], True)


@pytest.mark.parametrize("source, divisions", [("bunny", 40), ("angle_block", 30), ("wavy", 25)])
def test_the_band_in_key_ranges_is_the_whole_surface_band(source, divisions):
    """Each range's band from the triangles near it alone, merged: the same arrays as the band
    of the whole surface (cells, corners, classes, cut points bit for bit, warps, lookup
    table), however the key space is cut, ranges ending inside octants or empty included."""
    from paroct.mesher import MeshReport, finest_band
    from paroct.partition import band_in_range, finest_band_in_ranges, merge_band_pieces

    surface = paroct.load_surface(_WAVY if source == "wavy" else DATA / f"{source}.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / divisions
    frame, snapped, faces, crossings = _pass_surface(surface, size)
    report = MeshReport(size, frame.levels)
    whole = finest_band(frame, snapped, faces, dict(crossings), report)
    assert whole.stuffing.targets.max() >= 0 and whole.stuffing.cuts.starts.size > 0
    for n_parts in (1, 2, 7):
        ranged_report = MeshReport(size, frame.levels)
        _same_band(finest_band_in_ranges(frame, snapped, faces, n_parts, ranged_report), whole)
        assert ranged_report.unresolved_cuts == report.unresolved_cuts
    rng = np.random.default_rng(7)
    step = 1 << (3 * (ML - frame.levels))
    cuts = np.sort(rng.choice(whole.keys, size=5, replace=False)) + step * rng.integers(0, 2, size=5)
    bounds = [0, *cuts.tolist(), int(cuts[-1]), 1 << (3 * ML)]  # an empty range before the last
    pieces = [band_in_range(frame, snapped, faces, bounds[r], bounds[r + 1]) for r in range(len(bounds) - 1)]
    _same_band(merge_band_pieces(frame, pieces, MeshReport(size, frame.levels)), whole)


def test_band_pieces_that_disagree_are_refused():
    """A cut point two pieces hold must come out the same in both: a piece whose copy differs
    in its last bit is an AssertionError, not a merged band."""
    from paroct.mesher import MeshReport
    from paroct.partition import range_bounds, band_in_range, merge_band_pieces, pack_coords

    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 20
    frame, snapped, faces, _ = _pass_surface(surface, size)
    bounds = range_bounds(frame, snapped, 3)
    pieces = [band_in_range(frame, snapped, faces, int(bounds[r]), int(bounds[r + 1])) for r in range(3)]
    first = set(zip(pack_coords(pieces[0].edge_starts).tolist(), pack_coords(pieces[0].edge_ends).tolist()))
    second = zip(pack_coords(pieces[1].edge_starts).tolist(), pack_coords(pieces[1].edge_ends).tolist())
    shared = np.array([e for e, pair in enumerate(second) if pair in first])
    assert shared.size > 0
    fracs = pieces[1].fracs.copy()
    fracs[shared[0]] = np.nextafter(fracs[shared[0]], 2.0)
    pieces[1] = dataclasses.replace(pieces[1], fracs=fracs)
    with pytest.raises(AssertionError, match="disagree on a shared cut edge"):
        merge_band_pieces(frame, pieces, MeshReport(size, frame.levels))


@pytest.mark.parametrize("source, divisions, uniform", [("bunny", 80, False), ("bunny", 40, True), ("wavy", 30, False)])
def test_the_octree_in_key_ranges_is_the_whole_octree(source, divisions, uniform):
    """Each range of whole max_size octants balanced from the band and seeds within one
    max_size octant of it: together, the whole pass's leaves, key for key and level for level
    (the ring matters: without it, bunny at diag/80 in three ranges has 77 leaves fewer)."""
    from paroct.mesher import MeshReport, X_AXIS_DIRECTION, finest_band, octree_around_band
    from paroct.partition import octree_in_range, range_bounds
    from paroct.sizing import size_field

    surface = paroct.load_surface(_WAVY if source == "wavy" else DATA / f"{source}.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / divisions
    frame, snapped, faces, crossings = _pass_surface(surface, size)
    field = size_field(size, size if uniform else None)
    band = finest_band(frame, snapped, faces, dict(crossings), MeshReport(size, frame.levels))
    keys, levels = octree_around_band(frame, crossings[X_AXIS_DIRECTION], surface, field, band.surface_keys,
                                      band.keys)
    assert (len(set(levels.tolist())) == 1) == uniform
    coarse = frame.levels - field.coarse_depth
    for n_parts in (2, 3, 8):
        bounds = range_bounds(frame, snapped, n_parts, coarse)
        parts = [octree_in_range(frame, snapped, faces, surface, field, band.surface_keys, band.keys, int(bounds[r]),
                                 int(bounds[r + 1])) for r in range(n_parts)]
        assert np.array_equal(np.concatenate([k for k, _ in parts]), keys), n_parts
        assert np.array_equal(np.concatenate([lev for _, lev in parts]), levels), n_parts
    step = 1 << (3 * (ML - coarse))
    with pytest.raises(ValueError, match="not whole octants"):
        octree_in_range(frame, snapped, faces, surface, field, band.surface_keys, band.keys, step // 2, step)


def test_ranges_refuse_a_surface_overlapping_itself_as_mesh_does():
    """Each range reads only the x rows through its corners; together they hold every crossing,
    so the bent bar whose ends pass through each other is refused in ranges too, at a point
    where a row enters the solid a second time."""
    from .test_mesher import _bent_bar_overlapping_itself

    vertices, faces = _bent_bar_overlapping_itself()
    surface = paroct.load_surface((vertices, faces))
    for n_parts in (1, 5):
        with pytest.raises(paroct.ParoctError, match="enters or leaves the solid twice in a row"):
            mesh_in_ranges(surface, divisions=20, n_parts=n_parts)


def test_ranges_run_side_by_side_in_other_processes():
    """mapper runs the three stages of every range: with a process pool (the stages' functions
    and arguments pickle), the same mesh as one after another; each stage maps every range."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 25
    calls = []

    def recording_map(function, *iterables):
        items = [list(i) for i in iterables]  # a stage may hand its tasks over as they are made
        calls.append(len(items[0]))
        return map(function, *items)

    alone = mesh_in_ranges(surface, size, n_parts=3, mapper=recording_map, thin_features=False)  # one pass
    assert calls == [3, 3, 3]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        side_by_side = mesh_in_ranges(surface, size, n_parts=3, mapper=pool.map, thin_features=False)
    for got, want in zip(_canonical(side_by_side), _canonical(alone)):
        assert np.array_equal(got, want)
    with pytest.raises(paroct.ParoctError, match="mapper = 4"):
        mesh_in_ranges(surface, size, n_parts=3, mapper=4)


def _gyroid_sheet() -> manifold3d.Manifold:
    """A gyroid sheet (|f| < 0.4, two periods) clipped to a box: thin and bent everywhere,
    so a coarse uniform pass pinches at hundreds of vertices."""
    import math

    k, phase = 4 * math.pi, (4.4992, 0.13, 5.5768)

    def sdf(x, y, z):
        X, Y, Z = k * x + phase[0], k * y + phase[1], k * z + phase[2]
        f = math.sin(X) * math.cos(Y) + math.sin(Y) * math.cos(Z) + math.sin(Z) * math.cos(X)
        return min((0.4 - abs(f)) / k, 0.5 - max(abs(x), abs(y), abs(z)))

    return manifold3d.Manifold.level_set(sdf, [-0.55, -0.55, -0.55, 0.55, 0.55, 0.55], 0.042)


def test_ranges_repair_pinches_as_the_one_pass_does(monkeypatch):
    """The gyroid sheet at diag/50, uniform, repairs 426 tets at pinches: repaired in the
    ranges (range_pinches), the same tets go, and the ranges finish the mesh (range_finish):
    no pinch repair nor check runs on the merged mesh (when the repair's order came from the
    vertex ids, both passes repaired 441 tets, not the same ones, and the meshes differed)."""
    surface = paroct.load_surface(_gyroid_sheet())
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 50
    whole = paroct.mesh(surface, size, max_size=size, thin_features=False)
    assert whole.report.repaired_tets > 100 and "warps" not in whole.report.stage_seconds
    want = _canonical(whole)
    for n_parts in (2, 7):
        checked = []  # the merged mesh is never repaired nor finished in one place: the ranges did it
        monkeypatch.setattr(mesher, "remove_pinches", lambda *a: checked.append(remove_pinches(*a)) or checked[-1])
        ranged = mesh_in_ranges(surface, size, n_parts=n_parts, max_size=size, thin_features=False)
        assert checked == []
        assert ranged.report.repaired_tets == whole.report.repaired_tets
        for got, expected in zip(_canonical(ranged), want):
            assert np.array_equal(got, expected), n_parts
        monkeypatch.undo()
        _assert_same_finish(ranged, whole, n_parts)


@pytest.mark.parametrize("seed", range(4))
def test_points_on_finest_leaves_match_the_leaves_corners_listed(seed):
    """partition.FinestLeaves.corners_among (eight binary searches a point) against the set of the
    corners of every finest leaf, on random leaves and random points, some on the frame's
    edges and outside it."""
    from paroct.frame import CUBE_CORNERS
    from paroct.frame import FatFrame
    from paroct.partition import finest_leaves

    rng = np.random.default_rng(6100 + seed)
    levels = 4
    cells = np.unique(rng.integers(0, 1 << levels, size=(int(rng.integers(1, 300)), 3)), axis=0)
    fine_keys = np.sort(octant.morton_keys(cells << (ML - levels)))
    corners = {tuple(c) for c in (cells[:, None, :] + CUBE_CORNERS[None, :, :]).reshape(-1, 3).tolist()}
    points = rng.integers(-1, (1 << levels) + 2, size=(400, 3)).astype(np.int64)
    frame = FatFrame(np.zeros(3), 1.0, levels)
    got = finest_leaves(fine_keys, np.full(fine_keys.shape[0], levels, dtype=np.int8), frame).corners_among(points)
    assert got.tolist() == [tuple(p) in corners for p in points.tolist()] and got.any()


@pytest.mark.parametrize("seed", range(4))
def test_keys_are_routed_to_the_ranges_they_are_near(seed):
    """keys_near_ranges (each cell's 27 neighbours of the coarse level, looked up once)
    against every range testing every key (_octants_near_interval, itself against a search
    of every cell), on random cells and random ranges of whole coarse octants."""
    from paroct.partition import _octants_near_interval, keys_near_ranges

    rng = np.random.default_rng(6000 + seed)
    levels, coarse = 5, 2
    cells = rng.integers(0, 1 << levels, size=(300, 3))
    keys = np.unique(octant.morton_keys(cells << (ML - levels)))
    step = 1 << (3 * (ML - coarse))
    inner = np.sort(rng.integers(0, 1 << (3 * coarse), size=int(rng.integers(1, 7)))) * step
    bounds = np.array([0, *inner.tolist(), 1 << (3 * ML)], dtype=np.int64)
    routed = keys_near_ranges(keys, coarse, bounds)
    assert len(routed) == len(bounds) - 1
    for r in range(len(bounds) - 1):
        want = keys[_octants_near_interval(keys, levels, coarse, int(bounds[r]), int(bounds[r + 1]))]
        assert np.array_equal(routed[r], want), r
