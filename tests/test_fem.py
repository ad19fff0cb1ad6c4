"""The meshes in a finite-element solver (scikit-fem, linear tets): the patch test, and the
bundled example's heat flow through a bar between two boundary patches."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import manifold3d
import numpy as np
import skfem
from skfem.models.poisson import laplace

import paroct

ROOT = Path(__file__).resolve().parent.parent


def _example():
    spec = importlib.util.spec_from_file_location("heat_skfem", ROOT / "examples" / "heat_skfem.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_linear_tets_reproduce_a_linear_field_on_a_graded_mesh():
    """The patch test: with T = a . x + b on every boundary node, linear elements give T = a . x + b
    at every interior node, exactly, only on a conforming mesh of positive tets (a hanging
    node of a transition, or a flipped tet, breaks it)."""
    result = paroct.mesh(ROOT / "data" / "bunny.stl", divisions=25)
    assert len(result.report.leaf_levels) >= 3  # graded: transition templates inside
    mesh = skfem.MeshTet(np.ascontiguousarray(result.mesh.points.T), np.ascontiguousarray(result.mesh.tets.T))
    basis = skfem.Basis(mesh, skfem.ElementTetP1())
    exact = mesh.p.T @ np.array([0.3, -1.7, 2.9]) + 0.25
    boundary = mesh.boundary_nodes()
    assert 0 < boundary.size < mesh.p.shape[1] / 2
    field = np.zeros(basis.N)
    field[boundary] = exact[boundary]
    field = skfem.solve(*skfem.condense(laplace.assemble(basis), x=field, D=boundary))
    assert np.abs(field - exact).max() < 1e-9 * np.abs(exact).max()


def test_heat_flows_through_a_bar_between_its_end_patches():
    """A 1 x 1 x 2 bar, T = 0 on the patch at z = 0 and 1 at z = 2, no flux elsewhere: T = z / 2
    and the heat flow is k A / L = 0.5.  Stuffing cuts the bar's edges, so the ends are
    slightly smaller and the sides slightly slanted there: 1 % on the flow, 3 % of the
    temperature difference on T."""
    example = _example()
    result = paroct.mesh(manifold3d.Manifold.cube([1, 1, 2]), size=0.1)
    patches = result.boundary_patches()
    centroids = result.mesh.points[patches.faces].mean(axis=1)
    height = {p: centroids[patches.patches == p, 2].mean() for p in range(1, patches.n_patches + 1)}
    cold, hot = min(height, key=height.get), max(height, key=height.get)
    assert height[cold] < 0.01 and height[hot] > 1.99  # the end caps (with a few of the cut edges' triangles)
    mesh = example.skfem_mesh(result, patches)
    temperature, flow_in, flow_out = example.solve_heat(mesh, f"patch_{cold}", f"patch_{hot}")
    assert abs(flow_in - flow_out) < 1e-9 * flow_in
    assert abs(flow_in - 0.5) < 0.005
    assert np.abs(temperature - mesh.p[2] / 2).max() < 0.03


def test_the_example_runs_on_the_bundled_part(capsys):
    assert _example().main([str(ROOT / "data" / "angle_block.stl"), "--divisions", "20"]) == 0
    out = capsys.readouterr().out
    flows = [float(line.split(": ")[1].split(",")[0]) for line in out.splitlines() if line.startswith("heat in")]
    assert len(flows) == 1 and flows[0] > 0


def test_the_example_holds_named_patches(tmp_path, capsys):
    """The 1 x 1 x 2 bar as an ASCII STL with one named solid an end and one for the sides: the
    example takes the ends by name, and the flow is k A / L = 0.5 as above."""
    bar = manifold3d.Manifold.cube([1, 1, 2]).to_mesh64()
    vertices, faces = np.asarray(bar.vert_properties)[:, :3], np.asarray(bar.tri_verts)
    normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    name = np.where(normals[:, 2] < -0.5, "base", np.where(normals[:, 2] > 0.5, "lid", "wall"))
    text = ""
    for solid in ("base", "lid", "wall"):
        text += f"solid {solid}\n" + "".join(
            "facet normal 0 0 0\nouter loop\n" + "".join("vertex %.17g %.17g %.17g\n" % tuple(vertices[v]) for v in f)
            + "endloop\nendfacet\n" for f in faces[name == solid]) + f"endsolid {solid}\n"
    path = tmp_path / "bar.stl"
    path.write_text(text)
    example = _example()
    assert example.main([str(path), "--divisions", "20", "--cold", "lid", "--hot", "base"]) == 0
    out = capsys.readouterr().out
    assert "T = 0 on patch 2 'lid'" in out and "T = 1 on patch 1 'base'" in out
    flow = float(next(line for line in out.splitlines() if line.startswith("heat in")).split(": ")[1].split(",")[0])
    assert abs(flow - 0.5) < 0.01
    assert example.main([str(path), "--divisions", "20", "--cold", "side"]) == 2
    assert "no patch 'side' with boundary triangles; patches: 1 'base', 2 'lid', 3 'wall'" in capsys.readouterr().err
