"""Exchanges between ranges of Morton keys (partition, range_pinches, range_finish): which
rows a range sends to each owner, and ids numbered by their owners.  Here a send is a list
append; between workers it is one exchange."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .octant import sorted_unique


def rows_by_owner(owners: np.ndarray, n_ranges: int) -> list[tuple[int, np.ndarray]]:
    """(range, its rows (ascending)) for each range among owners (R,) (0..n_ranges-1), in range
    order: what a range sends each owner."""
    if owners.size and owners.min() == owners.max():  # one owner (the usual case)
        return [(int(owners[0]), np.arange(owners.shape[0]))]
    order = np.argsort(owners, kind="stable")
    bounds = np.searchsorted(owners[order], np.arange(n_ranges + 1))
    return [(int(r), order[bounds[r]:bounds[r + 1]]) for r in np.flatnonzero(np.diff(bounds))]


def owned_ids(keys: Sequence[np.ndarray], owners: Sequence[np.ndarray], n_ranges: int) -> tuple[list[np.ndarray], int]:
    """Ids 0..K-1 of the K distinct keys that pieces hold (keys[i] (N_i,) int64, owners[i]
    (N_i,): the range owning each, a function of the key), numbered with no sort of them all:
    each piece sends its keys to their owners, each owner numbers the distinct keys it
    receives in ascending order, an exclusive scan of the owners' counts gives each owner its
    first id, and each piece reads its keys' ids back from their owners.  Returns (the ids of
    each piece's keys, K).  (Between workers: one exchange each way, and the scan a reduction
    of one count a range.)"""
    received: list[list[np.ndarray]] = [[] for _ in range(n_ranges)]
    sent = []
    for piece_keys, piece_owners in zip(keys, owners):
        groups = rows_by_owner(piece_owners, n_ranges)
        for r, rows in groups:
            received[r].append(piece_keys[rows])
        sent.append(groups)
    owned = [sorted_unique(np.concatenate(part)) if part else np.zeros(0, dtype=np.int64) for part in received]
    first = np.concatenate([[0], np.cumsum([o.shape[0] for o in owned])]).astype(np.int64)
    ids = []
    for piece_keys, groups in zip(keys, sent):
        piece_ids = np.empty(piece_keys.shape[0], dtype=np.int64)
        for r, rows in groups:
            piece_ids[rows] = first[r] + np.searchsorted(owned[r], piece_keys[rows])
        ids.append(piece_ids)
    return ids, int(first[-1])


__all__ = ["owned_ids", "rows_by_owner"]
