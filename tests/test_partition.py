"""Meshing in Morton ranges (paroct.partition): the halo of a range against a naive search, and
the merged mesh against the one-process pass, tet for tet and bit for bit."""

from pathlib import Path

import manifold3d
import numpy as np
import pytest

import paroct
from paroct import octant
from paroct.check import canonical_form
from paroct.octree import balance
from paroct.partition import leaf_ranges, mesh_in_ranges, mesh_range, touching_leaves

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


def test_leaf_ranges_cover_the_leaves_in_order_and_evenly():
    for n, k in ((10, 3), (7, 7), (3, 5), (0, 2), (1000, 16)):
        b = leaf_ranges(n, k)
        sizes = np.diff(b)
        assert b[0] == 0 and b[-1] == n and len(b) == k + 1 and np.all(sizes >= 0)
        assert sizes.max() - sizes.min() <= 1
    with pytest.raises(ValueError):
        leaf_ranges(5, 0)


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
        ranged = mesh_in_ranges(surface, size, n_parts=n_parts, max_size=max_size)
        points, tets = _canonical(ranged)
        assert np.array_equal(points, want_points) and np.array_equal(tets, want_tets), n_parts
        assert ranged.report.min_dihedral == whole.report.min_dihedral
        assert ranged.report.repaired_tets == whole.report.repaired_tets
        assert ranged.report.boundary_genus == whole.report.boundary_genus


def test_ranges_cut_through_transition_leaves_and_share_points():
    """The ranges meet across leaves of different sizes (templates on both sides), and the
    pieces share lattice vertices and cut points, placed alike (merge_ranges checks)."""
    from paroct.frame import fat_frame
    from paroct.mesher import MeshReport, checked_x_rows, graded_leaves
    from paroct.partition import BandIndex
    from paroct.sizing import size_field

    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 20
    frame = fat_frame(surface.bbox_min, surface.bbox_max, size)
    snapped, faces, crossings = checked_x_rows(surface, frame)
    keys, levels, band = graded_leaves(frame, snapped, faces, crossings, surface, size_field(size),
                                       MeshReport(size=size, levels=frame.levels))
    bounds = leaf_ranges(keys.shape[0], 4)
    index = BandIndex.build(band)
    pieces = [mesh_range(frame, keys, levels, index, int(bounds[r]), int(bounds[r + 1])) for r in range(4)]
    mixed = 0
    for r in range(1, 4):
        around = touching_leaves(keys, levels, int(bounds[r]), int(bounds[r + 1]))
        mixed += len(set(levels[around].tolist()) | set(levels[bounds[r]:bounds[r + 1]].tolist())) > 1
    assert mixed > 0
    shared_vertices = np.intersect1d(pieces[0].vertex_keys, pieces[1].vertex_keys)
    shared_cuts = np.intersect1d(pieces[0].cut_ids, pieces[1].cut_ids)
    assert shared_vertices.size > 0 and shared_cuts.size > 0
    assert sum(p.tets.shape[0] for p in pieces) > 0


def test_a_range_pass_that_needs_mending_says_so():
    """bunny at diag/30, uniform: a stuffed tet of 10.48 degrees, which mesh() mends by other
    warps over the whole mesh; the ranges keep it and warn."""
    surface = paroct.load_surface(DATA / "bunny.stl")
    size = float(np.linalg.norm(surface.bbox_max - surface.bbox_min)) / 30
    whole = paroct.mesh(surface, size, max_size=size, thin_features=False)
    ranged = mesh_in_ranges(surface, size, n_parts=3, max_size=size)
    assert "warps" in whole.report.stage_seconds and whole.report.min_dihedral >= 10.7
    assert ranged.report.min_dihedral < 10.7
    assert any("mending" in w for w in ranged.report.warnings)


def test_a_part_thinner_than_the_lattice_is_refused_in_ranges():
    surface = paroct.load_surface(manifold3d.Manifold.cube([1.0, 1.0, 0.01]))
    with pytest.raises(paroct.ParoctError, match="no tets"):
        mesh_in_ranges(surface, 0.1, n_parts=2)


@pytest.mark.parametrize("n_parts", [0, -2, 2.5, True, "3"])
def test_a_range_count_that_is_no_whole_number_is_refused_in_one_line(n_parts):
    with pytest.raises(paroct.ParoctError, match=r"n_parts = .*: must be a whole number of ranges, at least 1"):
        mesh_in_ranges(DATA / "bunny.stl", n_parts=n_parts, divisions=10)
