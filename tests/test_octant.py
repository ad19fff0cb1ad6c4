import numpy as np
import pytest

from paroct import octant
from paroct.octree import linearize, tree_is_complete, tree_is_linear, tree_is_sorted

from . import naive

RNG = np.random.default_rng(20261122)


def test_morton_key_matches_bit_by_bit_interleave():
    coords = RNG.integers(0, 1 << 21, size=(500, 3))
    coords = np.vstack([coords, [[0, 0, 0], [(1 << 21) - 1] * 3, [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    keys = octant.morton_keys(coords)
    assert [int(k) for k in keys] == [naive.morton_key(*map(int, c)) for c in coords]
    assert np.array_equal(octant.morton_decode(keys), coords)


def test_morton_order_sorts_octants_after_ancestors():
    # Children keys of a parent are the parent key plus child id at the child's level.
    parent = octant.morton_key(8 << 10, 4 << 10, 12 << 10)
    level = octant.MAX_LEVEL - 12
    for c in range(8):
        child = parent | (c << (3 * (octant.MAX_LEVEL - level - 1)))
        assert octant.octant_parent_key(child, level + 1) == parent
        assert octant.octant_child_id(child, level + 1) == c
        assert octant.octant_is_ancestor(parent, level, child, level + 1)
        assert not octant.octant_is_ancestor(child, level + 1, parent, level)
        assert child <= octant.octant_last_key(parent, level)


@pytest.mark.parametrize("trial", range(200))
def test_octant_is_ancestor_matches_box_containment(trial):
    la, lb = sorted(RNG.integers(0, 8, size=2) + octant.MAX_LEVEL - 8)
    side_a = 1 << (octant.MAX_LEVEL - la)
    side_b = 1 << (octant.MAX_LEVEL - lb)
    a = RNG.integers(0, (1 << octant.MAX_LEVEL) // side_a, size=3) * side_a
    # Half the time put b inside a.
    if trial % 2:
        b = a + RNG.integers(0, side_a // side_b, size=3) * side_b
    else:
        b = RNG.integers(0, (1 << octant.MAX_LEVEL) // side_b, size=3) * side_b
    ka = octant.morton_key(*a)
    kb = octant.morton_key(*b)
    expect = la < lb and naive.octant_contains(a, la, b, lb)
    assert octant.octant_is_ancestor(ka, la, kb, lb) == expect
    assert octant.octant_overlaps(ka, la, kb, lb) == (naive.octant_contains(a, la, b, lb) or naive.octant_contains(b, lb, a, la))


def _uniform_tree(level):
    n = 1 << level
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) << (octant.MAX_LEVEL - level)
    keys = np.sort(octant.morton_keys(g))
    return keys, np.full(keys.shape, level, dtype=np.int8)


def test_tree_predicates_on_uniform_and_broken_trees():
    keys, levels = _uniform_tree(2)
    assert tree_is_sorted(keys, levels) and tree_is_linear(keys, levels) and tree_is_complete(keys, levels)
    assert not tree_is_complete(keys[:-1], levels[:-1])  # a hole
    assert tree_is_linear(keys[:-1], levels[:-1])
    # Insert the parent of the first eight octants: sorted but no longer linear.
    k2 = np.concatenate([[keys[0]], keys])
    l2 = np.concatenate([[1], levels]).astype(np.int8)
    assert tree_is_sorted(k2, l2) and not tree_is_linear(k2, l2)
    keep = linearize(k2, l2)
    assert keep[0] == False and keep[1:].all()  # noqa: E712
    assert not tree_is_sorted(keys[::-1], levels[::-1])


@pytest.mark.parametrize("seed", range(4))
def test_sorted_unique_matches_numpy_unique(seed):
    rng = np.random.default_rng(seed)
    values = rng.integers(-50, 50, size=int(rng.integers(0, 300)))
    assert np.array_equal(octant.sorted_unique(values), np.unique(values))
    keys = octant.morton_keys(rng.integers(0, 1 << 10, size=(200, 3)))
    assert np.array_equal(octant.sorted_unique(np.concatenate([keys, keys[::3]])), np.unique(keys))
    # Input already ascending (repeats kept) takes the path without a sort, and is not aliased.
    ordered = np.sort(np.concatenate([keys, keys[::3]]))
    out = octant.sorted_unique(ordered)
    assert np.array_equal(out, np.unique(keys)) and not np.shares_memory(out, ordered)
    # Long enough for the radix sort: random Morton keys of a level, with repeats.
    level_keys = octant.morton_keys(rng.integers(0, 1 << 9, size=(5000, 3))) << np.int64(3 * (octant.MAX_LEVEL - 9))
    assert np.array_equal(octant.sorted_unique(level_keys[rng.permutation(5000)]), np.unique(level_keys))


@pytest.mark.parametrize("seed", range(4))
def test_radix_sort_is_numpys_sort(seed):
    """On random int64 of every range (both signs, the extremes, a few values, all equal,
    values differing only in high or only in low bits) and lengths 0..3 * RADIX_MIN."""
    rng = np.random.default_rng(seed)
    info = np.iinfo(np.int64)
    cases = [np.zeros(0, dtype=np.int64), np.array([7]), np.full(3000, -5),
             np.array([info.max, info.min, 0, -1, 1, info.max, info.min]),
             rng.integers(info.min, info.max, size=6000, endpoint=True),
             rng.integers(-3, 3, size=5000),
             rng.integers(0, 1 << 20, size=4000) << np.int64(40),  # only high bits differ
             rng.integers(0, 2, size=4500) + np.int64(1 << 62),  # only the lowest bit differs
             rng.choice(np.array([info.min, info.max]), size=3000)]
    for values in cases:
        values = np.asarray(values, dtype=np.int64)
        got = octant.radix_sorted(values)
        assert got.dtype == np.int64 and np.array_equal(got, np.sort(values)), values[:4]


@pytest.mark.parametrize("seed", range(4))
def test_is_ascending_matches_its_definition(seed):
    rng = np.random.default_rng(seed)
    cases = [np.zeros(0, dtype=np.int64), np.array([7]), np.full(5, 3), np.arange(9), np.arange(9)[::-1].copy()]
    for _ in range(50):
        values = np.sort(rng.integers(-20, 20, size=int(rng.integers(2, 40))))
        if rng.random() < 0.5:  # one swap of two positions
            i, j = rng.integers(0, values.size, 2)
            values[[i, j]] = values[[j, i]]
        cases.append(values)
    for values in cases:
        assert octant.is_ascending(values) == all(values[i] <= values[i + 1] for i in range(values.size - 1))


@pytest.mark.parametrize("seed", range(4))
def test_ancestor_keys_match_coarsened_coordinates(seed):
    rng = np.random.default_rng(seed)
    level = int(rng.integers(0, octant.MAX_LEVEL + 1))
    coords = rng.integers(0, 1 << octant.MAX_LEVEL, size=(100, 3))
    side = 1 << (octant.MAX_LEVEL - level)
    want = octant.morton_keys(coords // side * side)
    assert np.array_equal(octant.ancestor_keys(octant.morton_keys(coords), level), want)


@pytest.mark.parametrize("seed", range(4))
def test_sorted_lookup_matches_isin_and_index(seed):
    rng = np.random.default_rng(seed)
    keys = octant.sorted_unique(rng.integers(0, 1000, size=int(rng.integers(0, 200))))
    shuffled = rng.integers(-10, 1010, size=300)
    ordered = np.sort(rng.integers(-10, 1010, size=5000))  # mostly sorted, in several chunks
    for values in (shuffled, ordered, np.concatenate([ordered, shuffled, ordered[::-1]])):
        at, found = octant.sorted_lookup(keys, values)
        assert np.array_equal(found, np.isin(values, keys))
        assert np.array_equal(keys[at[found]], values[found])
        assert np.array_equal(at, np.minimum(np.searchsorted(keys, values), max(keys.shape[0] - 1, 0)))


@pytest.mark.parametrize("seed", range(3))
def test_lower_bound_near_is_searchsorted_from_any_hint(seed):
    """Galloping from a hint finds the same index as a binary search over all keys: repeats,
    keys before, between and after all, empty arrays, hints at both ends."""
    import numba

    @numba.njit
    def search(keys, queries, hints):
        return np.array([octant.lower_bound_near(keys, queries[i], hints[i]) for i in range(queries.shape[0])])

    rng = np.random.default_rng(seed)
    for n in (0, 1, 2, 7, 300):
        keys = np.sort(rng.integers(-50, 50, size=n)).astype(np.int64)
        queries = rng.integers(-60, 60, size=400).astype(np.int64)
        hints = rng.integers(0, n + 1, size=400)
        hints[:2] = 0, n
        assert np.array_equal(search(keys, queries, hints), np.searchsorted(keys, queries, side="left"))


@pytest.mark.parametrize("seed", range(4))
def test_octants_in_cells_matches_coordinate_division(seed):
    """Against the obvious twin: an octant is in a cell of ``level`` iff its anchor coordinates
    divided by the cell side are those of one of the cells."""
    rng = np.random.default_rng(seed)
    level = int(rng.integers(1, 6))
    side = 1 << (octant.MAX_LEVEL - level)
    cell_coords = rng.integers(0, 1 << level, size=(20, 3)) * side
    cells = octant.sorted_unique(octant.morton_keys(cell_coords))
    anchors = np.concatenate([cell_coords + rng.integers(0, side, size=(20, 3)),
                              rng.integers(0, 1 << octant.MAX_LEVEL, size=(80, 3))])
    want = np.array([tuple(a // side) in {tuple(c // side) for c in cell_coords} for a in anchors])
    got = octant.octants_in_cells(octant.morton_keys(anchors), cells, level)
    assert want[:20].all() and not want.all()
    assert np.array_equal(got, want)
