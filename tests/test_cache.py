"""numba's disk cache for cosymp (kernels.cachestamp): what invalidates it, and concurrent writers."""
import json
import multiprocessing
import pathlib
import re
import shutil
import subprocess
import sys

import pytest
from numba.core import caching

from cosymp.kernels import cachestamp

JITTED = re.compile(r"@njit|\bnjit\(|@overload|\boverload\(|@intrinsic|@jit\b|@generated_jit")


def test_the_stamp_covers_every_module_with_compiled_code():
    """A module that defines jitted code and is not stamped would leave stale loops in the cache."""
    stamped = set(cachestamp.compiled_sources())
    jitted = {f for f in cachestamp.PACKAGE.rglob("*.py") if JITTED.search(f.read_text())}
    assert jitted, "no jitted module found: the pattern is out of date"
    unstamped = sorted(str(f.relative_to(cachestamp.PACKAGE)) for f in jitted - stamped)
    assert not unstamped, f"add these to cachestamp.COMPILED: {unstamped}"


PROBE = """
import json
import numpy as np
from cosymp.integrate import Setup
from cosymp.kernels.loops import energies
s = Setup.make("modulated", "midpoint")
out = np.empty((1, 1))
energies(s.P, np.zeros(1), s.start[None].copy(), out)
print(json.dumps({"hits": sum(energies.stats.cache_hits.values()), "misses": sum(energies.stats.cache_misses.values())}))
"""


@pytest.mark.slow
def test_editing_the_command_line_keeps_the_cache_and_editing_a_scene_invalidates_it(tmp_path):
    """A copy of the package with its own cache: one kernel compiled, then loaded again after
    edits to sources the kernels are not built from, and compiled again after a scene changed."""
    root = tmp_path / "src"
    shutil.copytree(cachestamp.PACKAGE, root / "cosymp", ignore=shutil.ignore_patterns("__pycache__"))
    env = {"PYTHONPATH": str(root), "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin"}

    def probe():
        r = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=tmp_path, capture_output=True, text=True,
                           timeout=300, check=True)
        return json.loads(r.stdout.strip().splitlines()[-1])

    def append(relative, text):
        path = root / "cosymp" / relative
        path.write_text(path.read_text() + text)

    assert probe() == {"hits": 0, "misses": 1}
    for name in ("cli.py", "report/__init__.py", "workprecision.py", "warm.py"):
        append(name, "\n# an edit that changes no compiled code\n")
    assert probe() == {"hits": 1, "misses": 0}
    append("scenes/modulated.py", "\n# an edit to a scene\n")
    assert probe() == {"hits": 0, "misses": 1}


def _writer(path, worker, count):
    """Save `count` entries with keys of this worker into one cosymp index (a child process)."""
    cachestamp.install()
    cachestamp._OWN_PATHS.add(path)
    index = caching.IndexDataCacheFile(cache_path=path, filename_base="probe", source_stamp="stamp")
    for i in range(count):
        index.save((worker, i), {"worker": worker, "i": i})


def test_concurrent_processes_keep_every_entry_of_a_shared_index(tmp_path):
    """Four processes add 25 entries each to one function's index at once (as `cosymp compile`'s
    workers add specializations of one loop): every entry is there and loads its own data."""
    path = str(tmp_path)
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(path, w, 25)) for w in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    cachestamp._OWN_PATHS.add(path)
    index = caching.IndexDataCacheFile(cache_path=path, filename_base="probe", source_stamp="stamp")
    keys = [(w, i) for w in range(4) for i in range(25)]
    assert sorted(index._load_index()) == keys
    assert all(index.load(k) == {"worker": k[0], "i": k[1]} for k in keys)
    assert len(list(pathlib.Path(path).glob("probe.*.nbc"))) == len(keys)
