"""Load numba's cached kernels without first loading numba's compiler.

Before numba loads a kernel from its on-disk cache it "refreshes" its CPU target: it imports
and registers the lowering code of every Python and NumPy feature it can compile (about 70
modules: unicode strings, linalg, random generators, typed dicts, lists and sets, jitclasses,
datetimes...) and installs their registries. Loading needs none of it: the cached object code is
linked against numba's runtime (NRT) and helper library only, and the environments it
references import their own modules (`numba.core.environment._rebuild_env`). Compiling does
need it, and numba's compiler refreshes the target itself before every compile
(`numba.core.compiler.CompilerBase`), so a cache miss after lazy loads compiles as before.

Measured (cProfile, 2-core machine, warm cache): the refresh was 0.25-0.33 s of the 0.47 s
that pyramid-10's first `Simulation.step()` took (11 kernels loaded), and 0.16-0.19 s of
building its `Simulation`. With the collector paused while a kernel loads (below), the bench's
whole-process start-up to that first step took 0.77-0.81 of its CPU time before (interleaved
pairs, bench/README.md). The kernels and their bits are numba's own: only the moment of the
refresh moves (tests/test_kernel_loading.py).

`install()` replaces `numba.core.caching.Cache.load_overload` (numba 0.68's: refresh, then
``_load_overload``) by the same without the refresh, keeping the runtime's initialisation; it
leaves numba as it is when that method is not the one it knows (another numba version), and
``ISAAC_EAGER_KERNEL_LOADING=1`` turns it off. Imported by `isaac.engine.kernel_cache`, before
any kernel of the engine or the recorder is loaded.
"""

from __future__ import annotations

import gc
import os

EAGER_ENV = "ISAAC_EAGER_KERNEL_LOADING"


def install() -> bool:
    """Make cached loads skip numba's target refresh (once a process); returns whether the
    lazy loading is in place."""
    from numba.core import caching

    current = caching.Cache.load_overload
    if getattr(current, "isaac_lazy", False):
        return True
    if os.environ.get(EAGER_ENV) == "1":
        return False
    names = current.__code__.co_names
    if current.__qualname__ != "Cache.load_overload" or "_load_overload" not in names:
        return False  # not the method this replaces: leave numba alone
    from numba.core.runtime import rtsys

    def load_overload(self, sig, target_context):
        # what the cached code is linked against: the runtime (allocation, reference counts)
        rtsys.initialize(target_context)
        # a load makes thousands of objects (the unpickled library, the modules its
        # environments import) and frees none: the cyclic collector would only walk them
        paused = gc.isenabled()
        gc.disable()
        try:
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)
            # None returned if the `with` block swallows an exception (as numba's own)
        finally:
            if paused:
                gc.enable()

    load_overload.isaac_lazy = True
    load_overload.__doc__ = current.__doc__
    caching.Cache.load_overload = load_overload
    return True


LAZY = install()
