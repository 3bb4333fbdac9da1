import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import blurtrap  # noqa: E402
from blurtrap._config import faster_compilation  # noqa: E402

# the tests are compile-bound: XLA:CPU's classic emitters make the first call of blurtrap's
# programs 1.2-1.7x faster (same results to rounding). Set here, before the first
# computation, it reaches the xdist workers, the CLI and notebook subprocesses too; a user's
# $XLA_FLAGS that names the flag wins, and BLURTRAP_DEFAULT_XLA=1 keeps XLA's defaults
# (here and in the CLI).
faster_compilation()
blurtrap.enable_x64()
# share compiled programs between the xdist workers (and between runs on one machine)
_CACHE = os.path.abspath(blurtrap.enable_compilation_cache(
    os.environ.get("BLURTRAP_TEST_CACHE_DIR",
                   os.path.join(os.path.dirname(__file__), "..", ".pytest_cache", "jax"))
))
# ... and with the processes the tests start: `blurtrap.cli.main` (in-process, it calls
# enable_compilation_cache() with $BLURTRAP_CACHE_DIR), the notebook kernels (jax reads
# JAX_COMPILATION_CACHE_DIR at import) and the subprocess tests (BLURTRAP_TEST_CACHE_DIR)
os.environ["BLURTRAP_TEST_CACHE_DIR"] = _CACHE
os.environ["BLURTRAP_CACHE_DIR"] = _CACHE
os.environ["JAX_COMPILATION_CACHE_DIR"] = _CACHE
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = str(
    jax.config.jax_persistent_cache_min_compile_time_secs)


def _memory_maps() -> int:
    try:
        with open("/proc/self/maps", "rb") as fh:
            return sum(1 for _ in fh)
    except OSError:  # not Linux: no per-process map limit to watch
        return 0


#: XLA:CPU keeps every compiled program's machine code in its own memory mappings (~6 per
#: program). A test worker that compiles thousands of distinct programs reaches the kernel's
#: per-process limit (vm.max_map_count, 65 530 by default) and the next compilation dies with
#: a segmentation fault inside XLA. Past this many mappings the in-memory compilation caches
#: are dropped after a test module (programs then come back from the persistent cache).
MAX_MAPS = 20_000


@pytest.fixture(autouse=True, scope="module")
def _bounded_compiled_programs():
    yield
    if _memory_maps() > MAX_MAPS:
        import gc

        jax.clear_caches()
        gc.collect()


@pytest.fixture
def rng():
    """A numpy Generator with a fixed, recorded seed (never global RNG state)."""
    return np.random.default_rng(20061225)


@pytest.fixture
def getkey():
    """Fresh JAX keys from a fixed seed: `k = getkey()`."""
    key = jax.random.key(1234)
    state = {"key": key}

    def _next():
        state["key"], sub = jax.random.split(state["key"])
        return sub

    return _next


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import sys

    if "matplotlib.pyplot" in sys.modules:
        import matplotlib.pyplot as plt

        plt.close("all")
