"""Gated optimal assignment: which rows of a cost matrix go with which columns (people to their tracks, hands to
the bodies' wrists), by scipy's `linear_sum_assignment` over the pairs a gate allows."""

import numpy as np
from scipy.optimize import linear_sum_assignment


def gated_pairs(cost: np.ndarray) -> list[tuple[int, int]]:
    """The pairs ``(row, column)`` of ``cost (R, C)``, each row and column in at most one, that pair the most rows
    among the finite entries (inf: a pair the gate refuses), and among those the least total cost."""
    cost = np.asarray(cost, np.float64)
    allowed = np.isfinite(cost)
    if not allowed.any():
        return []
    # a refused pair costs more than any set of allowed pairs can differ by: the most pairs first, then the cheapest
    refused = 2.0 * min(cost.shape) * np.abs(cost[allowed]).max() + 1.0
    rows, columns = linear_sum_assignment(np.where(allowed, cost, refused))
    return [(int(r), int(c)) for r, c in zip(rows, columns) if allowed[r, c]]
