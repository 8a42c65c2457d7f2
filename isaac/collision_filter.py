"""The collision filter's rule, one function for the scene's warnings (numpy arrays) and the
engine's broad phase (compiled, on scalars): Box2D's rule (b2ShouldCollide in Box2D 2.3).

Two bodies collide when they share a non-zero group and it is positive; never when they share a
negative one; otherwise when each one's mask has a bit of the other's category. Written with
`&`, `|`, `^` and comparisons only, which mean the same on numpy bool arrays and on scalars
(`not`/`~` would not: `~True` is -2).
"""

from __future__ import annotations

import numpy as np


def collides(category_a, mask_a, group_a, category_b, mask_b, group_b):
    """Whether bodies a and b may collide (bool, or a bool array for arrays)."""
    same = (group_a == group_b) & (group_a != 0)
    bits = ((mask_a & category_b) != 0) & ((mask_b & category_a) != 0)
    return (same & (group_a > 0)) | ((same ^ True) & bits)


# beyond this many distinct filters `colliders` does not look (its test is one per pair of them)
MOST_FILTERS = 1024


def colliders(category, mask, group):
    """(n,) bool: which bodies some other body may collide with by the rule, given every body's
    (category, mask, group) as (n,) int64 arrays. A body the rule keeps from all the others
    (the circles of Box2D v3's joint grid, one negative group) never makes a pair, and the broad
    phase leaves it out of its sweep. Bodies with one filter are one class: a class collides
    with another class present, or with itself when it has two bodies or more. All True when
    there are more than MOST_FILTERS distinct filters (then it does not look)."""
    n = category.shape[0]
    triples = np.stack([category, mask, group], axis=1)
    classes, of_body, count = np.unique(triples, axis=0, return_inverse=True, return_counts=True)
    if classes.shape[0] > MOST_FILTERS:
        return np.ones(n, dtype=bool)
    c = classes
    meets = collides(c[:, None, 0], c[:, None, 1], c[:, None, 2], c[None, :, 0], c[None, :, 1],
                     c[None, :, 2])  # fmt: skip
    np.fill_diagonal(meets, np.diagonal(meets) & (count >= 2))
    return meets.any(axis=1)[of_body.reshape(n)]
