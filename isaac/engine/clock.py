"""A monotonic clock that compiled code can read: `monotonic_ns()`, in integer nanoseconds.

For `isaac run --profile`, which times each stage inside the compiled driver
(`isaac.engine.driver`). numba has no clock of its own, so the compiled version calls the C
library's clock_gettime(CLOCK_MONOTONIC) by name (an intrinsic that emits the call; the name is
resolved when the code is loaded, so the kernels that read the clock stay in numba's on-disk
cache, which a ctypes function pointer, a per-process address, would prevent). Without the JIT
(NUMBA_DISABLE_JIT=1) it is Python's `time.monotonic_ns`, which reads the same clock.

About 20-50 ns a read on the 2-core development machine. Reading it never touches the physics:
the timed driver computes the same bits as the plain one (tests/test_profile.py).
Needs a C library with clock_gettime and a 64-bit `struct timespec` (two 64-bit integers:
Linux and macOS on 64-bit CPUs).
"""

from __future__ import annotations

import time

import numba

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

if numba.config.DISABLE_JIT:
    monotonic_ns = time.monotonic_ns
else:
    from llvmlite import ir
    from numba.core import cgutils, types
    from numba.extending import intrinsic

    _I32 = ir.IntType(32)
    _I64 = ir.IntType(64)

    @intrinsic
    def _clock_gettime_ns(typingctx):
        """clock_gettime(CLOCK_MONOTONIC, &spec); spec.tv_sec * 10^9 + spec.tv_nsec."""

        def codegen(context, builder, signature, args):
            spec = cgutils.alloca_once(builder, ir.ArrayType(_I64, 2))
            fnty = ir.FunctionType(_I32, [_I32, spec.type])
            fn = cgutils.get_or_insert_function(builder.module, fnty, "clock_gettime")
            builder.call(fn, [ir.Constant(_I32, time.CLOCK_MONOTONIC), spec])
            zero = ir.Constant(_I32, 0)
            seconds = builder.load(builder.gep(spec, [zero, zero]))
            nanoseconds = builder.load(builder.gep(spec, [zero, ir.Constant(_I32, 1)]))
            return builder.add(builder.mul(seconds, ir.Constant(_I64, 1_000_000_000)), nanoseconds)

        return types.int64(), codegen

    @numba.njit(cache=True, nogil=True, inline="always")
    def monotonic_ns():
        """Nanoseconds on the monotonic clock (an arbitrary origin; differences only)."""
        return _clock_gettime_ns()
