"""Broad phase: candidate pairs whose bounding circles (the seed's MaxDist) and boxes overlap.

Sort-and-sweep along x over existing bodies, so a step costs O(n log n + k) rather than the seed's
O(n^2) nested loop. Concrete-concrete pairs, absent bodies and (with filters) the pairs the
collision filter keeps apart are skipped.

determinism: the sweep order comes from a stable (merge) sort and the pairs found are then sorted
by (a, b) with a < b, so the output order depends only on the body indices and boxes.
(The merge sort is written out here: numba's np.argsort(kind="mergesort") took 2 s to compile,
a fifth of a first run's compile time.)
(A uniform grid was tried and was 3x slower than this sweep on piles of 100 to 10,000 bodies.)
"""

from __future__ import annotations

import numba
import numpy as np

from isaac import collision_filter
from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

# the scene's rule, compiled (a pure function of integers)
collides = numba.njit(cache=True, nogil=True, inline="always")(collision_filter.collides)

SWEEP_INDEX_ROWS = 6  # live, order, spare, body, per, slot (find_pairs scratch)
RUN = 16  # _stable_order insertion-sorts runs of this many elements before merging


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def find_pairs(
    position, radius, aabb, expand, movable, exists, sweeps, filtered, category, mask, group,
    no_collide, pair_a, pair_b, pair_spare, sweep_index, sweep_key, sweep_table,
):  # fmt: skip
    """Write candidate pairs (a < b, sorted by (a, b)) into pair_a / pair_b.

    position: (n, 2) m; radius: (n,) bounding radius (m); aabb: (n, 4) world boxes (m);
    expand: (n,) extra margin (m) for speculative contacts (0 without ccd); movable: (n,) bool.
    sweeps: (n,) bool, False for a body the filter keeps from every other one
    (`isaac.engine.world.Model.sweeps`): left out of the sweep, as an absent body (it makes no pair,
    so the pairs are the same; the 100 x 100 joint grid's circles, in columns that all
    overlap along x, made the sweep test 500,000 candidates a sub-step, 2.6 ms).
    filtered: whether to apply the collision filter (category, mask, group: (n,) int64,
    isaac.collision_filter) and drop the pairs listed in no_collide (sorted int64 keys
    a * n + b, a < b: bodies a joint connects) among those that pass the tests; False skips
    both.
    Scratch, contents on entry unused: pair_spare (like pair_a), sweep_index
    (SWEEP_INDEX_ROWS, n + 1) int64, sweep_key (n,) and sweep_table (n, 8) float64 (a step
    allocates nothing here: for a few bodies the allocations were most of the broad phase's
    time, 0.58 us of a 2-body step).
    Returns the number of pairs; when it is larger than the buffers, nothing past the capacity
    was written and the caller must grow the buffers and call again.

    The existing bodies' boxes, centres and radii are first gathered in sweep order into one
    contiguous table, so the sweep reads memory in order instead of jumping through indices.
    """
    n = position.shape[0]
    live = sweep_index[0]
    m = 0
    for i in range(n):
        if exists[i] and sweeps[i]:
            live[m] = i
            m += 1
    t = sweep_table
    lo = sweep_key[:m]
    for k in range(m):
        i = live[k]
        lo[k] = aabb[i, 0] - expand[i]
    order = _stable_order(lo, sweep_index[1], sweep_index[2])
    body = sweep_index[3]
    for k in range(m):
        i = live[order[k]]
        body[k] = i
    # sweep table, one row per body in order of its box's left edge:
    # lo_x, hi_x, lo_y, hi_y, x, y, reach (radius + margin), movable
    for k in range(m):
        i = body[k]
        e = expand[i]
        t[k, 0] = aabb[i, 0] - e
        t[k, 1] = aabb[i, 2] + e
        t[k, 2] = aabb[i, 1] - e
        t[k, 3] = aabb[i, 3] + e
        t[k, 4] = position[i, 0]
        t[k, 5] = position[i, 1]
        t[k, 6] = radius[i] + e
        t[k, 7] = 1.0 if movable[i] else 0.0
    capacity = pair_a.shape[0]
    count = 0
    for p in range(m):
        hi_x = t[p, 1]
        lo_y = t[p, 2]
        hi_y = t[p, 3]
        x = t[p, 4]
        y = t[p, 5]
        reach = t[p, 6]
        moving = t[p, 7]
        i = body[p]
        for q in range(p + 1, m):
            if t[q, 0] > hi_x:
                break
            # the seed's MaxDist test: centres closer than the sum of the bounding radii
            dx = t[q, 4] - x
            dy = t[q, 5] - y
            both = reach + t[q, 6]
            # the boxes do not overlap in y, both bodies are concrete (never collide), or the
            # bounding circles do not overlap; tested without branches (whether a candidate
            # passes is hard to predict), and the pair written either way: the next pair
            # found overwrites it
            skip = (
                (t[q, 2] > hi_y)
                | (lo_y > t[q, 3])
                | (moving + t[q, 7] == 0.0)
                | (dx * dx + dy * dy > both * both)
            )
            j = body[q]
            if filtered and not skip:
                skip = not collides(category[i], mask[i], group[i], category[j], mask[j], group[j])
                if not skip and no_collide.shape[0]:
                    key = min(i, j) * n + max(i, j)
                    at = np.searchsorted(no_collide, key)
                    skip = at < no_collide.shape[0] and no_collide[at] == key
            if count < capacity:
                pair_a[count] = min(i, j)
                pair_b[count] = max(i, j)
            count += 0 if skip else 1
    if count <= capacity:
        _sort_pairs(pair_a, pair_b, count, n, sweep_index[4], sweep_index[5], pair_spare)
    return count


# (_sort_pairs, _stable_order and _before are inlined into find_pairs, which is compiled without
# reference counts: a counted kernel called from it, returning a view, would leave the view's
# count raised)
@numba.njit(cache=True, nogil=True, inline="always")
def _sort_pairs(pair_a, pair_b, count, n, per, slot, sorted_b):
    """Sort pairs by (a, b): counting sort by a, then insertion sort of each a's few b's.
    per, slot: (n + 1,) and sorted_b: (count or more,) int64 scratch."""
    for i in range(n + 1):
        per[i] = 0
    for k in range(count):
        per[pair_a[k] + 1] += 1
    for i in range(n):
        per[i + 1] += per[i]
    for i in range(n + 1):
        slot[i] = per[i]
    for k in range(count):
        a = pair_a[k]
        sorted_b[slot[a]] = pair_b[k]
        slot[a] += 1
    for a in range(n):
        lo = per[a]
        hi = per[a + 1]
        for k in range(lo + 1, hi):
            b = sorted_b[k]
            m = k - 1
            while m >= lo and sorted_b[m] > b:
                sorted_b[m + 1] = sorted_b[m]
                m -= 1
            sorted_b[m + 1] = b
        for k in range(lo, hi):
            pair_a[k] = a
            pair_b[k] = sorted_b[k]


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def speculative_reach(velocity, angular_velocity, radius, look_ahead, extra, expand):
    """How far (m) each body can travel in `look_ahead` seconds: h (|v| + |w| r) + extra."""
    for i in range(velocity.shape[0]):
        # (products, not ** 2: pow is a libm call without the JIT)
        speed = np.sqrt(velocity[i, 0] * velocity[i, 0] + velocity[i, 1] * velocity[i, 1])
        expand[i] = look_ahead * (speed + abs(angular_velocity[i]) * radius[i]) + extra


@numba.njit(cache=True, nogil=True, inline="always")
def _stable_order(key, order, spare):
    """The permutation that sorts key stably: the same as np.argsort(key, kind="mergesort"),
    with NumPy's order (NaN after every number). Runs of RUN elements are insertion-sorted,
    then merged bottom up. order, spare: int64 scratch of at least len(key); returns one of
    them (its first len(key) entries)."""
    m = key.shape[0]
    for i in range(m):
        order[i] = i
    for start in range(0, m, RUN):
        end = min(start + RUN, m)
        for i in range(start + 1, end):
            x = order[i]
            j = i
            while j > start and _before(key[x], key[order[j - 1]]):
                order[j] = order[j - 1]
                j -= 1
            order[j] = x
    width = RUN
    while width < m:
        for start in range(0, m, 2 * width):
            mid = min(start + width, m)
            end = min(start + 2 * width, m)
            i = start
            j = mid
            k = start
            while i < mid and j < end:
                # the right run's element goes first only if strictly before (stable)
                if _before(key[order[j]], key[order[i]]):
                    spare[k] = order[j]
                    j += 1
                else:
                    spare[k] = order[i]
                    i += 1
                k += 1
            while i < mid:
                spare[k] = order[i]
                i += 1
                k += 1
            while j < end:
                spare[k] = order[j]
                j += 1
                k += 1
        order, spare = spare, order
        width *= 2
    return order


@numba.njit(cache=True, nogil=True, inline="always")
def _before(x, y):
    """x sorts strictly before y in NumPy's order (NaN after every number)."""
    return x < y or (y != y and x == x)
