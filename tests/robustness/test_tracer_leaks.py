"""No tracer leaks: a representative subset of the public API run once in a subprocess with
``JAX_CHECK_TRACER_LEAKS=1`` (JAX then raises as soon as a trace ends while one of its tracers
is still referenced).

Each step reports ``ok`` or the leak message; steps run in one process (one start-up) and a
leak in one step does not stop the others. The steps are the public entry points; the bare
physics functions under ``jit`` are not in the list because with jax 0.10.2 / equinox 0.13.8 /
optimistix 0.1.0 the checker also reports tracers held by JAX's own first-trace bookkeeping,
by ``eqx.error_if`` and inside ``optx.root_find`` under ``vmap`` (upstream, see README.md).
"""

import json
import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    r'''
    import json, sys, time, warnings
    import jax, numpy as np
    import blurtrap as bt

    bt.enable_x64()
    if sys.argv[1]:
        bt.enable_compilation_cache(sys.argv[1])
    assert jax.config.jax_check_tracer_leaks, "JAX_CHECK_TRACER_LEAKS was not picked up"
    DT = 1.0 / 1500.0
    GAMMA = 6 * np.pi * 0.00093 * 1.53e-6
    N = 2048

    def sim():
        x = bt.simulate(2e-5, GAMMA, DT, DT, N, key=jax.random.key(0), method="exact_frames",
                        tracking_std=2e-9, n_traces=4)
        return np.asarray(x, dtype=float).reshape(4, N)

    x = sim()
    r = bt.Recording(x[0], frame_interval=DT, exposure=DT)
    steps = {
        "simulate": sim,
        "calibrate (default: exact likelihood)": lambda: bt.calibrate(r),
        "calibrate (likelihood=whittle)": lambda: bt.calibrate(r, likelihood="whittle"),
        "calibrate_batch": lambda: bt.calibrate_batch(x, frame_interval=DT, exposure=DT),
        "diagnose": lambda: bt.diagnose(r),
        "sample_posterior": lambda: bt.sample_posterior(r, n_walkers=8, n_steps=10, seed=0),
    }
    for name, fn in steps.items():
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fn()
            out = {"step": name, "ok": True, "error": ""}
        except Exception as e:  # report and go on with the next step
            msg = str(e)
            where = msg.find("while tracing the function")
            out = {"step": name, "ok": False,
                   "error": f"{type(e).__name__}: {msg[:120]} ... {msg[where:where + 90]}"}
        out["seconds"] = round(time.perf_counter() - t0, 2)
        print("STEP " + json.dumps(out), flush=True)
    '''
)

# step -> known cause (None: must not leak)
STEPS = {
    "simulate": None,
    "calibrate (default: exact likelihood)": None,
    "calibrate (likelihood=whittle)": None,
    "calibrate_batch": None,
    "diagnose": None,
    "sample_posterior": None,
}


def _run_subset(tmp_path):
    script = tmp_path / "run.py"
    script.write_text(SCRIPT)
    env = dict(os.environ, JAX_CHECK_TRACER_LEAKS="1", JAX_TRACEBACK_FILTERING="off")
    cache = os.environ.get("BLURTRAP_TEST_CACHE_DIR",
                           os.path.join(os.path.dirname(__file__), "..", "..", ".pytest_cache", "jax"))
    proc = subprocess.run([sys.executable, str(script), os.path.abspath(cache)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = {}
    for line in proc.stdout.splitlines():
        if line.startswith("STEP "):
            d = json.loads(line[5:])
            results[d["step"]] = d
    assert set(results) == set(STEPS), (sorted(results), proc.stdout[-2000:])
    return results


def test_no_tracer_leaks(tmp_path):
    """One subprocess for all steps (a module fixture would run once per xdist worker).
    Steps not listed with a known cause must pass; known leaks are reported as xfail and
    turn into a failure once they are gone (strict), so that the list gets updated."""
    results = _run_subset(tmp_path)
    unexpected = {s: r["error"] for s, r in results.items() if not r["ok"] and not STEPS[s]}
    assert not unexpected, unexpected
    gone = [s for s, r in results.items() if r["ok"] and STEPS[s]]
    assert not gone, f"known leaks no longer occur in {gone}: remove them from STEPS"
    known = sorted(s for s, r in results.items() if not r["ok"])
    if known:
        pytest.xfail("; ".join(f"{s}: {STEPS[s]}" for s in known))
