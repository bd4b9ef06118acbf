"""The numba cache survives a new process: no kernel recompiles on the second start."""
import json
import subprocess
import sys

import pytest

SCRIPT = """
import json, time
t0 = time.perf_counter()
from cosymp import Setup, simulate
from cosymp.kernels.loops import propagate_matrix, propagate_one
t1 = time.perf_counter()
simulate(Setup.make("damped", "midpoint"), 0.1, 50.0)
simulate(Setup.make("kapitza", "midpoint"), 0.01, 1.0)
t2 = time.perf_counter()
stats = [propagate_matrix.stats, propagate_one.stats]
print(json.dumps({"import_s": t1 - t0, "first_run_s": t2 - t1,
                  "hits": sum(sum(s.cache_hits.values()) for s in stats),
                  "misses": sum(sum(s.cache_misses.values()) for s in stats)}))
"""


def fresh_process():
    r = subprocess.run([sys.executable, "-c", SCRIPT], check=True, capture_output=True, text=True,
                       timeout=600)
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_second_process_loads_every_kernel_from_the_cache():
    fresh_process()
    warm = fresh_process()
    assert warm["misses"] == 0 and warm["hits"] == 2, warm
