"""Ragged arrays: groups of different sizes stored one after another in flat arrays."""
from __future__ import annotations

import numpy as np


def group_offsets(counts) -> np.ndarray:
    """0 .. counts[i] - 1 for each i in turn: the place of each element within its group when groups
    of ``counts`` (ints >= 0) elements follow one another. E.g. [2, 0, 3] -> [0, 1, 0, 1, 2]."""
    counts = np.asarray(counts)
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
