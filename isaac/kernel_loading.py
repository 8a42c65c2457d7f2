"""Load numba's cached kernels without first loading numba's compiler.

Before numba loads a kernel from its on-disk cache it "refreshes" its CPU target: it imports
and registers the lowering code of every Python and NumPy feature it can compile (about 70
modules: unicode strings, linalg, random generators, typed dicts, lists and sets, jitclasses,
datetimes...) and installs their registries. Loading needs none of it: the cached object code is
linked against numba's runtime (NRT) and helper library only, and the environments it
references import their own modules. Compiling does need it, and numba's compiler refreshes the
target itself before every compile (`numba.core.compiler.CompilerBase`), so a cache miss after
lazy loads compiles as before.

A cached load also parses the LLVM bitcode numba keeps beside each kernel's object code (the
kernel's IR, for compiling other code against it: inlining, linking) only to list the symbols
the object defines. Here the list is read from the object's own ELF symbol table (the same
names, checked for every engine kernel), and the bitcode is parsed when something asks for it
(``_shared_module``: a kernel compiled later that calls this one, or numba saving it again).

What each of the two saves on a cached start-up is measured in docs/speed.md ("The first run").
The kernels and their bits are numba's own: only the moment of the refresh and of the parse
moves (tests/test_kernel_loading.py).

Both replace numba internals (`numba.core.caching.Cache.load_overload` by the same without the
refresh, keeping the runtime's initialisation; ``CPUCodeLibrary._unserialize``), so `install()`
puts them in place only on the numba versions in `TESTED_NUMBA` (pyproject.toml caps numba
below the next minor version); on any other, or with ``ISAAC_EAGER_KERNEL_LOADING=1``, numba loads
its own way and `LOADING` says why. Imported by `isaac.engine.kernel_cache`, before any kernel
of the engine or the recorder is loaded.

`tolerate_stale_indexes` (installed by `isaac.engine.kernel_cache` for the caches it keys, with
or without the above) makes a cache index an older engine wrote, naming types this one lacks,
a miss instead of an AttributeError at every run.
"""

from __future__ import annotations

import os
import struct

EAGER_ENV = "ISAAC_EAGER_KERNEL_LOADING"

TESTED_NUMBA = ("0.68.1",)
"""The numba versions (``numba.__version__``) whose internals `install()` was tested against:
on any other numba loads its own way."""

LOADING = "numba's own"
"""How this process loads cached kernels: "lazy" (`install()` in place) or "numba's own" with
the reason."""


def install() -> bool:
    """Make cached loads skip numba's target refresh and the bitcode parse (once a process), on a
    tested numba only (`TESTED_NUMBA`); returns whether they are in place (`LOADING` says why
    not)."""
    global LOADING
    import numba
    from numba.core import caching

    current = caching.Cache.load_overload
    if getattr(current, "isaac_lazy", False):
        return True
    if os.environ.get(EAGER_ENV) == "1":
        LOADING = f"numba's own ({EAGER_ENV}=1)"
        return False
    if numba.__version__ not in TESTED_NUMBA:
        LOADING = f"numba's own (numba {numba.__version__} is not one of {TESTED_NUMBA})"
        return False
    from numba.core import codegen
    from numba.core.runtime import rtsys

    def load_overload(self, sig, target_context):
        # numba's, without its target_context.refresh() (see the module docstring); what the
        # cached code is linked against is the runtime (allocation, reference counts)
        rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)
        # None returned if the `with` block swallows an exception (as numba's own)

    load_overload.isaac_lazy = True
    load_overload.__doc__ = current.__doc__
    caching.Cache.load_overload = load_overload
    codegen.CPUCodeLibrary._unserialize = classmethod(
        _lazy_unserialize(codegen.CPUCodeLibrary._unserialize.__func__)
    )
    LOADING = "lazy"
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


def _lazy_unserialize(unserialize):
    """numba's ``CPUCodeLibrary._unserialize`` (`unserialize`) with the bitcode kept as bytes."""

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

    return _unserialize


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
