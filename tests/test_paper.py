"""The recomputed paper table against closed forms and independently built tets."""

import math

import numpy as np
import pytest

from paroct.frame import TODD_A
from paroct.paper import (
    FIVE_TET_SPLIT,
    SIX_TET_CORNER_SPLIT,
    format_paper_table,
    lattice_vertex_counts,
    paper_errata,
    paper_table,
)
from paroct.topology import boundary_faces, match_faces, surface_topology

from . import naive

K1_TET = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]], float)  # 0, e1, e1 + e2, e1 + e2 + e3
UNIT_CUBE = np.array([[(c >> i) & 1 for i in range(3)] for c in range(8)], float)


@pytest.fixture(scope="module")
def rows():
    return {r.key: r for r in paper_table()}


def test_fat_tet_ratio_is_three_over_sqrt_ten(rows):
    fat = 3 / math.sqrt(10)
    assert fat == pytest.approx(1.5 * math.sqrt(2 / 5), abs=1e-15)  # not 3 sqrt(2/5) = 1.897
    for key in ("fat_max", "fat_min", "fat_bcc_min", "fat_bcc_max"):
        assert rows[key].computed == pytest.approx(fat, abs=1e-12), key
    # Todd's A written out from its definition, on one K1 tet, measured by the naive formula.
    a = np.eye(3) - 1 / (3 + 1 + math.sqrt(3 + 1)) * np.ones((3, 3))
    assert naive.tet_radius_ratio(K1_TET @ a.T) == pytest.approx(fat, abs=1e-12)
    assert np.allclose(a, TODD_A)
    assert rows["fat_max"].paper == "0.9487" and round(fat, 4) == 0.9487


def test_printed_matrix_is_not_fat(rows):
    printed = np.array([[5, 1, 1], [1, 5, 1], [1, 1, 5]]) / 6  # as typeset in the paper
    expected = naive.tet_radius_ratio(K1_TET @ printed.T)
    assert rows["printed_matrix"].computed == pytest.approx(expected, abs=1e-12)
    assert expected < 0.5


def test_icosahedral_tet_against_a_polar_construction(rows):
    # Icosahedron of circumradius 1: poles and two pentagon rings at z = +-1/sqrt(5).
    z, rho = 1 / math.sqrt(5), 2 / math.sqrt(5)
    top = np.array([0.0, 0.0, 1.0])
    ring = [np.array([rho * math.cos(2 * math.pi * k / 5), rho * math.sin(2 * math.pi * k / 5), z]) for k in range(2)]
    assert np.linalg.norm(ring[0] - ring[1]) == pytest.approx(np.linalg.norm(top - ring[0]))  # an equilateral face
    expected = naive.tet_radius_ratio(np.array([np.zeros(3), top, ring[0], ring[1]]))
    assert rows["icosahedral"].computed == pytest.approx(expected, abs=1e-12)
    assert round(expected, 4) == 0.9964
    assert math.isnan(rows["icosahedral_gap"].computed) and rows["icosahedral_gap"].paper == "0.7681"


def test_cube_splits_against_closed_forms(rows):
    kuhn = math.sqrt(6) - math.sqrt(3)
    corner = math.sqrt(3) - 1
    assert rows["kuhn_min"].computed == pytest.approx(kuhn, abs=1e-12)
    assert rows["kuhn_max"].computed == pytest.approx(kuhn, abs=1e-12)
    assert naive.tet_radius_ratio(K1_TET) == pytest.approx(kuhn, abs=1e-12)
    assert round(kuhn, 4) == 0.7174 and round(corner, 5) == 0.73205
    assert rows["five_corner"].computed == pytest.approx(corner, abs=1e-12)
    assert rows["five_centre"].computed == pytest.approx(1.0, abs=1e-12)
    assert rows["six_corner_max"].computed == pytest.approx(corner, abs=1e-12)
    # The diagonal tet 0, (1,1,0), (0,1,1), (1,1,1): faces sqrt(3)/2, sqrt(2)/2 twice, 1/2; R = sqrt(3)/2.
    diagonal_tet = 2 * math.sqrt(3) / (1 + math.sqrt(3) + 2 * math.sqrt(2))
    assert naive.tet_radius_ratio(np.array([[0, 0, 0], [1, 1, 0], [0, 1, 1], [1, 1, 1]], float)) == pytest.approx(diagonal_tet)
    assert rows["six_corner_min"].computed == pytest.approx(diagonal_tet, abs=1e-12)
    assert round(diagonal_tet, 5) == 0.62299  # the paper's cube minimum


@pytest.mark.parametrize("split,n", [(FIVE_TET_SPLIT, 5), (SIX_TET_CORNER_SPLIT, 6)])
def test_cube_splits_tile_the_cube(split, n):
    assert split.shape == (n, 4)
    vols = [np.linalg.det(UNIT_CUBE[t[1:]] - UNIT_CUBE[t[0]]) / 6 for t in split]
    assert min(vols) > 0 and sum(vols) == pytest.approx(1.0)
    neighbour, overloaded, same_side = match_faces(split)
    assert overloaded == 0 and same_side == 0
    faces = boundary_faces(split, neighbour)
    assert len(faces) == 12  # two triangles per cube face
    for f in faces:  # each boundary triangle lies in a cube face
        pts = UNIT_CUBE[f]
        assert any(np.all(pts[:, k] == pts[0, k]) for k in range(3))
    assert surface_topology(faces, 8).manifold


def test_lattice_vertex_has_14_edges_and_24_tets(rows):
    degree, incident = lattice_vertex_counts(6)
    assert degree.shape == (125,)
    assert np.all(degree == 14) and np.all(incident == 24)
    assert rows["vertex_degree"].computed == 14 and rows["vertex_tets"].computed == 24
    # The one interior vertex of a 2^3 block already has its full star.
    small_degree, small_incident = lattice_vertex_counts(2)
    assert small_degree.tolist() == [14] and small_incident.tolist() == [24]


def test_dihedral_angles(rows):
    assert rows["regular_dihedral"].computed == pytest.approx(math.degrees(math.acos(1 / 3)), abs=1e-9)
    assert rows["regular_dihedral"].paper == "72.221"
    assert rows["fat_dihedral_min"].computed == pytest.approx(60.0, abs=1e-9)
    assert rows["fat_dihedral_max"].computed == pytest.approx(90.0, abs=1e-9)
    angles = naive.tet_dihedral_angles(K1_TET @ TODD_A.T)
    assert sorted(np.round(angles, 9)) == [60.0] * 4 + [90.0] * 2


def test_printed_table_and_errata():
    text = format_paper_table()
    for value in ("0.948683", "0.996407", "0.717439", "0.732051", "0.622986", "70.5288", "0.9497", "72.221"):
        assert value in text
    errata = paper_errata()
    assert len(errata) == 5 and "Errata:" in text
    joined = " ".join(errata)
    for fact in ("-1/6", "0.9497", "0.9487", "72.221", "70.53", "0.73205", "0.7174", "3/sqrt(10)"):
        assert fact in joined
    assert all("\n" not in e for e in errata)
