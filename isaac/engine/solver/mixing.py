"""How two bodies' coefficients (restitution, friction) combine into a pair's."""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

RULE_MAX = 0
RULE_MIN = 1
RULE_MEAN = 2
RULE_PRODUCT = 3
RULE_SQRT = 4  # geometric mean (friction's default)
RULE_CODES = {
    "max": RULE_MAX,
    "min": RULE_MIN,
    "mean": RULE_MEAN,
    "product": RULE_PRODUCT,
    "sqrt": RULE_SQRT,
}


@numba.njit(cache=True, nogil=True)
def combine(rule, x, y):
    """Mix two bodies' coefficients (restitution or friction) by a pair rule."""
    if rule == RULE_MAX:
        return max(x, y)
    if rule == RULE_MIN:
        return min(x, y)
    if rule == RULE_MEAN:
        return 0.5 * (x + y)
    if rule == RULE_PRODUCT:
        return x * y
    return np.sqrt(x * y)
