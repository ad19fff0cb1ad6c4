"""Algorithms over linear octrees (the layer of p4est's p8est_algorithms.h).

A linear octree is a pair of arrays ``keys`` (N,) int64 (Morton keys of the anchors,
see :mod:`paroct.octant`) and ``levels`` (N,) int8, sorted by key, with no octant
overlapping another.  The algorithms follow Sundar, Sampath & Biros, "Bottom-up
construction and 2:1 balance refinement of linear octrees in parallel", SIAM J.
Sci. Comput. 30 (2008).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .frame import LATTICE_TO_SPACE, FatFrame
from .octant import MAX_LEVEL, morton_decode, octant_is_ancestor, octant_last_key, octant_overlaps


@nb.njit(cache=True)
def tree_is_sorted(keys, levels):
    """True iff (key, level) pairs are in ascending order: ancestors precede descendants."""
    for i in range(1, keys.shape[0]):
        if keys[i] < keys[i - 1] or (keys[i] == keys[i - 1] and levels[i] <= levels[i - 1]):
            return False
    return True


@nb.njit(cache=True)
def tree_is_linear(keys, levels):
    """True iff the tree is sorted and no octant overlaps its successor (hence none overlaps any other)."""
    if not tree_is_sorted(keys, levels):
        return False
    for i in range(1, keys.shape[0]):
        if octant_overlaps(keys[i - 1], levels[i - 1], keys[i], levels[i]):
            return False
    return True


@nb.njit(cache=True)
def tree_is_complete(keys, levels):
    """True iff the tree is linear and its octants tile the root cube: each starts where the last ended."""
    if keys.shape[0] == 0 or not tree_is_linear(keys, levels):
        return False
    expected = np.int64(0)
    for i in range(keys.shape[0]):
        if keys[i] != expected:
            return False
        expected = octant_last_key(keys[i], levels[i]) + 1
    return expected == (np.int64(1) << (3 * MAX_LEVEL))


@nb.njit(cache=True)
def linearize(keys, levels):
    """Drop every octant that is an ancestor of its successor in a sorted array (keep the finest).

    Returns a boolean mask (N,) of the octants kept.  Input must satisfy tree_is_sorted.
    """
    n = keys.shape[0]
    keep = np.ones(n, dtype=np.bool_)
    for i in range(n - 1):
        if octant_is_ancestor(keys[i], levels[i], keys[i + 1], levels[i + 1]):
            keep[i] = False
    return keep


def octant_lattice_anchors(keys: np.ndarray, frame: FatFrame) -> np.ndarray:
    """Anchors (N, 3) int64 of octants in lattice units of the frame's finest level."""
    return morton_decode(keys) >> (MAX_LEVEL - frame.levels)


def uniform_leaves(frame: FatFrame, box_min: np.ndarray, box_max: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """All octants of ``level`` whose parallelepiped meets the space box, as a sorted linear octree.

    Descends from the root keeping the octants whose image bounding box meets the box;
    children of a sorted array, appended in child order, stay sorted.
    Returns (keys (N,) int64, levels (N,) int8).
    """
    if not 0 <= level <= frame.levels:
        raise ValueError(f"level = {level} is outside 0..{frame.levels}")
    lo = (np.asarray(box_min, dtype=np.float64) - frame.origin) / frame.h
    hi = (np.asarray(box_max, dtype=np.float64) - frame.origin) / frame.h
    keys = np.zeros(1, dtype=np.int64)
    child = np.arange(8, dtype=np.int64)
    for lev in range(1, level + 1):
        keys = (keys[:, None] | (child[None, :] << (3 * (MAX_LEVEL - lev)))).ravel()
        side = float(1 << (frame.levels - lev))
        anchors = (morton_decode(keys) >> (MAX_LEVEL - frame.levels)).astype(np.float64)
        centre = anchors @ LATTICE_TO_SPACE.T
        # Each row of LATTICE_TO_SPACE has entries (1/2, 1/2, -1/2) in some order:
        # over the cube anchor + [0, side]^3 a space coordinate spans [c - side/2, c + side].
        meets = np.all((centre + side >= lo) & (centre - side / 2 <= hi), axis=1)
        keys = keys[meets]
    return keys, np.full(keys.shape[0], level, dtype=np.int8)
