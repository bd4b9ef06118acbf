"""numba's disk cache for cosymp: one stamp for the compiled sources, and safe concurrent writers.

Stamp. Numba stamps a cached function with its own file only, but our generic loops (loops.py)
inline code from scene, family and expression modules: editing a scene must not leave a stale
compiled loop behind. This locator wraps numba's usual choice for files of this package and
replaces the stamp with a hash of every source the compiled code is built from (COMPILED), and
of nothing else: editing the command line, the reports or the studies keeps the cache.

Writers. numba saves a new entry by reading the function's index, adding the entry and writing
the index back, then writing the entry's data file. Two processes compiling different
specializations of one function at once (`cosymp compile` runs one per core) would lose one of
the entries, or give both the same data file; and a process reading the index between the two
writes could load a stale data file of that name. For cosymp's caches the save is therefore
done under an exclusive lock on the index, data first and index last.
"""
import contextlib
import functools
import hashlib
import itertools
import pathlib

from numba.core import caching

_CacheImpl = getattr(caching, "CacheImpl", None) or caching._CacheImpl

PACKAGE = pathlib.Path(__file__).resolve().parent.parent
COMPILED = ("kernels", "scenes", "expr.py")
"""What jitted code is built from, relative to the package: every module that defines an
@njit function, an @overload or an @intrinsic (tests/test_cache.py checks the list)."""


def compiled_sources():
    """The package's source files that COMPILED names, in a fixed order."""
    files = []
    for name in COMPILED:
        path = PACKAGE / name
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return files


@functools.cache
def package_stamp():
    """SHA-256 of the compiled sources (contents, not times: a checkout or a copy that leaves them
    unchanged keeps the cache)."""
    digest = hashlib.sha256()
    for f in compiled_sources():
        digest.update(str(f.relative_to(PACKAGE)).encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()


_OWN_PATHS = set()


class PackageStampLocator:
    """numba's cache locator for a cosymp file, with the package-wide stamp."""

    def __init__(self, inner):
        self._inner = inner
        _OWN_PATHS.add(inner.get_cache_path())

    def ensure_cache_path(self):
        self._inner.ensure_cache_path()

    def get_cache_path(self):
        return self._inner.get_cache_path()

    def get_source_stamp(self):
        return package_stamp()

    def get_disambiguator(self):
        return self._inner.get_disambiguator()

    @classmethod
    def from_function(cls, py_func, py_file):
        if not pathlib.Path(py_file).resolve().is_relative_to(PACKAGE):
            return None
        for base in _CacheImpl._locator_classes:
            if base is not cls:
                inner = base.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner)
        return None


def cache_dir():
    """The folder where numba keeps the cache of the kernels (created if need be)."""
    locator = PackageStampLocator.from_function(cache_dir, __file__)
    locator.ensure_cache_path()
    return locator.get_cache_path()


@contextlib.contextmanager
def _locked(path):
    """An exclusive lock on path + '.lock' across processes (no lock where fcntl is missing)."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(path + ".lock", "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


_numba_save = caching.IndexDataCacheFile.save


def _save(self, key, data):
    """IndexDataCacheFile.save for cosymp's caches: under the index's lock, data before index."""
    if self._cache_path not in _OWN_PATHS:
        return _numba_save(self, key, data)
    with _locked(self._index_path):
        overloads = self._load_index()
        name = overloads.get(key)
        if name is None:
            taken = set(overloads.values())
            name = next(n for n in map(self._data_name, itertools.count(1)) if n not in taken)
        self._save_data(name, data)
        if overloads.get(key) != name:
            overloads[key] = name
            self._save_index(overloads)


def install():
    """Put the locator first in numba's list and make cosymp's saves safe (idempotent)."""
    if PackageStampLocator not in _CacheImpl._locator_classes:
        _CacheImpl._locator_classes.insert(0, PackageStampLocator)
    caching.IndexDataCacheFile.save = _save
