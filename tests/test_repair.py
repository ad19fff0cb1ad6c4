"""Pinch repair against a dictionary twin (tests/naive.py), and the boundary it updates
against one computed from scratch."""

import numpy as np
import pytest

from paroct.lattice import leaf_tets
from paroct.repair import remove_pinches
from paroct.topology import boundary_faces, match_faces, nonmanifold_vertices

from . import naive


def _pinched_block(seed: int, n: int = 10, keep: float = 0.55):
    """Kuhn tets of an n^3 block with random tets of its outer cell layers dropped (pinches
    appear where the remaining tets touch at a vertex or edge), and the core mask: vertices on
    no boundary face, so a face of three core vertices is interior."""
    rng = np.random.default_rng(seed)
    g = np.arange(n)
    anchors = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = leaf_tets(anchors, np.ones(len(anchors), dtype=np.int64))
    centre = coords[tets].mean(axis=1)
    outer = (np.minimum(centre, n - centre) < 2).any(axis=1)
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
    band = np.zeros(len(core), dtype=bool)
    band[tets[~core[tets].all(axis=1)].ravel()] = True
    assert not band[tets].any(axis=1).all()  # the local repair works on part of the mesh
    out, removed, out_faces = remove_pinches(tets, core.copy())
    assert removed == int((~whole_alive).sum()) > 0
    assert np.array_equal(out, tets[whole_alive])
    # The updated boundary is the result's boundary, closed and manifold.
    assert _face_set(out_faces) == _face_set(boundary_faces(out, match_faces(out)[0]))
    assert not nonmanifold_vertices(out_faces, len(core)).any()
