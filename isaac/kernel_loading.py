"""Load numba's cached kernels without first loading numba's compiler.

Before numba loads a kernel from its on-disk cache it "refreshes" its CPU target: it imports
and registers the lowering code of every Python and NumPy feature it can compile (about 70
modules: unicode strings, linalg, random generators, typed dicts, lists and sets, jitclasses,
datetimes...) and installs their registries. Loading needs none of it: the cached object code is
linked against numba's runtime (NRT) and helper library only, and the environments it
references import their own modules (`numba.core.environment._rebuild_env`). Compiling does
need it, and numba's compiler refreshes the target itself before every compile
(`numba.core.compiler.CompilerBase`), so a cache miss after lazy loads compiles as before.

The kernels and their bits are numba's own: only the moment of the refresh moves
(tests/test_kernel_loading.py). What it saves on a cached start-up: docs/speed.md.

Two more things a cached load does that a run does not need, skipped the same way:

- It parses the LLVM bitcode numba keeps beside each kernel's object code (the kernel's IR, for
  compiling other code against it: inlining, linking) only to list the symbols the object
  defines. Here the list is read from the object's own ELF symbol table (the same names, checked
  for every engine kernel), and the bitcode is parsed when something asks for it
  (``_shared_module``: a kernel compiled later that calls this one, or numba saving it again).
- Rebuilding a kernel's environments imports the module of every function inlined into it; for
  numba's own implementation modules (``numba.np.arraymath`` pulls in ``numba.np.arrayobj``,
  the unicode and charseq support, ``numba.np.linalg`` and SciPy's BLAS) that import is
  deferred to the module's first use (``importlib.util.LazyLoader``). Compiled code without
  object mode never reads those globals; numba's compiler imports the modules itself when it
  refreshes its target.

`install()` replaces `numba.core.caching.Cache.load_overload` (numba 0.68's: refresh, then
``_load_overload``) by the same without the refresh, keeping the runtime's initialisation, and
wraps ``CPUCodeLibrary._unserialize`` and ``numba.core.environment._rebuild_env`` for the two
above; it leaves numba as it is on a numba release `TESTED_NUMBA` does not name, when those are
not the ones it knows, and when ``ISAAC_EAGER_KERNEL_LOADING=1`` turns all three off. Imported by
`isaac.engine.kernel_cache`, before any kernel of the engine or the recorder is loaded.

`tolerate_stale_indexes` (installed by `isaac.engine.kernel_cache` for the caches it keys, with
or without the above) makes a cache index an older engine wrote, naming types this one lacks,
a miss instead of an AttributeError at every run.
"""

from __future__ import annotations

import gc
import os
import struct
import sys

EAGER_ENV = "ISAAC_EAGER_KERNEL_LOADING"

# the numba releases (major.minor) whose internals the replacements below were read from and
# tested with; on any other numba loads its kernels itself (tests/test_kernel_loading.py)
TESTED_NUMBA = ("0.68",)


def tested_numba(version: str) -> bool:
    """Whether numba ``version`` (e.g. ``'0.68.1'``) is one `TESTED_NUMBA` names."""
    return ".".join(version.split(".")[:2]) in TESTED_NUMBA


def install() -> bool:
    """Make cached loads skip numba's target refresh, the bitcode parse and the environments'
    imports (once a process); returns whether the lazy loading is in place (the refresh's
    replacement at least: the other two also check numba's code before they replace it)."""
    import numba
    from numba.core import caching

    current = caching.Cache.load_overload
    if getattr(current, "isaac_lazy", False):
        return True
    if os.environ.get(EAGER_ENV) == "1" or not tested_numba(numba.__version__):
        return False  # numba's own loading
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
    _install_lazy_bitcode()
    _install_lazy_environments()
    _install_plain_ndarray_typeof()
    return True


# ---- the bitcode: parsed when asked for ------------------------------------------------------


def elf_defined_symbols(obj: bytes) -> set[str] | None:
    """The names an ELF64 little-endian relocatable object defines (its symbol table's symbols
    with a section, sections and file names left out), or None for any other object format."""
    try:
        if obj[:4] != b"\x7fELF" or obj[4] != 2 or obj[5] != 1:  # ELFCLASS64, ELFDATA2LSB
            return None
        (shoff,) = struct.unpack_from("<Q", obj, 0x28)
        shentsize, shnum = struct.unpack_from("<HH", obj, 0x3A)
        # Elf64_Shdr: name, type, flags, addr, offset, size, link, info, addralign, entsize
        sections = [
            struct.unpack_from("<IIQQQQIIQQ", obj, shoff + i * shentsize) for i in range(shnum)
        ]
        names: set[str] = set()
        for _, kind, _, _, offset, size, link, _, _, entsize in sections:
            if kind != 2 or not entsize:  # SHT_SYMTAB
                continue
            strings = sections[link][4]
            for k in range(size // entsize):
                # Elf64_Sym: name, info, other, section index, value, size
                name, info, _, shndx, _, _ = struct.unpack_from(
                    "<IBBHQQ", obj, offset + k * entsize
                )
                if name == 0 or shndx == 0 or (info & 0xF) in (3, 4):  # UNDEF, SECTION, FILE
                    continue
                start = strings + name
                names.add(obj[start : obj.index(b"\0", start)].decode())
        return names
    except (struct.error, ValueError, IndexError, UnicodeDecodeError):
        return None


_LAZY_LIBRARIES: dict[type, type] = {}


def _lazy_library(base: type) -> type:
    """`base` (numba's JITCodeLibrary) whose ``_shared_module`` (the bitcode for linking) is
    parsed from the cached bytes at its first use."""
    cls = _LAZY_LIBRARIES.get(base)
    if cls is None:

        class LazyBitcodeLibrary(base):
            @property
            def _shared_module(self):
                d = self.__dict__
                if "_isaac_bitcode" in d:
                    import llvmlite.binding as ll

                    d["_isaac_shared_module"] = ll.parse_bitcode(d.pop("_isaac_bitcode"))
                return d.get("_isaac_shared_module")

            @_shared_module.setter
            def _shared_module(self, module):
                self.__dict__.pop("_isaac_bitcode", None)
                self.__dict__["_isaac_shared_module"] = module

        cls = _LAZY_LIBRARIES[base] = LazyBitcodeLibrary
    return cls


def _install_lazy_bitcode() -> bool:
    from numba.core import codegen

    current = codegen.CPUCodeLibrary.__dict__.get("_unserialize")
    unserialize = getattr(current, "__func__", None)
    if unserialize is None:
        return False
    if getattr(unserialize, "isaac_lazy", False):
        return True
    names = unserialize.__code__.co_names
    if not {"_set_compiled_object", "_load_defined_symbols", "parse_bitcode"} <= set(names):
        return False  # not numba 0.68's: leave it

    def _unserialize(cls, codegen, state):
        # numba's 'object' branch, with the symbols read from the object code instead of the
        # parsed bitcode, and the bitcode kept as bytes (see the module docstring)
        name, kind, data = state
        if kind == "object":
            object_code, shared_bitcode = data
            symbols = elf_defined_symbols(object_code)
            if symbols is not None:
                self = codegen.create_library(name)
                assert isinstance(self, cls)
                self.enable_object_caching()
                self._set_compiled_object(object_code)
                self.__dict__.pop("_shared_module", None)
                self.__class__ = _lazy_library(type(self))
                self._isaac_bitcode = shared_bitcode
                self._finalize_final_module()
                codegen._engine._defined_symbols |= symbols
                return self
        return unserialize(cls, codegen, state)

    _unserialize.isaac_lazy = True
    codegen.CPUCodeLibrary._unserialize = classmethod(_unserialize)
    return True


# ---- numba's implementation modules: imported at their first use -------------------------------

_LAZY_MODULES: dict[str, tuple] = {}  # name -> (the module as put in sys.modules, its globals)
_DEFERRED: list = []  # the lazily imported modules that may not have run yet


def _lazy_globals(modname: str) -> dict | None:
    """The globals of numba's module `modname`, imported lazily if it is not imported yet; None
    when numba's own import is to be used (another module, an imported one, no source)."""
    if not modname.startswith("numba."):
        return None
    known = _LAZY_MODULES.get(modname)
    if known is not None and sys.modules.get(modname) is known[0]:
        return known[1]
    if modname in sys.modules:
        return None
    import importlib.util

    spec = importlib.util.find_spec(modname)
    if spec is None or not hasattr(spec.loader, "exec_module"):
        return None
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    module_globals = module.__dict__  # (before exec_module: any attribute read after it imports)
    sys.modules[modname] = module
    loader.exec_module(module)
    parent, _, child = modname.rpartition(".")
    setattr(sys.modules[parent], child, module)
    _LAZY_MODULES[modname] = (module, module_globals)
    _DEFERRED.append(module)
    return module_globals


def _install_lazy_environments() -> bool:
    from numba.core import environment

    current = environment._rebuild_env
    if getattr(current, "isaac_lazy", False):
        return True
    code = current.__code__
    if code.co_varnames[:3] != ("modname", "consts", "env_name") or "import_module" not in (
        code.co_names
    ):
        return False  # not numba 0.68's: leave it

    def _rebuild_env(modname, consts, env_name):
        # numba's, with the module's globals taken before the module runs (see the docstring)
        env = environment.lookup_environment(env_name)
        if env is not None:
            return env
        module_globals = _lazy_globals(modname) if isinstance(modname, str) else None
        if module_globals is None:
            return current(modname, consts, env_name)
        env = environment.Environment(module_globals)
        env.consts[:] = consts
        env.env_name = env_name
        environment.Environment._memo[env_name] = env
        return env

    _rebuild_env.isaac_lazy = True
    # (cached environments are unpickled through this module attribute)
    environment._rebuild_env = _rebuild_env
    # numba's compiler registers its typing and lowering (the @overload functions of
    # numba.np.arraymath...) by importing those modules when it refreshes its contexts: a
    # deferred one must run first, or a later compile would not know np.sum
    from numba.core.base import BaseContext as TargetContext
    from numba.core.typing.context import BaseContext as TypingContext

    for context in (TargetContext, TypingContext):
        context.refresh = _after_deferred_imports(context.refresh)
    return True


def _after_deferred_imports(refresh):
    def refreshed(self):
        while _DEFERRED:
            module = _DEFERRED.pop()
            _ = module.__name__  # (reading any attribute runs a lazily imported module)
        return refresh(self)

    refreshed.__doc__ = refresh.__doc__
    return refreshed


# ---- numpy.ma: not imported to type a plain array ---------------------------------------------


def _install_plain_ndarray_typeof() -> bool:
    """numba types every array argument it does not recognise in C (an array in a tuple or
    named bundle: the engine's) by first asking whether it is a np.ma.MaskedArray, which imports
    numpy.ma (5-10 ms of CPU) on the first call. An array whose class is np.ndarray itself is
    not one; any subclass still goes to numba's own function."""
    import numpy as np
    from numba.core import errors, types
    from numba.core.typing.typeof import typeof_impl
    from numba.np import numpy_support

    original = typeof_impl.dispatch(np.ndarray)
    if getattr(original, "isaac_lazy", False):
        return True
    names = set(original.__code__.co_names)
    if (
        original.__name__ != "_typeof_ndarray"
        or not {
            "MaskedArray",
            "from_dtype",
            "map_layout",
        }
        <= names
    ):
        return False  # not numba 0.68's: leave it

    def _typeof_ndarray(val, c):
        if type(val) is not np.ndarray:
            return original(val, c)
        # numba 0.68's _typeof_ndarray after its MaskedArray test
        try:
            dtype = numpy_support.from_dtype(val.dtype)
        except errors.NumbaNotImplementedError:
            raise errors.NumbaValueError(f"Unsupported array dtype: {val.dtype}") from None
        layout = numpy_support.map_layout(val)
        readonly = not val.flags.writeable
        return types.Array(dtype, val.ndim, layout, readonly=readonly)

    _typeof_ndarray.isaac_lazy = True
    typeof_impl.register(np.ndarray)(_typeof_ndarray)
    return True


LAZY = install()


def tolerate_stale_indexes(keys) -> None:
    """Make numba's index of a kernel whose cache is keyed by one of `keys` (the collection
    `isaac.engine.kernel_cache` fills; a keyed stamp ends with its key) read as empty when it
    does not unpickle: a miss, so the kernel compiles and its index is written anew. numba
    unpickles an index's signatures before it compares its stamp, and the index an older engine
    wrote names the types it had (a renamed kernel argument type made every later run in that
    tree fail with an AttributeError). Any other cache's index loads as numba loads it. Once a
    process; whatever ISAAC_EAGER_KERNEL_LOADING says (it is not about the loading's speed)."""
    import pickle

    from numba.core import caching

    index_file = caching.IndexDataCacheFile
    if getattr(index_file._load_index, "isaac_tolerant", False):
        return
    load = index_file._load_index
    unreadable = (pickle.UnpicklingError, AttributeError, ImportError, EOFError, TypeError)

    def _load_index(self):
        try:
            return load(self)
        except unreadable:
            stamp = self._source_stamp
            if not (isinstance(stamp, tuple) and stamp and stamp[-1] in keys):
                raise
            return {}

    _load_index.isaac_tolerant = True
    index_file._load_index = _load_index
