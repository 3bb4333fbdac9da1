"""Cost per frame of `simulate(method="exact_frames")` against the size of the output.

Not a test. Run:  python benchmarks/bench_alloc.py
and again with ``MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=4294967296`` in the
environment. Outputs of 32 MiB or more come from fresh mmap'ed memory on every call unless
glibc's allocator is told to keep it (see RESULTS_simulate.md, session 5).
"""

from __future__ import annotations

import os
import time

import jax

from blurtrap import enable_x64, simulate

K, TAU = 5e-5, 0.537e-3
SIZES = ((1024, 3900), (1024, 4000), (1024, 4096), (1024, 8000), (256, 16000), (256, 16384))


def main():
    enable_x64()
    env = {k: v for k, v in os.environ.items() if k.startswith("MALLOC_")}
    print(f"# jax {jax.__version__}, load {os.getloadavg()[0]:.2f}, malloc env {env or 'none'}")
    for n_traces, n_frames in SIZES:
        def run(n_traces=n_traces, n_frames=n_frames):
            return simulate(K, K * TAU, 0.5 * TAU, TAU, n_frames, key=jax.random.key(0),
                            n_traces=n_traces, method="exact_frames").block_until_ready()

        run()
        best = float("inf")
        for _ in range(5):
            t0 = time.perf_counter()
            run()
            best = min(best, time.perf_counter() - t0)
        mib = n_traces * n_frames * 8 / 2**20
        print(f"N = {n_traces:5d}, {n_frames:6d} frames, output {mib:5.1f} MiB: "
              f"{best / (n_traces * n_frames) * 1e9:5.2f} ns per frame")


if __name__ == "__main__":
    main()
