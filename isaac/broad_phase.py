"""Broad phase: candidate pairs whose bounding circles (the seed's MaxDist) and boxes overlap.

Sort-and-sweep along x over existing bodies, so a step costs O(n log n + k) rather than the seed's
O(n^2) nested loop. Concrete-concrete pairs and absent bodies are skipped.

determinism: the sweep order comes from a stable (merge) sort and the pairs found are then sorted
by the integer key a * n + b (a < b), so the output order depends only on the body indices.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def find_pairs(position, radius, aabb, expand, movable, exists, pair_a, pair_b):
    """Write candidate pairs (a < b, sorted by (a, b)) into pair_a / pair_b.

    position: (n, 2) m; radius: (n,) bounding radius (m); aabb: (n, 4) world boxes (m);
    expand: (n,) extra margin (m) for speculative contacts (0 without ccd); movable: (n,) bool.
    Returns the number of pairs; when it is larger than the buffers, nothing past the capacity
    was written and the caller must grow the buffers and call again.
    """
    n = position.shape[0]
    live = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        if exists[i]:
            live[m] = i
            m += 1
    live = live[:m]
    lo = np.empty(m)
    for k in range(m):
        i = live[k]
        lo[k] = aabb[i, 0] - expand[i]
    order = np.argsort(lo, kind="mergesort")
    capacity = pair_a.shape[0]
    count = 0
    for p in range(m):
        i = live[order[p]]
        hi_i = aabb[i, 2] + expand[i]
        for q in range(p + 1, m):
            j = live[order[q]]
            if aabb[j, 0] - expand[j] > hi_i:
                break
            if not movable[i] and not movable[j]:
                continue
            grow = expand[i] + expand[j]
            if aabb[j, 1] - expand[j] > aabb[i, 3] + expand[i]:
                continue
            if aabb[i, 1] - expand[i] > aabb[j, 3] + expand[j]:
                continue
            # the seed's MaxDist test: centres closer than the sum of the bounding radii
            dx = position[j, 0] - position[i, 0]
            dy = position[j, 1] - position[i, 1]
            reach = radius[i] + radius[j] + grow
            if dx * dx + dy * dy > reach * reach:
                continue
            if count < capacity:
                pair_a[count] = min(i, j)
                pair_b[count] = max(i, j)
            count += 1
    if count > capacity:
        return count
    key = np.empty(count, dtype=np.int64)
    for k in range(count):
        key[k] = pair_a[k] * n + pair_b[k]
    order2 = np.argsort(key, kind="mergesort")
    for k in range(count):
        pair_a[k] = key[order2[k]] // n
        pair_b[k] = key[order2[k]] % n
    return count


@numba.njit(cache=True)
def speculative_reach(velocity, angular_velocity, radius, look_ahead, extra, expand):
    """How far (m) each body can travel in `look_ahead` seconds: h (|v| + |w| r) + extra."""
    for i in range(velocity.shape[0]):
        speed = np.sqrt(velocity[i, 0] ** 2 + velocity[i, 1] ** 2)
        expand[i] = look_ahead * (speed + abs(angular_velocity[i]) * radius[i]) + extra
