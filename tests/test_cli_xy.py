"""`blurtrap calibrate` on x/y recordings (in-process through `blurtrap.cli.main`): the
principal axes, k per axis and one shared gamma of a simulated anisotropic, rotated trap."""

import json
import math
import re

import jax
import numpy as np
import pytest

import blurtrap as bt
from blurtrap.cli import main
from blurtrap.data import save_manifest, write_xy_csv

# README's example (2000 fps camera, W = 0.4 ms, k2/k1 = 2.5, 3 nm tracking noise). Over
# seeds 0-11 of this simulation the z-scores (estimate - truth) / SE of k1, k2, gamma, phi had
# mean -0.17, -0.34, -0.27, 0.08 and SD 0.74, 0.97, 1.00, 1.05; seed 0 is the first of them.
K1, K2, GAMMA, W, DT, N, PHI, EPS = 2e-5, 5e-5, 1e-8, 4e-4, 5e-4, 4096, 0.5, 3e-9
SEED = 0


@pytest.fixture(scope="module")
def xy():
    out = np.asarray(bt.simulate_xy(K1, K2, GAMMA, W, DT, N, key=jax.random.key(SEED), angle=PHI,
                                    tracking_std=EPS))
    return bt.xy_from_arrays(out[0, :, 0], out[0, :, 1], frame_interval=DT, exposure=W,
                             name="bead")


@pytest.fixture(scope="module")
def manifest(xy, tmp_path_factory):
    path = tmp_path_factory.mktemp("xy") / "manifest.json"
    save_manifest(xy, path)
    return path


@pytest.fixture(scope="module")
def json_result(manifest):
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["calibrate", str(manifest), "--json"])
    assert rc == 0
    return json.loads(buf.getvalue())


def test_json_recovers_the_truth(json_result):
    out = json_result
    assert out["name"] == "bead"
    for key, truth in (("k1", K1), ("k2", K2), ("gamma", GAMMA)):
        assert abs(out[key] - truth) < 4 * out[f"{key}_err"], (key, out[key], out[f"{key}_err"])
    assert out["resolved"]
    # the axis of the soft trap (k1) at PHI (an axis: modulo pi)
    d = (out["phi"] - PHI + math.pi / 2) % math.pi - math.pi / 2
    assert abs(d) < 4 * out["phi_err"], (out["phi"], out["phi_err"])


def test_json_matches_calibrate_xy(json_result, manifest):
    """The command runs calibrate_xy on what bt.load reads (same numbers)."""
    (loaded,) = bt.load(manifest)
    ref = bt.calibrate_xy(loaded)
    for key in ("k1", "k2", "phi", "gamma", "k_x", "k_y", "k_xy"):
        assert json_result[key] == pytest.approx(getattr(ref, key), rel=1e-9)


def test_text_names_the_principal_axes(manifest, capsys):
    assert main(["calibrate", str(manifest)]) == 0
    out = capsys.readouterr().out
    assert "x/y calibration" in out
    for label in ("k1 (soft axis)", "k2", "phi (axis 1 from x)", "gamma (shared)", "k_xy"):
        assert label in out
    assert "pN/nm" in out and "deg" in out


@pytest.mark.parametrize("flag", [["--report", "REPORT"], ["--posterior"],
                                  ["--k-mode", "shared"]])
def test_refused_options_are_named(manifest, flag, capsys, tmp_path):
    flag = [str(tmp_path / "r") if f == "REPORT" else f for f in flag]
    assert main(["calibrate", str(manifest), *flag]) != 0
    err = capsys.readouterr().err
    assert re.search(rf"{flag[0]} (is not available|cannot be used) (for|with) x/y recordings",
                     err), err
    assert not (tmp_path / "r").exists()


def test_bare_xy_csv_is_refused_with_the_reason(xy, tmp_path, capsys):
    write_xy_csv(xy, tmp_path / "xy.csv")
    assert main(["calibrate", str(tmp_path / "xy.csv")]) != 0
    assert "does not say its frame interval, exposure" in capsys.readouterr().err


def test_diagnose_refuses_xy_with_the_reason(manifest, capsys):
    assert main(["diagnose", str(manifest)]) != 0
    assert "diagnose does not take x/y recordings yet" in capsys.readouterr().err


def test_several_entries_each_get_a_table(xy, tmp_path, capsys):
    two = [bt.xy_from_arrays(xy.x.positions, xy.y.positions, frame_interval=DT, exposure=W,
                             name=n) for n in ("left", "right")]
    save_manifest(two, tmp_path / "two.json")
    assert main(["calibrate", str(tmp_path / "two.json")]) == 0
    out = capsys.readouterr().out
    assert out.count("x/y calibration") == 2
    assert out.index("left:") < out.index("right:")
