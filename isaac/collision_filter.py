"""The collision filter's rule, one function for the scene's warnings (numpy arrays) and the
engine's broad phase (compiled, on scalars): Box2D's rule (b2ShouldCollide in Box2D 2.3).

Two bodies collide when they share a non-zero group and it is positive; never when they share a
negative one; otherwise when each one's mask has a bit of the other's category. Written with
`&`, `|`, `^` and comparisons only, which mean the same on numpy bool arrays and on scalars
(`not`/`~` would not: `~True` is -2).
"""

from __future__ import annotations


def collides(category_a, mask_a, group_a, category_b, mask_b, group_b):
    """Whether bodies a and b may collide (bool, or a bool array for arrays)."""
    same = (group_a == group_b) & (group_a != 0)
    bits = ((mask_a & category_b) != 0) & ((mask_b & category_a) != 0)
    return (same & (group_a > 0)) | ((same ^ True) & bits)
