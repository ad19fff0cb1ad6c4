"""Steady heat conduction through a meshed part with scikit-fem, boundary conditions on patches.

    pip install -e ".[examples]"
    python examples/heat_skfem.py [PART.stl] [--divisions 40] [--cold P] [--hot Q]   (P, Q: patch numbers or names)

paroct meshes the part and tags its boundary triangles by surface patch (the input's named
groups, else the surface split at edges sharper than 40 degrees); scikit-fem solves -div(k grad T) = 0 with linear tets,
T = 0 on the cold patch, T = 1 on the hot one, no flux through the rest.  By default the
cold and hot patches are the two whose triangles lie lowest and highest in z.  Prints the
patches, the heat flowing in and out (equal, up to the solver's tolerance) and the
temperature range; the default part is the bundled angle_block.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import skfem
from skfem.models.poisson import laplace

import paroct

ROOT = Path(__file__).resolve().parent.parent


def skfem_mesh(result: paroct.MeshResult, patches: paroct.BoundaryPatches) -> skfem.MeshTet:
    """The mesh as a scikit-fem MeshTet whose boundaries, named as the patches (``patch_<p>``, or
    the input's group names), are the facets of each patch."""
    mesh = skfem.MeshTet(np.ascontiguousarray(result.mesh.points.T), np.ascontiguousarray(result.mesh.tets.T))
    n = mesh.p.shape[1]

    def keys(triangles: np.ndarray) -> np.ndarray:  # sorted vertex triples packed in one integer
        t = np.sort(triangles.astype(np.int64), axis=1)
        return (t[:, 0] * n + t[:, 1]) * n + t[:, 2]

    facet_keys = keys(mesh.facets.T)
    order = np.argsort(facet_keys)
    facets = order[np.searchsorted(facet_keys[order], keys(patches.faces))]
    return mesh.with_boundaries({name: facets[patches.patches == p] for p, name in enumerate(patches.names, start=1)})


def solve_heat(mesh: skfem.MeshTet, cold: str, hot: str, conductivity: float = 1.0) -> tuple[np.ndarray, float, float]:
    """Temperature at the mesh's points (T = 0 on boundary ``cold``, 1 on ``hot``, no flux
    elsewhere) and the heat flowing in through ``hot`` and out through ``cold`` (per unit
    temperature difference, in conductivity x length units)."""
    basis = skfem.Basis(mesh, skfem.ElementTetP1())
    stiffness = conductivity * laplace.assemble(basis)
    cold_dofs, hot_dofs = basis.get_dofs(cold).all(), basis.get_dofs(hot).all()
    temperature = np.zeros(basis.N)
    temperature[hot_dofs] = 1.0
    temperature = skfem.solve(*skfem.condense(stiffness, x=temperature, D=np.concatenate([cold_dofs, hot_dofs])))
    reaction = stiffness @ temperature  # the nodal heat the Dirichlet nodes take in
    return temperature, float(reaction[hot_dofs].sum()), float(-reaction[cold_dofs].sum())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("surface", nargs="?", default=str(ROOT / "data" / "angle_block.stl"))
    ap.add_argument("--divisions", type=float, default=40)
    ap.add_argument("--cold", help="patch held at T = 0, by number or name (default: the lowest in z)")
    ap.add_argument("--hot", help="patch held at T = 1, by number or name (default: the highest in z)")
    args = ap.parse_args(argv)
    try:
        result = paroct.mesh(args.surface, divisions=args.divisions)
    except paroct.ParoctError as exc:
        print(f"heat_skfem: {exc}", file=sys.stderr)
        return 2
    patches = result.boundary_patches()
    points = result.mesh.points
    centroids = points[patches.faces].mean(axis=1)
    present = np.unique(patches.patches)
    height = {int(p): float(centroids[patches.patches == p, 2].mean()) for p in present}

    def patch(given: str | None, default: int) -> int | None:  # by number or by name; None if no such patch meshed
        if given is None:
            return default
        p = int(given) if given.isdigit() else patches.names.index(given) + 1 if given in patches.names else None
        return p if p in height else None

    cold = patch(args.cold, min(height, key=height.get))
    hot = patch(args.hot, max(height, key=height.get))
    for p, given in ((cold, args.cold), (hot, args.hot)):
        if p is None:
            listed = ", ".join(f"{q} {patches.names[q - 1]!r}" for q in height)
            print(f"heat_skfem: no patch {given!r} with boundary triangles; patches: {listed}", file=sys.stderr)
            return 2
    print(f"{len(result.mesh.tets)} tets, {len(patches.faces)} boundary triangles in {patches.n_patches} patches")
    cold_name, hot_name = patches.names[cold - 1], patches.names[hot - 1]
    temperature, flow_in, flow_out = solve_heat(skfem_mesh(result, patches), cold_name, hot_name)
    print(f"T = 0 on patch {cold} {cold_name!r} (z ~ {height[cold]:.4g}), T = 1 on patch {hot} {hot_name!r} "
          f"(z ~ {height[hot]:.4g})")
    print(f"heat in through {hot_name!r}: {flow_in:.6g}, out through {cold_name!r}: {flow_out:.6g} (k = 1)")
    print(f"temperature {temperature.min():.4g} .. {temperature.max():.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
