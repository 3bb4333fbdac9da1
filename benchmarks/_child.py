"""Run one timed call of blurtrap in a fresh child process (its own compilation and peak
memory), against the code at ``code_root`` (this checkout or an old one from
``git worktree``): the shared harness of bench_diagnose.py and bench_folded.py.

The child loads recordings from an ``.npz`` (``x`` (R, N), ``dt`` (R,), ``w`` (R,)), runs
``call`` (Python source of one statement that sets ``res`` from ``recs``, plus ``record``:
the source of an expression of ``res`` giving the JSON-able fields kept per call) ``calls``
times and prints one ``RESULT {json}`` line: the resident memory after loading the data,
and per call its wall time, peak resident memory and the recorded fields.
"""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import time

_TEMPLATE = r"""
import json, resource, sys, time
import numpy as np
import blurtrap as bt
bt.enable_x64()
d = np.load(sys.argv[1])
recs = [bt.Recording(x, frame_interval=float(dt), exposure=float(w))
        for x, dt, w in zip(d["x"], d["dt"], d["w"])]
rss = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # GiB
out = {"rss_data_gib": rss(), "calls": []}
for _ in range(int(sys.argv[2])):
    t0 = time.perf_counter()
    %(call)s
    out["calls"].append(dict({"s": time.perf_counter() - t0, "rss_gib": rss()}, **(%(record)s)))
print("RESULT " + json.dumps(out))
"""


#: the head of a child that counts XLA compilations (``count = [number, seconds]``,
#: ``jax.monitoring``) and reads ``n0, n1`` from its JSON argument (bench_held.py,
#: bench_diagnose_buckets.py)
COUNTED_HEAD = r"""
import json, sys, time
import numpy as np, jax
import blurtrap as bt
bt.enable_x64()
n0, n1 = json.loads(sys.argv[1])
count = [0, 0.0]
def _listen(event, duration, **kw):
    if event == "/jax/core/compile/backend_compile_duration":
        count[0] += 1
        count[1] += duration
jax.monitoring.register_event_duration_secs_listener(_listen)
"""


def child_script(call: str, record: str) -> str:
    """The child's source for one statement `call` (setting ``res``) and the dict
    expression `record` of the fields kept per call."""
    return _TEMPLATE % {"call": call, "record": record}


def run_source(code_root: pathlib.Path, script: str, args=(), timeout: float | None = None):
    """Run the Python source `script` with ``args`` in a fresh process against the package
    at ``code_root`` (``PYTHONPATH``, cwd; no persistent compilation cache): the JSON of its
    ``RESULT ...`` line, or ``{"error": ...}`` (a timeout or the end of stderr)."""
    env = dict(os.environ, PYTHONPATH=str(code_root), JAX_ENABLE_X64="1")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    try:
        proc = subprocess.run([sys.executable, "-c", script, *map(str, args)], env=env,
                              capture_output=True, text=True, timeout=timeout, cwd=code_root)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:.0f} s"}
    line = [s for s in proc.stdout.splitlines() if s.startswith("RESULT ")]
    if not line:
        return {"error": proc.stderr[-2000:]}
    return json.loads(line[0][7:])


def run_child(code_root: pathlib.Path, data: pathlib.Path, calls: int, timeout: float,
              script: str) -> dict:
    """Run `script` (from :func:`child_script`) on `data` (:func:`run_source`); the parsed
    RESULT plus ``process_s`` (the whole child), or ``{"error": ...}``."""
    t0 = time.perf_counter()
    out = run_source(code_root, script, (data, calls), timeout)
    if "error" not in out:
        out["process_s"] = time.perf_counter() - t0
    return out
