"""check_mesh on meshes with known defects, and the exact distance kernels against naive twins."""

import math

import manifold3d
import numpy as np
import pytest

from paroct.check import (canonical_form, check_mesh, chord_volumes, distances_to_triangles, far_from_points,
                          point_triangle_distance, sample_triangles)
from paroct.errors import ParoctError
from paroct.lattice import leaf_tets
from paroct.surface import load_surface
from paroct.topology import boundary_faces, match_faces

from . import naive

KUHN_RATIO = math.sqrt(6) - math.sqrt(3)  # 3r/R of a Kuhn tet of a cube


def _block(n: int, h: float = 1.0):
    """Kuhn tets of an n x n x n block of axis-aligned cubes of side h: [0, n h]^3."""
    g = np.arange(n)
    anchors = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = leaf_tets(anchors, np.ones(len(anchors), dtype=np.int64))
    return coords * float(h), tets.astype(np.int64)


def _box_surface(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return load_surface(manifold3d.Manifold.cube(list(hi - lo)).translate(list(lo)))


def test_valid_block_is_ok_with_the_kuhn_numbers():
    points, tets = _block(3, 0.5)
    rep = check_mesh(points, tets)
    assert rep.ok and rep.problems() == []
    assert rep.n_tets == 6 * 27 and rep.n_vertices == 64 and rep.n_unreferenced == 0
    assert rep.n_inverted == 0 and rep.overloaded_faces == 0 and rep.same_side_faces == 0
    assert rep.volume == pytest.approx(1.5**3, rel=1e-12)
    assert rep.min_dihedral == pytest.approx(45.0, abs=1e-9) and rep.max_dihedral == pytest.approx(90.0, abs=1e-9)
    assert rep.min_radius_ratio == pytest.approx(KUHN_RATIO, abs=1e-12)
    assert rep.boundary_faces == 6 * 9 * 2  # two triangles per boundary square
    assert rep.boundary_manifold and rep.boundary_components == 1 and rep.boundary_genus == 0
    assert rep.solid_volume is None and rep.hausdorff is None
    assert rep.format().splitlines()[-1] == "ok"


def test_inverted_interior_tet_fails_with_same_side_faces():
    points, tets = _block(3)
    # A tet of the centre cube [1, 2]^3 has all four faces interior.
    centre = next(t for t in range(len(tets)) if np.all(points[tets[t]] >= 1) and np.all(points[tets[t]] <= 2))
    tets[centre, [0, 1]] = tets[centre, [1, 0]]
    rep = check_mesh(points, tets)
    assert not rep.ok
    assert rep.n_inverted == 1
    assert rep.same_side_faces == 4  # each of its faces now lies on the same side as its neighbour's
    assert rep.boundary_manifold  # the outer boundary is untouched
    problems = rep.problems()
    assert len(problems) == 2 and all(any(ch.isdigit() for ch in p) for p in problems)
    assert "1 of 162 tets are inverted" in problems[0]


def test_two_tets_sharing_only_an_edge_are_not_manifold():
    points = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    tets = np.array([[0, 2, 3, 1], [0, 4, 5, 1]])
    assert np.all([np.linalg.det(points[t[1:]] - points[t[0]]) > 0 for t in tets])
    rep = check_mesh(points, tets)
    assert not rep.ok and rep.n_inverted == 0 and rep.overloaded_faces == 0
    assert rep.boundary_bad_edges == 1  # edge 0-1 is in four boundary triangles
    assert rep.boundary_bad_vertices == 2  # its ends see two separate fans
    assert any("1 of its edges" in p for p in rep.problems())


def test_two_tets_sharing_only_a_vertex_are_not_manifold():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], float)
    tets = np.array([[0, 1, 2, 3], [0, 5, 4, 6]])
    assert np.all([np.linalg.det(points[t[1:]] - points[t[0]]) > 0 for t in tets])
    rep = check_mesh(points, tets)
    assert not rep.ok
    assert rep.boundary_bad_edges == 0 and rep.boundary_bad_vertices == 1
    assert rep.boundary_components == 1


def test_interior_cavity_is_a_closed_manifold_shell_and_passes():
    points, tets = _block(3)
    centre = next(t for t in range(len(tets)) if np.all(points[tets[t]] >= 1) and np.all(points[tets[t]] <= 2))
    rep = check_mesh(points, np.delete(tets, centre, axis=0))
    assert rep.ok
    assert rep.boundary_components == 2 and rep.boundary_genus == 0
    assert rep.boundary_faces == 6 * 9 * 2 + 4
    assert rep.volume == pytest.approx(27 - 1 / 6, rel=1e-12)


def test_duplicated_tet_is_overloaded():
    points, tets = _block(2)
    rep = check_mesh(points, np.vstack([tets, tets[:1]]))
    assert not rep.ok
    # The copy's interior faces meet a third tet; its boundary faces meet the original from the same side.
    assert rep.overloaded_faces > 0 and rep.same_side_faces > 0


def test_unreferenced_vertex_is_counted_but_ok():
    points, tets = _block(2)
    rep = check_mesh(np.vstack([points, [[9.0, 9.0, 9.0]]]), tets)
    assert rep.ok and rep.n_unreferenced == 1 and rep.n_vertices == len(points) + 1


def test_empty_mesh_is_not_ok():
    rep = check_mesh(np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64))
    assert not rep.ok and rep.problems() == ["the mesh has no tets"]


@pytest.mark.parametrize(
    "points,tets,match",
    [
        (np.zeros((4, 2)), np.array([[0, 1, 2, 3]]), "points.shape"),
        (np.eye(4, 3), np.array([[0, 1, 2]]), "tets.shape"),
        (np.eye(4, 3), np.array([[0, 1, 2, 4]]), "span 0..4"),
        (np.eye(4, 3), np.array([[0, 1, 2, -1]]), "span -1..2"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]), np.array([[0, 1, 2, 3]]), "NaN"),
        (np.eye(4, 3), np.array([[0.0, 1, 2, 3]]), "integers"),
    ],
)
def test_malformed_arrays_raise_one_line_errors(points, tets, match):
    with pytest.raises(ParoctError, match=match) as info:
        check_mesh(points, tets)
    assert "\n" not in str(info.value)


def test_hausdorff_zero_when_boundary_is_the_surface_and_shift_when_shifted():
    points, tets = _block(2, 0.5)  # [0, 1]^3
    same = check_mesh(points, tets, _box_surface([0, 0, 0], [1, 1, 1]))
    assert same.ok
    assert same.hausdorff < 1e-12 and abs(same.volume_error) < 1e-12
    shift = 0.05
    moved = _box_surface([shift, 0, 0], [1 + shift, 1, 1])
    rep = check_mesh(points, tets, moved)
    expected = shift / math.sqrt(3)  # the diagonal of the unit box
    # The mesh's face x = 0 is shift away from the surface, and the surface's face x = 1 + shift from the mesh.
    assert rep.hausdorff_to_surface == pytest.approx(expected, rel=1e-9)
    assert rep.hausdorff_to_mesh == pytest.approx(expected, rel=1e-9)
    assert rep.volume_error == pytest.approx(0.0, abs=1e-12)
    taller = check_mesh(points, tets, _box_surface([0, 0, 0], [1, 1, 1.25]))
    assert taller.volume_error == pytest.approx(1 / 1.25 - 1, rel=1e-12)
    assert taller.solid_volume == pytest.approx(1.25, rel=1e-12)
    assert taller.hausdorff == pytest.approx(0.25 / math.sqrt(2 + 1.25**2), rel=1e-9)


def test_hausdorff_matches_brute_force_on_the_samples():
    points, tets = _block(2, 0.5)
    sphere = load_surface(manifold3d.Manifold.sphere(0.6, 16).translate([0.5, 0.5, 0.5]))
    rep = check_mesh(points, tets, sphere, samples_per_triangle=2, seed=7)
    faces = boundary_faces(tets, match_faces(tets)[0])
    on_mesh = sample_triangles(points, faces, 2, 7)
    on_sphere = sample_triangles(sphere.vertices, sphere.faces, 2, 7)
    to_sphere = max(min(naive.point_triangle_distance(p, *sphere.vertices[f]) for f in sphere.faces) for p in on_mesh)
    to_mesh = max(min(naive.point_triangle_distance(p, *points[f]) for f in faces) for p in on_sphere)
    assert rep.hausdorff_to_surface == pytest.approx(to_sphere / sphere.diagonal, rel=1e-9)
    assert rep.hausdorff_to_mesh == pytest.approx(to_mesh / sphere.diagonal, rel=1e-9)
    assert rep.hausdorff > 0.01  # a sphere is not a cube


def _degenerate_triangles(rng):
    a, b = rng.normal(size=3), rng.normal(size=3)
    return [
        (a, a, a),  # a point
        (a, a, b),  # a segment with a repeated corner
        (a, b, a + 2 * (b - a)),  # collinear, c beyond b
        (a, a + 0.5 * (b - a), b),  # collinear, middle corner between
        (a, b, b),
        (a, b, a + 3 * (b - a) + 1e-13 * rng.normal(size=3)),  # a sliver, almost collinear
    ]


def test_point_triangle_distance_matches_naive_on_random_triangles():
    rng = np.random.default_rng(1)
    q = 400
    points = rng.normal(size=(q, 3)) * rng.choice([0.01, 1.0, 100.0], size=(q, 1))
    tris = rng.normal(size=(q, 3, 3))
    got = point_triangle_distance(points, tris)
    want = np.array([naive.point_triangle_distance(points[i], *tris[i]) for i in range(q)])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_point_triangle_distance_on_degenerate_triangles_and_on_the_triangle():
    rng = np.random.default_rng(2)
    pts, tris = [], []
    for _ in range(20):
        for tri in _degenerate_triangles(rng):
            for p in (rng.normal(size=3), tri[0], 0.3 * tri[0] + 0.7 * tri[2]):
                pts.append(p)
                tris.append(np.array(tri))
    # Points in the plane of a proper triangle, inside and outside it, and at its corners.
    for _ in range(40):
        tri = rng.normal(size=(3, 3))
        w = rng.normal(size=3)
        pts.append(w @ tri / w.sum())
        tris.append(tri)
        pts.append(tri[rng.integers(3)])
        tris.append(tri)
    pts, tris = np.array(pts), np.array(tris)
    got = point_triangle_distance(pts, tris)
    want = np.array([naive.point_triangle_distance(p, *t) for p, t in zip(pts, tris)])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    assert np.all(got[-79::2] < 1e-12)  # a corner is on its triangle


@pytest.mark.parametrize("case", ["soup", "small", "slab", "ceiling", "far_queries", "flat", "one_triangle"])
def test_distances_to_triangles_matches_brute_force(case):
    seeds = {"soup": 3, "small": 9, "slab": 10, "ceiling": 11, "far_queries": 4, "flat": 5, "one_triangle": 6}
    rng = np.random.default_rng(seeds[case])
    vertices = rng.random((120, 3))
    faces = rng.integers(0, 120, size=(150, 3))  # includes degenerate faces with repeated corners
    queries = rng.random((120, 3)) * 1.6 - 0.3
    if case == "small":  # triangles much smaller than the grid cells
        vertices = (rng.random((150, 1, 3)) + 0.02 * rng.normal(size=(150, 3, 3))).reshape(-1, 3)
        faces = np.arange(450).reshape(150, 3)
        queries = rng.random((300, 3)) * 1.2 - 0.1
    if case in ("slab", "ceiling"):  # small triangles on the grid's floor, queries above: the nearest is often straight down
        vertices = (rng.random((150, 1, 3)) * [1, 1, 0.03] + 0.02 * rng.normal(size=(150, 3, 3))).reshape(-1, 3)
        faces = np.arange(450).reshape(150, 3)
        queries = rng.random((300, 3)) + [0, 0, 0.1]
        if case == "ceiling":  # upside down
            vertices[:, 2] *= -1
            queries[:, 2] *= -1
    if case == "far_queries":
        queries = queries * 30 + 5
    if case == "flat":
        vertices[:, 2] = 0.0
        queries[:60, 2] = 0.0
    if case == "one_triangle":
        faces = faces[:1]
    got = distances_to_triangles(queries, vertices, faces)
    want = np.array([min(naive.point_triangle_distance(q, *vertices[f]) for f in faces) for q in queries])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_sample_triangles_are_on_their_triangles_and_repeatable():
    rng = np.random.default_rng(8)
    vertices = rng.normal(size=(10, 3))
    faces = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7]])
    a = sample_triangles(vertices, faces, 4, seed=3)
    assert np.array_equal(a, sample_triangles(vertices, faces, 4, seed=3))
    assert not np.array_equal(a, sample_triangles(vertices, faces, 4, seed=4))
    assert a.shape == (8 + 3 + 3 * 4, 3)  # used vertices, centroids, random points
    random_part = a[11:].reshape(3, 4, 3)
    for f, pts in zip(faces, random_part):
        assert max(naive.point_triangle_distance(p, *vertices[f]) for p in pts) < 1e-12


def test_mesh_metrics_orient_by_majority_and_count_the_rest_inverted():
    from paroct.check import mesh_metrics
    from paroct.mesher import mesh

    surface = load_surface(manifold3d.Manifold.cube([1.0, 1.0, 1.0]))
    result = mesh(surface, size=0.25, max_size=0.25)
    points, tets = result.mesh.points, result.mesh.tets.astype(np.int64)
    good = mesh_metrics(points, tets, surface)
    assert good["inverted"] == 0 and good["closed"] and good["topology_kept"]
    assert good["tets"] == len(tets) and abs(good["volume_error"]) < 0.01
    assert good["min_dihedral"] <= good["p1_dihedral"] <= good["max_dihedral"]
    # Another mesher's orientation convention: all tets flipped is the same mesh.
    flipped = mesh_metrics(points, tets[:, [1, 0, 2, 3]], surface)
    assert flipped["inverted"] == 0 and flipped["min_dihedral"] == pytest.approx(good["min_dihedral"], abs=1e-9)
    # A minority of flipped tets is inverted and breaks conformity.
    some = tets.copy()
    some[:3] = some[:3][:, [1, 0, 2, 3]]
    bad = mesh_metrics(points, some, surface)
    assert bad["inverted"] == 3 and not bad["closed"]


@pytest.mark.parametrize("seed", range(3))
def test_surface_edge_counts_match_a_dictionary_twin(seed):
    from paroct.topology import surface_topology

    rng = np.random.default_rng(seed)
    # Boundaries of random tet sets of a block (closed, sometimes pinched), then torn and doubled faces.
    keys = np.arange(27)
    points, tets = leaf_tets(np.stack(np.unravel_index(keys, (3, 3, 3)), 1).astype(np.int64), np.ones(27, dtype=np.int64))
    tets = tets[rng.random(len(tets)) < 0.6]
    faces = boundary_faces(tets, match_faces(tets)[0])
    faces = np.concatenate([faces[rng.random(len(faces)) < 0.9], faces[: 5 * seed]])
    topo = surface_topology(faces, len(points))
    assert (topo.n_edges, topo.n_vertices, topo.bad_edges) == naive.surface_edges(faces)


@pytest.mark.parametrize("seed", range(6))
def test_far_from_points_matches_all_pairs(seed):
    rng = np.random.default_rng(seed)
    points = rng.random((300, 3)) * [4.0, 1.0, 0.01]  # one thin axis: many points per cell
    queries = np.concatenate([rng.random((400, 3)) * [5.0, 1.5, 1.0] - 0.2, points[:20] + [0.1, 0, 0]])
    queries = np.concatenate([queries, points[20:40] + rng.normal(size=(20, 3)) * 0.001])
    # The last two radii ask for far more cells than points: the grid is coarsened.
    radius = [0.05, 0.1, 0.3, 2.0, 0.005, 0.0007][seed]
    assert np.array_equal(far_from_points(queries, points, radius), naive.far_from_points(queries, points, radius))


def test_far_from_points_degenerate_inputs():
    grid = np.stack(np.meshgrid(*[np.arange(4.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    # Queries exactly one radius from a grid point count as near (distance <= radius).
    queries = grid + [1.0, 0.0, 0.0]
    assert not far_from_points(queries, grid, 1.0).any()
    assert np.array_equal(far_from_points(grid + 0.5, grid, 0.5), naive.far_from_points(grid + 0.5, grid, 0.5))
    assert far_from_points(queries, np.zeros((0, 3)), 1.0).all()
    one = np.array([[1e8, -1e8, 3.0]])  # one point, far from the origin: a 1-cell grid
    assert np.array_equal(far_from_points(one + [[0, 0, 0.5], [0, 0, 2]], one, 1.0), [False, True])
    with pytest.raises(ValueError, match="radius"):
        far_from_points(queries, grid, 0.0)


def test_a_mesh_of_another_solid_fails_the_check_against_the_surface():
    """Validity alone passed a mesh of a different part: against a surface, a volume off by
    more than half or a boundary a quarter of the diagonal away fails."""
    import manifold3d

    import paroct

    small = paroct.mesh(manifold3d.Manifold.cube([1, 1, 1]), size=0.25)
    big = load_surface(manifold3d.Manifold.cube([4, 4, 4]))
    report = check_mesh(small.mesh.points, small.mesh.tets, big)
    assert not report.ok and len(report.problems()) == 2
    assert "volume differs from the solid's by -98.4%" in report.problems()[0]
    assert "apart at" in report.problems()[1]
    same = check_mesh(small.mesh.points, small.mesh.tets, load_surface(manifold3d.Manifold.cube([1, 1, 1])))
    assert same.ok


def test_canonical_form_ignores_numbering_and_sees_any_change():
    rng = np.random.default_rng(3)
    points = rng.random((30, 3))
    tets = np.array([rng.choice(30, 4, replace=False) for _ in range(40)])
    want = canonical_form(points, tets)
    perm = rng.permutation(30)  # new point ids: point i becomes point perm[i]
    moved = np.empty_like(points)
    moved[perm] = points
    shuffled = perm[tets][rng.permutation(40)][:, [2, 0, 3, 1]]
    got = canonical_form(moved, shuffled)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    other = tets.copy()
    other[7, 1] = next(i for i in range(30) if i not in tets[7])  # one corner of one tet changed
    assert not np.array_equal(canonical_form(points, other)[1], want[1])
    nudged = points.copy()
    nudged[5, 2] = np.nextafter(nudged[5, 2], 2.0)
    assert not np.array_equal(canonical_form(nudged, tets)[0], want[0])


def test_chord_volumes_match_the_naive_twin_on_random_faces():
    rng = np.random.default_rng(58)
    surface_vertices = rng.normal(size=(30, 3))
    surface_faces = rng.integers(0, 30, size=(20, 3))
    surface_faces[0] = [1, 1, 2]  # degenerate: normal 0
    points = rng.normal(size=(40, 3))
    faces = rng.integers(0, 40, size=(60, 3))
    point_faces = rng.integers(-1, 20, size=40)
    expected = naive.chord_volumes(points, faces, point_faces, surface_vertices, surface_faces)
    assert np.count_nonzero(expected) > 10  # some faces have all three vertices on triangles
    got = chord_volumes(points, faces, point_faces, surface_vertices, surface_faces)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)


def _tangent_triangles(points: np.ndarray, centre: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """A small triangle in the tangent plane of the sphere about centre at each point (outward:
    its normal is the sphere's there), for exact normals at the points."""
    vertices, faces = [], []
    for p in points:
        n = (p - centre) / np.linalg.norm(p - centre)
        u = np.cross(n, [0.3, 0.5, 0.8])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        k = len(vertices)
        vertices += [p + width * u, p + width * v, p - width * (u + v)]
        faces.append([k, k + 1, k + 2])
    return np.array(vertices), np.array(faces)


@pytest.mark.parametrize("side", [1, -1])
def test_chord_volume_of_a_triangle_on_a_sphere_is_the_cap_between_them(side):
    # An equilateral triangle of edge 0.05 R with its vertices on a sphere of radius R: the
    # sphere lies L^2 / (8 R) off it on average, by quadrature of its height over the
    # triangle; the mesh lacks that volume where the sphere bulges out (side 1: the solid
    # inside), and has it extra where the solid is outside (side -1: a cavity).
    radius, edge, centre = 2.0, 0.1, np.array([0.3, -0.2, 0.5])
    rho = edge / math.sqrt(3)
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    u = np.cross(axis, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    angles = 2 * np.pi * np.arange(3) / 3
    foot = centre + math.sqrt(radius**2 - rho**2) * axis
    points = foot + rho * (np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * v)
    face = np.array([[0, 1, 2]] if side == 1 else [[0, 2, 1]])
    vertices, faces = _tangent_triangles(points, centre, 0.01)
    if side == -1:
        faces = faces[:, ::-1]  # the cavity's surface faces into it
    got = chord_volumes(points, face, np.arange(3), vertices, faces)[0]
    # The gap by quadrature: the sphere's distance from the triangle's plane along its normal.
    a, b, c = points
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a))
    inner = np.random.default_rng(0).dirichlet([1, 1, 1], size=200_000) @ points
    gap = np.sqrt(radius**2 - np.sum((inner - centre - ((inner - centre) @ axis)[:, None] * axis) ** 2, axis=1)) \
        - (inner - centre) @ axis
    exact = -side * area * gap.mean()
    assert exact == pytest.approx(-side * area * edge**2 / (8 * radius), rel=0.01)
    assert got == pytest.approx(exact, rel=0.01)


@pytest.mark.parametrize("divisions", [10, 20])
def test_chord_volumes_sum_to_the_volume_a_sphere_mesh_lacks(divisions):
    # Every boundary vertex of a stuffed mesh lies on the surface, so on a smooth solid the
    # boundary's chords are all the volume error: a finely tessellated sphere lacks 0.8-3 %
    # at these sizes, and the estimate is within 3 % of it.
    import paroct

    result = paroct.mesh(manifold3d.Manifold.sphere(1.0, 256), divisions=divisions, thin_features=False)
    surface = result.surface
    estimate = chord_volumes(result.mesh.points, result.boundary_faces, result.point_faces, surface.vertices,
                             surface.faces).sum() / surface.volume
    assert result.report.volume_error < -0.005
    assert estimate == pytest.approx(result.report.volume_error, rel=0.03)


def test_chord_volumes_refuse_mismatched_arrays():
    points, faces = np.zeros((3, 3)), np.array([[0, 1, 2]])
    with pytest.raises(ValueError, match="len\\(point_faces\\) = 2 but len\\(points\\) = 3"):
        chord_volumes(points, faces, np.zeros(2, dtype=np.int64), points, faces)
    with pytest.raises(ValueError, match="point_faces hold 0..5 but len\\(surface_faces\\) = 1"):
        chord_volumes(points, faces, np.array([0, 5, 0]), points, faces)
    with pytest.raises(ValueError, match="point_faces hold -2..0"):
        chord_volumes(points, faces, np.array([0, -2, 0]), points, faces)
    with pytest.raises(ValueError, match="faces hold 0..3 but len\\(points\\) = 3"):
        chord_volumes(points, np.array([[0, 1, 3]]), np.zeros(3, dtype=np.int64), points, faces)
    with pytest.raises(ValueError, match="surface_faces hold 0..7 but len\\(surface_vertices\\) = 3"):
        chord_volumes(points, faces, np.zeros(3, dtype=np.int64), points, np.array([[0, 1, 7]]))
