"""Many trajectories run in cache-sized tiles (blurtrap.simulate._core.run_chunk): the tiles
must give exactly the numbers of the untiled scan (same counters per trajectory)."""

import jax
import numpy as np
import pytest

from blurtrap.simulate import ExposureWindows, _core, simulate

K, TAU = 5e-5, 0.537e-3
CASES = [
    ("exact", dict(substeps=9, exposure=0.5 * TAU)),
    ("exact_frames", dict(exposure=ExposureWindows([0.2 * TAU, 0.5 * TAU]))),
    ("exact_frames", dict(exposure=0.5 * TAU)),  # the innovations form
]


@pytest.mark.parametrize("method, kw", CASES, ids=["exact", "exact_frames", "innovations"])
def test_tiles_give_the_untiled_numbers(monkeypatch, method, kw):
    tiles = []  # the tile sizes run_chunk was traced with
    tile_size, run_chunk = _core.tile_size, _core.run_chunk

    def recorded_tile_size(cfg, n_traj):
        tiles.append(tile_size(cfg, n_traj))
        return tiles[-1]

    monkeypatch.setattr(_core, "tile_size", recorded_tile_size)

    def run(tile_bytes):
        monkeypatch.setattr(_core, "_TILE_BYTES", tile_bytes)
        # a fresh jit of a fresh run_chunk (jax caches traces per function), as the tile size
        # is read when run_chunk is traced; unlike jax.clear_caches(), this keeps the other
        # tests' compiled programs in this worker
        monkeypatch.setattr(_core, "run_chunk", lambda *args: run_chunk(*args))
        monkeypatch.setattr(_core, "run_chunk_jit", _core._jit_for_cpu())
        tiles.clear()
        x = np.asarray(simulate(K, K * TAU, frame_interval=TAU, n_frames=6,
                                key=jax.random.key(5), n_traces=700, method=method,
                                chunk_frames=4, **kw))
        return x, set(tiles)

    untiled, untiled_tiles = run(1 << 40)
    tiled, tiled_tiles = run(256)  # tiles of 256 trajectories: 3 tiles, the last one padded
    # both runs were traced, one without and one with tiles
    assert untiled_tiles == {None} and tiled_tiles == {256}, (untiled_tiles, tiled_tiles)
    # the scan really ran in tiles (exact: 10 rows per frame, exact_frames: 4, innovations: 1)
    innovations = not isinstance(kw["exposure"], ExposureWindows)
    rows = {"exact": (9, 1, 1), "exact_frames": (0, 1, 1 if innovations else 2)}[method]
    cfg = _core.CoreConfig(method, rows[0], rows[1], rows[2], rows[2], False, None, "float64",
                           None, 1, "float64", innovations)
    assert tile_size(cfg, 700) == 256
    np.testing.assert_array_equal(tiled, untiled)
    assert np.all(np.isfinite(tiled)) and np.std(tiled) > 0
