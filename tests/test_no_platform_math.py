"""No platform math in the compiled step: the machine code of every numba kernel of the engine
and of the recorder's frame packing holds no fused multiply-add and no call into libm's
transcendental functions (whose last bit differs between libm implementations). Together with
isaac.trig and exactly rounded + - * / sqrt, that is what lets a log replay bit for bit on
another machine (docs/physics.md).

x86-64 only: the scan reads x86 mnemonics."""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
from pathlib import Path

import numba
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from asm_scan import scan  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(
    platform.machine().lower() not in ("x86_64", "amd64"),
    reason=f"the scan reads x86-64 assembly; this machine is {platform.machine()}",
)

# kernels the scan must have seen compiled (every stage, both drivers, the frame packers)
REQUIRED = {
    "isaac.trig.sin_cos",
    "isaac.engine.geometry.transform",
    "isaac.engine.driver.run_steps_seed",
    "isaac.engine.driver.run_steps_sequential",
    "isaac.engine.driver.run_steps_sequential_joints",
    "isaac.engine.driver.run_steps_sequential_joints_timed",
    "isaac.engine.joints.joint.solve_joint_velocities",
    "isaac.engine.broad_phase.find_pairs",
    "isaac.engine.narrow_phase.collide_pairs",
    "isaac.engine.push_out.push_out",
    "isaac.engine.solver.seed.solve_seed",
    "isaac.engine.solver.sequential.solve_sequential",
    "isaac.engine.integrate.advance_positions",
    "recorder.pack.pack_frame",
    "recorder.pack.pack_frames",
}
# compiled only for the Rerun viewer (float32 outlines and arrows, never replayed or compared)
VIEWER_ONLY = (
    "recorder.rerun_batch.",
    "recorder.pack.pack_rerun",
    "recorder.pack.rerun_offsets",
    "recorder.pack._put",  # and _put_pairs: pack_rerun's helpers
    "recorder.pack._first",
)


def _host_has_fma() -> bool:
    import llvmlite.binding as llvm

    return bool(llvm.get_host_cpu_features().get("fma"))


def test_the_scan_catches_libm_calls_and_fused_multiply_add():
    @numba.njit
    def uses_libm(x, y):
        return math.sin(x) + math.exp(y) + math.atan2(x, y) + math.pow(x, y)

    @numba.njit
    def plain(a, b, c):
        return a * b + c

    uses_libm(0.5, 0.25)
    plain(1.0, 2.0, 3.0)
    found = scan(uses_libm.inspect_asm(uses_libm.signatures[0]))
    assert {"sin", "exp", "atan2", "pow"} <= set(found["libm"]), found
    assert scan(plain.inspect_asm(plain.signatures[0])) == {"fma": [], "libm": []}
    if _host_has_fma():
        # fast-math lets LLVM contract a * b + c into one fused instruction
        @numba.njit(fastmath=True)
        def contracted(a, b, c):
            return a * b + c

        contracted(1.0, 2.0, 3.0)
        assert scan(contracted.inspect_asm(contracted.signatures[0]))["fma"]


def test_the_scan_reads_the_call_forms_of_x86_assembly():
    asm = (
        "\tmovabsq\t$cos, %rax\n\tcallq\t*%rax\n\tcallq\tlog1p@PLT\n\tjmp\texpf\n"
        "\tmovabsq\t$PyFloat_FromDouble, %rax\n\tcallq\tfloor\n\tvsqrtsd\t%xmm0, %xmm0, %xmm0\n"
        "\tvfnmadd231sd\t%xmm2, %xmm1, %xmm0\n\tvmulsd\t%xmm1, %xmm0, %xmm0\n"
    )
    assert scan(asm) == {"fma": ["vfnmadd231sd"], "libm": ["cos", "expf", "log1p"]}


@pytest.mark.slow
def test_no_fused_multiply_add_and_no_libm_call_in_any_compiled_kernel(tmp_path):
    """Every kernel compiled afresh (an empty NUMBA_CACHE_DIR: numba shows no code for what it
    loads from its cache) by small scenes through every path of the step, then scanned: about
    100 s of CPU time compiling (slow; `make test-all`). Measured: 60 signatures of 43 kernels,
    no FMA, no libm call."""
    out = tmp_path / "scan.json"
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "NUMBA_CPU_NAME")}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")
    done = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "asm_scan.py"), str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    kernels = json.loads(out.read_text())
    # every signature compiled in the scanning process, none loaded from the cache, whose
    # machine code numba does not show
    assert not {name: k["cached"] for name, k in kernels.items() if k["cached"]}
    compiled = {name for name, k in kernels.items() if k["signatures"]}
    assert REQUIRED <= compiled, sorted(REQUIRED - compiled)
    # every kernel of the step and of the recorder's packing was reached, except those numba
    # inlines into their callers (scanned there) and the viewer's
    missed = sorted(
        name
        for name, k in kernels.items()
        if not k["signatures"] and not k["inline"] and not name.startswith(VIEWER_ONLY)
    )
    assert not missed, missed
    bad = {
        f"{name} {sig}": found
        for name, k in kernels.items()
        for sig, found in k["signatures"].items()
        if found["fma"] or found["libm"]
    }
    assert not bad, bad
    assert sum(len(k["signatures"]) for k in kernels.values()) >= 50


# numpy reductions and products whose grouping (pairwise sums, BLAS blocking, threads) depends on
# the array's length or the machine, and libm's transcendental functions
_REDUCTIONS = {
    "sum", "nansum", "dot", "vdot", "inner", "matmul", "einsum", "tensordot", "mean", "average",
    "nanmean", "prod", "nanprod", "std", "var", "trace", "linalg", "fsum", "cross",
}  # fmt: skip
_TRANSCENDENTAL = {
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "asin", "acos", "atan", "atan2",
    "sinh", "cosh", "tanh", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "pow",
    "power", "hypot", "cbrt", "erf", "erfc", "gamma", "lgamma",
}  # fmt: skip


def _platform_math(source: str) -> list[str]:
    import ast

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(f"line {node.lineno}: @ (BLAS)")
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            module, name = node.value.id, node.attr
            if module in ("np", "numpy", "math") and name in _REDUCTIONS | _TRANSCENDENTAL:
                found.append(f"line {node.lineno}: {module}.{name}")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            receiver = node.func.value
            if isinstance(receiver, ast.Name) and receiver.id in ("np", "numpy", "math"):
                continue  # np.sum(...) is the Attribute above
            if node.func.attr in ("sum", "dot", "mean", "prod"):  # an array's own a.sum()
                found.append(f"line {node.lineno}: .{node.func.attr}()")
    return found


def test_the_engine_source_has_no_order_dependent_reduction_and_no_libm_call():
    """The step's sums are written-out loops in a fixed order; its sin/cos are isaac.trig's."""
    found = {}
    for path in sorted((ROOT / "isaac" / "engine").rglob("*.py")):
        hits = _platform_math(path.read_text())
        if hits:
            found[str(path.relative_to(ROOT))] = hits
    assert not found, found


def test_the_source_audit_would_catch_them():
    text = "import numpy as np\ndef f(a, b):\n    return np.sum(a) + a @ b + np.cos(a) + a.dot(b)\n"
    assert len(_platform_math(text)) == 4
