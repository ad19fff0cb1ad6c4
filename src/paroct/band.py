"""The boundary band of a locally refined mesh: surface cells at the level each place asks for.

Thin walls and gaps need a finer boundary than the requested size, but only where they are.
The frame is refined ``m`` levels below the requested size (its lattice holds the coarse one:
same origin, h / 2**m), the band is the surface cells of the coarse level, and cells asked
for finer split into their children that still meet the surface, level by level.  Every
leaf of the final octree that meets the surface lies inside a band cell, so every other leaf
has one class throughout and stuffing cuts only band leaves (of several levels, and the
transition templates between them: stuffing.warp_targets handles both).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from .frame import FatFrame
from .octant import MAX_LEVEL, morton_coords, morton_key, octants_in_cells, sort_values, sorted_lookup
from .octree import (FaceBuckets, balance, faces_meeting_cells, octant_lattice_anchors, octants_holding, octants_within,
                     surface_cells)
from .rays import RowCrossings, winding_numbers
from .sizing import OUTSIDE, UNDECIDED, WHOLLY_INSIDE, SizeField, size_seeds


@dataclass(frozen=True)
class BandLevels:
    """Where the band must be finer than ``coarse_level``: keys (K,) sorted octree keys of
    cells of coarse_level, levels (K,) int8 the band level asked for in each."""

    coarse_level: int
    keys: np.ndarray
    levels: np.ndarray

    def level_of(self, keys: np.ndarray) -> np.ndarray:
        """Band level (N,) asked for at the cells of coarse_level with these keys (coarse_level
        where nothing finer is asked)."""
        at, found = sorted_lookup(self.keys, keys)
        out = np.full(keys.shape[0], self.coarse_level, dtype=np.int8)
        out[found] = self.levels[at[found]]
        return out


def no_band_levels(coarse_level: int) -> BandLevels:
    return BandLevels(coarse_level, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int8))


def band_levels(frame: FatFrame, coarse_level: int, coords: np.ndarray, levels: np.ndarray, ring: int = 1) -> BandLevels:
    """Ask for band level levels[i] in the cells of coarse_level within ``ring`` cells of the
    lattice point coords[i] (coords (K, 3) lattice units, any real dtype); a cell asked for
    several levels gets the finest."""
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    levels = np.asarray(levels, dtype=np.int8)
    if coords.shape[0] != levels.shape[0]:
        raise ValueError(f"len(coords) = {coords.shape[0]} but len(levels) = {levels.shape[0]}")
    cells = np.floor(coords / (1 << (frame.levels - coarse_level))).astype(np.int64)
    # Many samples share a cell (a wall is sampled by every row that crosses it): the finest
    # ask of each cell first, so that each ring is asked once (tray_bottom at diag/80: 28 k
    # samples in 11.5 k cells; 754 k ring asks to sort before, now 311 k).
    sample_asks = _sample_asks(cells, levels, ring, 1 << coarse_level)
    sample_asks.sort()
    return _finest_packed(coarse_level, _ring_asks(sample_asks, ring, 1 << coarse_level))


#: Bits of a packed ask below the cell's Morton index (at coarse_level): the level asked for.
_LEVEL_BITS = 5


@nb.njit(cache=True)
def _sample_asks(cells, levels, ring, n_cells):
    """Packed asks (Morton index of the cell moved by ``ring`` along each axis, so that cells
    just outside the box key too, << _LEVEL_BITS | level) of the cells (K, 3) (coordinates at
    coarse_level) whose ring meets the 0..n_cells-1 box; the others are dropped."""
    out = np.empty(cells.shape[0], dtype=np.int64)
    n = 0
    reach = n_cells + 2 * ring
    for i in range(cells.shape[0]):
        x, y, z = cells[i, 0] + ring, cells[i, 1] + ring, cells[i, 2] + ring
        if 0 <= x < reach and 0 <= y < reach and 0 <= z < reach:
            out[n] = (morton_key(x, y, z) << _LEVEL_BITS) | np.int64(levels[i])
            n += 1
    return out[:n]


@nb.njit(cache=True)
def _ring_asks(sample_asks, ring, n_cells):
    """Packed asks (Morton index of the cell at its level << _LEVEL_BITS | level) of every cell
    of the 0..n_cells-1 box within ``ring`` of a cell of sample_asks (_sample_asks, sorted),
    for the finest level asked there (the last of the cell's run)."""
    width = 2 * ring + 1
    out = np.empty(sample_asks.shape[0] * width ** 3, dtype=np.int64)
    n = 0
    for i in range(sample_asks.shape[0]):
        cell = sample_asks[i] >> _LEVEL_BITS
        if i + 1 < sample_asks.shape[0] and sample_asks[i + 1] >> _LEVEL_BITS == cell:
            continue  # the cell is asked finer next
        level = sample_asks[i] & ((1 << _LEVEL_BITS) - 1)
        cx, cy, cz = morton_coords(cell)
        for x in range(cx - 2 * ring, cx + 1):
            for y in range(cy - 2 * ring, cy + 1):
                for z in range(cz - 2 * ring, cz + 1):
                    if 0 <= x < n_cells and 0 <= y < n_cells and 0 <= z < n_cells:
                        out[n] = (morton_key(x, y, z) << _LEVEL_BITS) | level
                        n += 1
    return out[:n]


def merge_band_levels(a: BandLevels, b: BandLevels) -> BandLevels:
    """The finer of the two asks in every cell."""
    if a.coarse_level != b.coarse_level:
        raise ValueError(f"coarse levels {a.coarse_level} and {b.coarse_level} differ")
    return _finest_per_key(a.coarse_level, np.concatenate([a.keys, b.keys]), np.concatenate([a.levels, b.levels]))


def _finest_per_key(coarse_level: int, keys: np.ndarray, levels: np.ndarray) -> BandLevels:
    shift = 3 * (MAX_LEVEL - coarse_level)
    return _finest_packed(coarse_level, ((keys >> shift) << _LEVEL_BITS) | levels.astype(np.int64))


def _finest_packed(coarse_level: int, packed: np.ndarray) -> BandLevels:
    """The finest ask per cell of packed asks (see _ring_asks), cells in key order: through a
    map of every cell of coarse_level, a byte each, where they are at most
    FINEST_MAP_CELLS_PER_ASK a packed ask, else one sort of the packed values and the last
    of each cell's run (np.lexsort on keys and levels took 10x longer)."""
    shift = 3 * (MAX_LEVEL - coarse_level)
    if 3 * coarse_level < 62 and (1 << (3 * coarse_level)) <= FINEST_MAP_CELLS_PER_ASK * packed.shape[0]:
        cells, levels = _finest_in_map(packed, np.int64(1) << (3 * coarse_level))
        return BandLevels(coarse_level, cells << shift, levels)
    s = sort_values(packed)
    cell = s >> _LEVEL_BITS
    last = np.ones(s.shape[0], dtype=bool)
    last[:-1] = cell[1:] != cell[:-1]
    return BandLevels(coarse_level, cell[last] << shift, (s[last] & ((1 << _LEVEL_BITS) - 1)).astype(np.int8))


#: Cells of coarse_level a packed ask up to which _finest_packed maps every cell (a byte
#: each) rather than sorting the asks: a sort costs about 20 ns an ask here, the map 1-2 ns
#: a cell, fresh pages included (plate_holes at diag/40: 56 k ring asks of 2 k cells, 1.2 ms
#: sorted, 0.45 ms in a map of its 262 k cells).
FINEST_MAP_CELLS_PER_ASK = 8


@nb.njit(cache=True)
def _finest_in_map(packed, n_cells):
    """_finest_packed's (cells (K,) int64 Morton indices ascending, levels (K,) int8) through
    a byte a cell of the n_cells (8**coarse_level): the finest level asked there plus one, 0
    where none."""
    finest = np.zeros(n_cells, dtype=np.int8)
    mask = (1 << _LEVEL_BITS) - 1
    for i in range(packed.shape[0]):
        cell = packed[i] >> _LEVEL_BITS
        level = np.int8((packed[i] & mask) + 1)
        if level > finest[cell]:
            finest[cell] = level
    count = 0
    for c in range(n_cells):
        count += finest[c] != 0
    cells = np.empty(count, dtype=np.int64)
    levels = np.empty(count, dtype=np.int8)
    k = 0
    for c in range(n_cells):
        if finest[c] != 0:
            cells[k] = c
            levels[k] = finest[c] - 1
            k += 1
    return cells, levels


@dataclass(frozen=True)
class FineSurfaceCells:
    """Surface cells finer than a coarse level, computed coarse cell by coarse cell as band_cells
    asks for them, for the passes that share a frame: for each level, done[level] the sorted
    coarse keys whose descendants meeting the surface are in met[level] (sorted keys)."""

    done: dict = field(default_factory=dict)
    met: dict = field(default_factory=dict)


def band_cells(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, snap_bits: int, buckets: FaceBuckets,
               wanted: BandLevels, fine: FineSurfaceCells | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The band: a linear octree (keys (B,) int64 sorted, levels (B,) int8) of the cells
    that meet the surface, each at the level ``wanted`` asks for in its coarse cell.

    buckets: face_buckets of wanted.coarse_level (its keys are the coarse surface cells).  A
    cell asked finer splits into the children that meet one of the triangles of its coarse
    cell (surface_cells, same margin), down to the level asked for: these are the cells of
    that level inside it that meet one of those triangles, since a cell's widened box holds
    its children's, so each coarse cell's cells are found at its asked level alone (tray_bottom
    diag/40 asks three levels down everywhere: the two levels between took 30 % of the tests).
    fine: the finer surface cells found so far in this frame, extended here (default: a new,
    empty one).
    """
    coarse = wanted.coarse_level
    fine = FineSurfaceCells() if fine is None else fine
    keys = buckets.keys
    asked = wanted.level_of(keys)
    whole = asked <= coarse
    out_keys, out_levels = [keys[whole]], [np.full(int(whole.sum()), coarse, dtype=np.int8)]
    for level in np.unique(asked[~whole]).tolist():
        met = _fine_surface_cells(frame, snapped, faces, snap_bits, buckets, fine, level, keys[asked == level])
        out_keys.append(met)
        out_levels.append(np.full(met.shape[0], level, dtype=np.int8))
    keys = np.concatenate(out_keys)
    levels = np.concatenate(out_levels)
    order = np.argsort(keys, kind="stable")
    return keys[order], levels[order]


def _fine_surface_cells(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, snap_bits: int, buckets: FaceBuckets,
                        fine: FineSurfaceCells, level: int, coarse_keys: np.ndarray) -> np.ndarray:
    """Sorted surface cells of ``level`` inside the coarse cells coarse_keys (sorted, all
    surface cells of buckets.level), from ``fine`` and, for coarse cells new to it, from their
    buckets' triangles."""
    done = fine.done.get(level, np.zeros(0, dtype=np.int64))
    met = fine.met.get(level, np.zeros(0, dtype=np.int64))
    new = coarse_keys[~sorted_lookup(done, coarse_keys)[1]]
    if new.size:
        near = np.compress(faces_meeting_cells(buckets, new, faces.shape[0]), faces, axis=0)
        found = surface_cells(frame, snapped, near, snap_bits, level)
        found = np.compress(octants_in_cells(found, new, buckets.level), found)
        # Both sorted: the first time at a level there is nothing to merge (np.sort of the
        # sorted cells took 3.3 ms of tray_bottom's 23 at diag/40).
        met = np.sort(np.concatenate([met, found])) if met.size else found
        done = np.sort(np.concatenate([done, new])) if done.size else new
        fine.done[level], fine.met[level] = done, met
    return np.compress(octants_in_cells(met, coarse_keys, buckets.level), met)


def surface_prune(frame: FatFrame, surface_keys: np.ndarray, x_crossings: RowCrossings):
    """The size_seeds prune of an octree whose surface cells are surface_keys (sorted, of one
    level): an octant of that level or coarser that holds none of them has one class
    throughout, its anchor's winding number; one that holds one stays undecided."""

    def classify(octants: np.ndarray, level: int) -> np.ndarray:
        found = np.full(octants.shape[0], UNDECIDED, dtype=np.int8)
        free = np.nonzero(~octants_holding(octants, level, surface_keys))[0]
        inside = winding_numbers(x_crossings, octant_lattice_anchors(octants[free], frame)) > 0
        found[free] = np.where(inside, WHOLLY_INSIDE, OUTSIDE)
        return found

    return classify


def kept_leaves(frame: FatFrame, keys: np.ndarray, levels: np.ndarray, in_band: np.ndarray, seeds: tuple,
                x_crossings: RowCrossings) -> np.ndarray:
    """Mask (N,) of the leaves that may hold inside tets: band leaves, leaves inside a seed
    size_seeds found wholly inside (balance only splits seeds), and the other leaves whose
    anchor is inside (they meet no surface, so the anchor classifies them whole).
    seeds: size_seeds' (keys, levels, wholly_inside)."""
    seed_keys, seed_levels, seed_inside = seeds
    inside_keys, inside_levels = seed_keys[seed_inside], seed_levels[seed_inside]
    order = np.argsort(inside_keys, kind="stable")
    keep = in_band | octants_within(keys, levels, inside_keys[order], inside_levels[order])
    ask = np.nonzero(~keep)[0]
    keep[ask] = winding_numbers(x_crossings, octant_lattice_anchors(keys[ask], frame)) > 0
    return keep


def local_leaves(frame: FatFrame, band_keys: np.ndarray, band_cell_levels: np.ndarray, surface_keys: np.ndarray,
                 coarse_level: int, x_crossings: RowCrossings, box_min: np.ndarray, box_max: np.ndarray,
                 field: SizeField) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted leaves (keys (N,) int64, levels (N,) int8) of the 2:1-balanced octree that may
    hold inside tets, and in_band (N,) bool: the leaf lies in a band cell.

    band_keys, band_cell_levels: band_cells; surface_keys: the surface cells of coarse_level
    (sorted), whose size_seeds octants stay undecided.  Leaves outside the band meet no
    surface: their anchor's winding number classifies them whole, and outside ones are dropped.
    The size field is that of coarse_level (field.size); coarser leaves follow it up to
    max_size.
    """
    prune = surface_prune(frame, surface_keys, x_crossings)
    seeds = size_seeds(frame, box_min, box_max, field, prune=prune, finest=coarse_level)
    keys, levels = balance(np.concatenate([band_keys, seeds[0]]), np.concatenate([band_cell_levels, seeds[1]]))
    in_band = octants_within(keys, levels, band_keys, band_cell_levels)
    keep = kept_leaves(frame, keys, levels, in_band, seeds, x_crossings)
    return np.compress(keep, keys), np.compress(keep, levels), np.compress(keep, in_band)
