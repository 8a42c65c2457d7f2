"""The stability suite: the engine at its extremes, one file per case family.

A package so that pytest puts `tests/` on sys.path (for `physics_helpers`) and these modules
get unique names (`extremes.test_energy`).
"""
