"""Octree algorithms against slow, obvious twins on random trees (fixed seeds)."""

import itertools

import numpy as np
import pytest

from paroct import octant
from paroct.octree import (
    _insulation_parents,
    balance,
    complete_from_seeds,
    octants_holding,
    octants_within,
    refine_to_level,
    tree_is_balanced,
    tree_is_complete,
    tree_is_linear,
    unique_level_keys,
    written_slots,
)

ML = octant.MAX_LEVEL


def _box(key, level):
    x, y, z = octant.morton_decode(np.array([key]))[0]
    side = 1 << (ML - int(level))
    return np.array([x, y, z]), side


def _touch(a, la, b, lb):
    (pa, sa), (pb, sb) = _box(a, la), _box(b, lb)
    return all(pa[i] <= pb[i] + sb and pb[i] <= pa[i] + sa for i in range(3))


def naive_is_balanced(keys, levels):
    """All pairs: touching leaves differ by at most one level."""
    for i in range(len(keys)):
        for j in range(i + 1, len(keys)):
            if abs(int(levels[i]) - int(levels[j])) > 1 and _touch(keys[i], levels[i], keys[j], levels[j]):
                return False
    return True


def naive_balance(keys, levels):
    """Split the coarser leaf of any unbalanced touching pair until none is left."""
    leaves = {(int(k), int(l)) for k, l in zip(*complete_from_seeds(keys, levels))}
    changed = True
    while changed:
        changed = False
        items = sorted(leaves)
        for a, la in items:
            for b, lb in items:
                if lb > la + 1 and _touch(a, la, b, lb):
                    leaves.discard((a, la))
                    step = 3 * (ML - la - 1)
                    leaves |= {(a | (c << step), la + 1) for c in range(8)}
                    changed = True
                    break
            if changed:
                break
    out = sorted(leaves)
    return np.array([k for k, _ in out], dtype=np.int64), np.array([l for _, l in out], dtype=np.int8)


def _random_seeds(rng, n, max_level):
    levels = rng.integers(1, max_level + 1, size=n)
    keys = []
    for lev in levels:
        side = 1 << (ML - lev)
        keys.append(octant.morton_key(*(rng.integers(0, 1 << lev, size=3) * side)))
    keys = np.array(keys, dtype=np.int64)
    order = np.lexsort((levels, keys))
    return keys[order], levels[order].astype(np.int8)


@pytest.mark.parametrize("seed", range(12))
def test_complete_from_seeds_covers_root_and_keeps_seeds(seed):
    rng = np.random.default_rng(seed)
    keys, levels = _random_seeds(rng, 6, 4)
    ck, cl = complete_from_seeds(keys, levels)
    assert tree_is_complete(ck, cl)
    # Every seed is a leaf or refined: the leaf at its anchor is at least as fine.
    for k, lev in zip(keys, levels):
        j = np.searchsorted(ck, k, side="right") - 1
        assert cl[j] >= lev


def _naive_complete(keys, levels):
    """Split from the root every octant that has a seed as a strict descendant."""
    seeds = list(zip(keys.tolist(), levels.tolist()))
    out, todo = [], [(0, 0)]
    while todo:
        key, lev = todo.pop()
        if any(sl > lev and key <= sk <= _last(key, lev) for sk, sl in seeds):
            step = 3 * (ML - lev - 1)
            todo.extend((key | (c << step), lev + 1) for c in range(8))
        else:
            out.append((key, lev))
    out.sort()
    return np.array([k for k, _ in out], dtype=np.int64), np.array([lv for _, lv in out], dtype=np.int8)


@pytest.mark.parametrize("seed", range(8))
def test_complete_from_seeds_matches_naive_splitting(seed):
    # Many seeds, repeated ones and ancestors of others among them (levels in any order
    # among equal keys): the descent's cursor must not skip any.
    rng = np.random.default_rng(300 + seed)
    keys, levels = _random_seeds(rng, 30, 4)
    parents = np.array([octant.octant_parent_key(k, lv) for k, lv in zip(keys[:10], levels[:10])], dtype=np.int64)
    keys = np.concatenate([keys, keys[:5], parents])
    levels = np.concatenate([levels, levels[:5], np.maximum(levels[:10] - 1, 0)]).astype(np.int8)
    order = np.argsort(keys, kind="stable")
    keys, levels = keys[order], levels[order]
    got = complete_from_seeds(keys, levels)
    want = _naive_complete(keys, levels)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


@pytest.mark.parametrize("keys, levels", [
    ([], []),  # the root alone
    ([0], [0]),  # the root as a seed
    ([(1 << (3 * ML)) - 1], [ML]),  # the last finest octant: no gap after it
    ([0], [ML]),  # the first finest octant: no gap before it
    ([c << (3 * (ML - 1)) for c in range(8)], [1] * 8),  # the root's children, no gaps
    ([0, 0, 0], [3, 1, 2]),  # one anchor at three levels: the finest only
])
def test_complete_from_seeds_at_the_ends_of_the_key_range(keys, levels):
    keys, levels = np.array(keys, dtype=np.int64), np.array(levels, dtype=np.int8)
    got = complete_from_seeds(keys, levels)
    want = _naive_complete(keys, levels)
    assert tree_is_complete(*got) and np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


@pytest.mark.parametrize("level,n", [(1, 3), (2, 40), (4, 50), (4, 3000), (6, 100), (12, 20000)])
def test_insulation_parents_lists_every_neighbour_in_the_root(level, n):
    # Clustered parents repeat most neighbours; the table of listed keys must drop only repeats.
    rng = np.random.default_rng(level * 1000 + n)
    side = 1 << (ML - level + 1)
    span = min(1 << (level - 1), 24)
    coords = rng.integers(0, span, size=(n, 3))
    parents = np.unique(octant.morton_keys(coords * side))
    want = set()
    for x, y, z in coords.tolist():
        for d in itertools.product((-1, 0, 1), repeat=3):
            q = (x + d[0], y + d[1], z + d[2])
            if d != (0, 0, 0) and all(0 <= c < 1 << (level - 1) for c in q):
                want.add(octant.morton_key(q[0] * side, q[1] * side, q[2] * side))
    got = _insulation_parents(parents, level)
    assert set(got.tolist()) == want
    assert len(got) <= 26 * len(parents) and (n < 1000 or len(got) < 3 * len(want))


@pytest.mark.parametrize("seed", range(12))
def test_balance_matches_naive_splitting(seed):
    rng = np.random.default_rng(100 + seed)
    keys, levels = _random_seeds(rng, 3, 5)
    bk, bl = balance(keys, levels)
    assert tree_is_complete(bk, bl) and tree_is_linear(bk, bl)
    assert tree_is_balanced(bk, bl) and naive_is_balanced(bk, bl)
    nk, nl = naive_balance(keys, levels)
    assert np.array_equal(bk, nk) and np.array_equal(bl, nl)


def test_tree_is_balanced_detects_a_corner_violation():
    # A level-4 octant at the far corner of the first level-1 octant touches the other level-1
    # leaves at a corner: completion alone leaves it three levels finer than them.
    c = (1 << (ML - 1)) - (1 << (ML - 4))
    seed = np.array([octant.morton_key(c, c, c)], dtype=np.int64)
    keys, levels = complete_from_seeds(seed, np.array([4], dtype=np.int8))
    assert not tree_is_balanced(keys, levels) and not naive_is_balanced(keys, levels)
    bk, bl = balance(seed, np.array([4], dtype=np.int8))
    assert tree_is_balanced(bk, bl) and naive_is_balanced(bk, bl)


def _last(key, level):
    return int(key) | ((1 << (3 * (ML - int(level)))) - 1)


@pytest.mark.parametrize("seed", range(6))
def test_octants_holding_matches_a_scan(seed):
    rng = np.random.default_rng(seed)
    level = int(rng.integers(1, 4))
    side = 1 << (ML - level)
    coords = np.unique(rng.integers(0, 1 << level, size=(40, 3)), axis=0) * side
    keys = np.sort(octant.morton_keys(coords))
    cell_side = 1 << (ML - 6)
    cells = octant.morton_keys(rng.integers(0, 1 << 6, size=(int(rng.integers(0, 60)), 3)) * cell_side)
    cells = np.unique(np.concatenate([cells, keys[::3], keys[1::4] + 1]))  # cells at octant anchors too
    got = octants_holding(keys, level, cells)
    want = [any(int(k) <= int(c) <= _last(k, level) for c in cells) for k in keys]
    assert got.tolist() == want


@pytest.mark.parametrize("seed", range(6))
def test_octants_within_matches_a_scan(seed):
    rng = np.random.default_rng(seed)
    outer_keys, outer_levels = complete_from_seeds(*_random_seeds(rng, 6, 4))
    pick = rng.random(len(outer_keys)) < 0.5  # disjoint, with gaps
    outer_keys, outer_levels = outer_keys[pick], outer_levels[pick]
    keys, levels = _random_seeds(rng, 80, 5)
    got = octants_within(keys, levels, outer_keys, outer_levels)
    want = [any(lo <= lv and int(ko) <= int(k) and _last(k, lv) <= _last(ko, lo) for ko, lo in zip(outer_keys, outer_levels))
            for k, lv in zip(keys, levels)]
    assert got.tolist() == want and any(want) and not all(want)


@pytest.mark.parametrize("depth", [0, 1, 2])
def test_refine_to_level_lists_every_descendant_in_morton_order(depth):
    """Slow twin: each octant's descendants at level + depth keyed from their anchors, sorted."""
    rng = np.random.default_rng(40 + depth)
    level = 5
    side = 1 << (ML - level)
    anchors = rng.integers(0, 1 << level, size=(20, 3)) * side
    keys = np.unique(octant.morton_keys(anchors))
    child = side >> depth
    expected = []
    for x, y, z in octant.morton_decode(keys):
        below = [octant.morton_keys(np.array([[x + i * child, y + j * child, z + k * child]]))[0]
                 for i, j, k in itertools.product(range(1 << depth), repeat=3)]
        expected.extend(sorted(below))
    assert np.array_equal(refine_to_level(keys, level, level + depth), expected)


@pytest.mark.parametrize("seed", range(4))
def test_unique_level_keys_by_bitmap_or_sort_are_the_set_of_keys(seed):
    """Distinct keys of one level, ascending, against a Python set: levels whose cells a
    bitmap holds (2, 3, 7) and one too fine for it (12, sorted), with repeats, shuffled, and
    no keys at all."""
    rng = np.random.default_rng(seed)
    for level, n in [(2, 1), (3, 0), (3, 200), (7, 5000), (12, 3000)]:
        coords = rng.integers(0, 1 << level, size=(n, 3))
        keys = octant.morton_keys(coords << (ML - level))
        keys = np.concatenate([keys, keys[: n // 2]])
        rng.shuffle(keys)
        got = unique_level_keys(keys, level)
        assert got.dtype == np.int64 and got.tolist() == sorted(set(keys.tolist()))


@pytest.mark.parametrize("n", [0, 1, 7, 500])
def test_written_slots_are_each_runs_slots_in_order(n):
    """written_slots: counts[f] slots from offsets[f] on, run after run, as numpy's
    concatenated aranges (runs of zero length and a gap after each)."""
    rng = np.random.default_rng(n)
    capacity = rng.integers(0, 6, n)
    offsets = np.concatenate([[0], np.cumsum(capacity)])[:n].astype(np.int64)
    counts = (capacity * rng.random(n)).astype(np.int64)
    want = np.concatenate([np.arange(o, o + c) for o, c in zip(offsets, counts)] + [np.zeros(0, dtype=np.int64)])
    assert np.array_equal(written_slots(offsets, counts), want)
