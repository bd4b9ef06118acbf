"""Invalidate every cached cosymp kernel when any cosymp source file changes.

Numba stamps a cached function with its own file only, but our generic loops (loops.py) inline
code from scene and family modules: editing a scene must not leave a stale compiled loop
behind. This locator wraps numba's usual choice for files of this package and replaces the
stamp with a hash of all of the package's sources.
"""
import functools
import hashlib
import pathlib

from numba.core import caching

_CacheImpl = getattr(caching, "CacheImpl", None) or caching._CacheImpl

PACKAGE = pathlib.Path(__file__).resolve().parent.parent


@functools.cache
def package_stamp():
    """SHA-256 of every source file of the package (contents, not times: a checkout or a copy
    that leaves the sources unchanged keeps the cache)."""
    digest = hashlib.sha256()
    for f in sorted(PACKAGE.rglob("*.py")):
        digest.update(str(f.relative_to(PACKAGE)).encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()


class PackageStampLocator:
    """numba's cache locator for a cosymp file, with the package-wide stamp."""

    def __init__(self, inner):
        self._inner = inner

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


def install():
    """Put the locator first in numba's list (idempotent)."""
    if PackageStampLocator not in _CacheImpl._locator_classes:
        _CacheImpl._locator_classes.insert(0, PackageStampLocator)
