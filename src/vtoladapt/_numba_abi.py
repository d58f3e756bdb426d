"""Every use the package makes of Numba's and llvmlite's private or version-dependent API, in one module.

The compiled parts of a run (control laws, force-model bases, wind parts, sensor channels) are C
kernels: Numba ``cfunc`` objects of their kind's fixed signature (:func:`c_kernel`), called from the
compiled loops through their C entry points (:func:`c_address`), which the loops receive as int64
tables and turn back into first-class functions (:func:`function_loader`). A Numba upgrade that
changes any of this should need edits here only; ``tests/test_parts.py`` tests each function
directly and checks that no other module of the package imports a private Numba or llvmlite name.

The whole suite has passed on Numba 0.68.1 with llvmlite 0.50.0 (LLVM 20), the minor version
``pyproject.toml`` pins; ``make test-numba-latest`` runs it on the newest release. This module's
functions were also checked on Numba 0.61.2 with llvmlite 0.44.0 (LLVM 15), the oldest release whose
first-class functions have the ``jit_addr`` field the loader fills (0.59 and 0.60 do not: there the
loader fails to compile). Each function says what it relies on and what public alternative is missing.

The one private option used elsewhere is ``_nrt=False`` (compile without Numba's reference counting),
passed by every kernel of the simulator's tick; ``tests/test_parts.py`` allows that keyword and no
other private one.
"""
from __future__ import annotations

import inspect
import warnings
from pathlib import Path
from typing import Any, Callable, Optional

import numba
from llvmlite import ir
from llvmlite.binding import llvm_version_info
from numba import cfunc, types
from numba.core import cgutils
from numba.extending import intrinsic

from . import _kernel_cache

NUMBA_CHECKED = ("0.61.2", "0.68.1")
"""The Numba releases this module's functions were checked on (the whole suite: 0.68.1)."""

# Typing a first-class function warns that the feature is experimental. The package uses the
# documented part of it (functions of one fixed signature, called with positional arguments), and
# tests/test_parts.py tests that.
warnings.filterwarnings("ignore", message="First-class function type feature is experimental")


def c_kernel(signature: Any, fn: Callable, **options: Any) -> Any:
    """``fn`` compiled as a C kernel of ``signature``: a Numba ``cfunc``, cached on disk, without
    reference counting (``_nrt=False``: a kernel of the tick allocates nothing), with NumPy's error
    model (a division by zero gives inf or nan, as in C: an exception cannot cross a C entry point).

    ``options`` are passed on to ``numba.cfunc`` after these. Checked on 0.61.2 and 0.68.1. Public
    API apart from ``_nrt``, a private option of Numba's ``jit``; it has no public equivalent per
    function (only the process-wide ``NUMBA_DISABLE_NRT``).
    """
    try:
        source = Path(inspect.getfile(fn))
    except TypeError:
        source = None
    # the package's own kernels are kept by its own guard; looking for a user's cache costs a file-system search
    if source is not None and not _kernel_cache.is_package_file(source):
        # a user's module: its kernels hold the package's offsets, so its cache must match this version
        cache_dir = kernel_cache_dir(fn)
        if cache_dir is not None:
            _kernel_cache.ensure_fresh_module_kernels(source, cache_dir)
    return cfunc(signature, **{"cache": True, "_nrt": False, "error_model": "numpy", **options})(fn)


def kernel_cache_dir(fn: Callable) -> Optional[Path]:
    """The folder where Numba caches the compiled kernels of ``fn``'s source file, or ``None`` if it
    cannot cache them (no source file, no writable place).

    Private API: Numba's cache locators (``numba.core.caching.CacheImpl._locator_classes``, named
    ``_CacheImpl`` before 0.62; each
    ``from_function(py_func, source_path).get_cache_path()``), the same search a cached function
    makes (``NUMBA_CACHE_DIR``, then beside the source, then the user-wide cache). Checked on 0.68.1;
    Numba has no public way to ask where a function will be cached before compiling it.
    """
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")
    try:
        source = inspect.getfile(fn)
    except TypeError:
        return None
    for locator_class in impl._locator_classes:
        try:
            locator = locator_class.from_function(fn, source)
        except Exception:  # a locator that cannot handle this file
            locator = None
        if locator is not None:
            return Path(locator.get_cache_path())
    return None


def signature_of(fn: Any) -> Optional[Any]:
    """The signature ``fn`` has as a first-class function (a ``numba.core.typing.Signature``), or
    ``None`` if it is none (a Python function, an ``njit`` dispatcher, anything else).

    Public API: ``numba.typeof`` of a ``cfunc`` is its ``numba.types.FunctionType``, whose
    ``signature`` is the signature it was compiled for (checked on 0.61.2 and 0.68.1; the package
    read the private ``CFunc._sig`` before: ``CFunc`` has no public attribute for it).
    """
    try:
        ty = numba.typeof(fn)
    except (ValueError, TypeError):
        return None
    return ty.signature if isinstance(ty, types.FunctionType) else None


def is_c_kernel(fn: Any, signature: Any) -> bool:
    """Whether ``fn`` is a first-class function of ``signature`` (same argument and return types):
    what a ``cfunc`` compiled for it is (public API, as :func:`signature_of`)."""
    sig = signature_of(fn)
    return (sig is not None and tuple(sig.args) == tuple(signature.args)
            and sig.return_type == signature.return_type)


def c_address(fn: Any, signature: Any) -> int:
    """The address of the C entry point of ``fn``, a ``cfunc`` compiled for ``signature``;
    ``TypeError`` if it is not one.

    Public API (``CFunc.address``; checked on 0.61.2 and 0.68.1). The address is valid in this
    process while ``fn`` lives.
    """
    if not is_c_kernel(fn, signature) or not isinstance(getattr(fn, "address", None), int):
        raise TypeError(f"{fn!r} is not a numba cfunc of {signature}")
    return fn.address


def function_loader(signature: Any, c_column: int) -> Callable:
    """A compiled ``load(table, j)``: the C entry point in column ``c_column`` of row ``j`` of an
    int64 table (made with :func:`c_address`) as a first-class function of ``signature``
    (``numba.types.FunctionType``), to be called like any function inside compiled code.

    ``table`` is an int64 2-D array; an address not made by :func:`c_address` for ``signature`` is a
    crash (kernels trust their tables as they trust their parameter arrays).

    Private: this builds the value of a ``FunctionType`` in an ``@intrinsic``, so it depends on that
    type's data model (``numba.experimental.function_type.FunctionModel``: a struct ``c_addr``,
    ``py_addr``, ``jit_addr``; a call goes through ``c_addr`` when ``jit_addr`` is null) and on
    ``numba.core.cgutils``. Checked on 0.61.2 and 0.68.1; 0.59 and 0.60 have no ``jit_addr`` (the
    intrinsic fails to compile there). Missing publicly: a first-class function value made
    from an address inside compiled code. Numba's own ways of passing one are a Python object
    unboxed at every call (10-180 us: too slow for the Gymnasium environment's steps) or a constant
    compiled into the caller (not cacheable on disk).
    """
    fnty = types.FunctionType(signature)

    @intrinsic
    def load(typingctx, table, j):
        if not (isinstance(table, types.Array) and table.dtype == types.int64 and table.ndim == 2
                and isinstance(j, types.Integer)):
            return None

        def codegen(context, builder, sig, args):
            aty = sig.args[0]
            ary = context.make_array(aty)(context, builder, args[0])
            row = context.cast(builder, args[1], sig.args[1], types.intp)
            ptr = cgutils.get_item_pointer2(context, builder, ary.data, cgutils.unpack_tuple(builder, ary.shape),
                                            cgutils.unpack_tuple(builder, ary.strides), aty.layout,
                                            [row, context.get_constant(types.intp, c_column)])
            fn = cgutils.create_struct_proxy(fnty)(context, builder)
            fn.c_addr = builder.inttoptr(builder.load(ptr), cgutils.voidptr_t)
            fn.py_addr = cgutils.get_null_value(cgutils.voidptr_t)
            fn.jit_addr = cgutils.get_null_value(cgutils.voidptr_t)  # null: the call goes through c_addr
            return fn._getvalue()

        return fnty(table, j), codegen

    return load


def has_disk_cache(dispatcher: Any) -> bool:
    """Whether Numba's on-disk cache holds an index for the ``njit`` function ``dispatcher`` (a
    load from the cache, not a compilation, is then likely); ``True`` when that cannot be told.

    Private: the index's file name (``<file stem>.<qualified name>-<line>.py<version>.nbi``, in
    ``dispatcher.stats.cache_path``) is Numba's cache format (checked on 0.61.2 and 0.68.1; the
    same name in the sources of 0.60-0.68). Missing
    publicly: asking whether a call would compile before making it (``dispatcher.stats`` counts cache
    hits and misses only after the fact).
    """
    try:
        fn = dispatcher.py_func
        stem = Path(fn.__code__.co_filename).stem
        return any(Path(dispatcher.stats.cache_path).glob(f"{stem}.{fn.__qualname__}-*.nbi"))
    except (AttributeError, OSError):
        return True  # unknown: behave as if cached (compile in this process only)


def _cache_lock(index_path: str, exclusive: bool):
    """An advisory lock (``flock``) on ``<index>.lock`` beside a kernel's cache index, exclusive
    for writing and shared for reading; a no-op where the folder is read-only or the platform has
    no ``fcntl`` (a single process cannot race with itself there)."""
    import contextlib
    import os

    try:
        import fcntl
    except ImportError:  # not POSIX
        return contextlib.nullcontext()

    @contextlib.contextmanager
    def held():
        try:
            fd = os.open(index_path + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:  # read-only cache folder: nobody can write it, nothing to race with
            yield
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
            yield
        finally:
            os.close(fd)  # closing releases the lock

    return held()


def make_disk_cache_process_safe() -> None:
    """Make Numba's on-disk cache safe for several processes compiling the same kernels at once.

    Numba's cache (``numba.core.caching.IndexDataCacheFile``) keeps, per source function, an index
    mapping each compiled signature to a numbered data file. ``save`` reads the index, picks the
    first free number, writes the index, then the data, with no lock between processes: two
    processes compiling *different* signatures of one kernel on a cold cache (the two workers of
    ``make test`` from a fresh clone, the worker processes of a campaign on a local cluster) both
    pick ``.1.nbc``; the last writer's index and data win, so one signature's entry is lost or,
    interleaved the other way, names the other signature's code, which a later load links and
    calls with the wrong types (a crash inside LLVM or in the kernel). Numba reports this as
    numba/numba#4807, open. Here every save and load takes a lock on ``<index>.lock``, and a save
    writes its data file before the index that names it, so a reader never sees an index entry
    whose file is not yet written.

    Private API: ``IndexDataCacheFile`` and its ``_index_path``, ``_load_index``, ``_save_index``,
    ``_save_data``, ``_data_name`` (the same in 0.59-0.68; checked on 0.68.1). Missing publicly: a
    cache that locks. Installed once at import of this module; idempotent.
    """
    import itertools

    from numba.core import caching

    cls = caching.IndexDataCacheFile
    if getattr(cls, "_vtoladapt_process_safe", False):
        return
    numba_load = cls.load

    def save(self, key, data):
        with _cache_lock(self._index_path, exclusive=True):
            overloads = self._load_index()
            data_name = overloads.get(key)
            if data_name is None:
                taken = set(overloads.values())
                data_name = next(n for n in map(self._data_name, itertools.count(1)) if n not in taken)
            self._save_data(data_name, data)
            if overloads.get(key) != data_name:
                overloads[key] = data_name
                self._save_index(overloads)

    def load(self, key):
        with _cache_lock(self._index_path, exclusive=False):
            return numba_load(self, key)

    def flush(self):
        with _cache_lock(self._index_path, exclusive=True):
            self._save_index({})

    cls.save, cls.load, cls.flush = save, load, flush
    cls._vtoladapt_process_safe = True


make_disk_cache_process_safe()


# LLVM names the intrinsic by its pointer type: "p0" since pointers became opaque (LLVM 17 has
# only those), "p0i8" for the typed i8* of the LLVM 14-15 under older Numba releases.
_PREFETCH_INTRINSIC = "llvm.prefetch.p0" if llvm_version_info[0] >= 17 else "llvm.prefetch.p0i8"


@intrinsic
def prefetch(typingctx, array2d, i, j):
    """Ask the CPU to bring ``array2d[i, j]``'s cache line into its caches (LLVM's ``llvm.prefetch``,
    read, locality 2, data: towards L2, not L1); a hint: no fault, no effect on results.

    Version-dependent: the intrinsic's name follows the LLVM under llvmlite (``llvm.prefetch.p0``
    from LLVM 17, ``llvm.prefetch.p0i8`` before), and the code is written with ``llvmlite.ir`` and
    ``numba.core.cgutils``. Checked on 0.61.2 (llvmlite 0.44, LLVM 15: ``p0i8``) and 0.68.1
    (llvmlite 0.50, LLVM 20: ``p0``). Missing publicly: Numba has no
    prefetch (nor any cache hint).
    """
    if not (isinstance(array2d, types.Array) and array2d.ndim == 2 and isinstance(i, types.Integer)
            and isinstance(j, types.Integer)):
        return None
    sig = types.void(array2d, i, j)

    def codegen(context, builder, signature, args):
        aty = signature.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer2(context, builder, ary.data, cgutils.unpack_tuple(builder, ary.shape),
                                        cgutils.unpack_tuple(builder, ary.strides), aty.layout,
                                        [args[1], args[2]])
        i8p = builder.bitcast(ptr, ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p.type, i32, i32, i32]),
                                            _PREFETCH_INTRINSIC)
        # read, locality 2 (towards L2, not L1: the next environment's ~10 kB would evict the
        # current one's from a 32 kB L1), data cache
        builder.call(fn, [i8p, i32(0), i32(2), i32(1)])
        return context.get_dummy_value()

    return sig, codegen


__all__ = ["NUMBA_CHECKED", "c_address", "c_kernel", "function_loader", "has_disk_cache", "is_c_kernel",
           "prefetch", "signature_of"]
