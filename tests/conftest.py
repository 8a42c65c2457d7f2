"""Suite-wide checks."""

import os

import pytest


@pytest.fixture(autouse=True)
def _cpus_given_back():
    """A Recorder pins this process to some CPUs while it records and gives them back when it
    closes; a test that leaves it pinned would run every later test on fewer CPUs (and break
    the affinity tests), so it fails here, and the CPUs are given back."""
    if not hasattr(os, "sched_getaffinity"):
        yield
        return
    before = os.sched_getaffinity(0)
    yield
    after = os.sched_getaffinity(0)
    if after != before:
        os.sched_setaffinity(0, before)
        pytest.fail(f"the test left this process on CPUs {sorted(after)} of {sorted(before)}")
