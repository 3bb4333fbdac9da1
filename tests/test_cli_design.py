"""``blurtrap design`` end to end: lab units in, SI JSON out, the figure written."""

import json

import pytest

from blurtrap.cli import main


def test_design_cli_json_and_plot(tmp_path, capsys):
    png = tmp_path / "design.png"
    code = main(["design", "--k", "0.05", "--radius-um", "1.5", "--max-fps", "1500",
                 "--frames", "16384", "--tracking-nm", "2", "--series", "1", "--json", "--plot", str(png),
                 "--target", "force_sensitivity", "--friction-error", "3"])
    out = capsys.readouterr().out
    assert code == 0
    doc = json.loads(out)
    assert doc["k_N_per_m"] == [pytest.approx(5e-5)]
    best = doc["best"]["recordings"]
    assert all(r["exposure_s"] <= r["frame_interval_s"] * (1 + 1e-9) for r in best)
    assert all(r["frame_interval_s"] >= 1 / 1500 * (1 - 1e-9) for r in best)
    assert doc["settings"]["tracking_std_m"] == pytest.approx(2e-9)
    assert doc["settings"]["friction_error"] == pytest.approx(0.03)  # --friction-error in %
    assert doc["target"] == "force_sensitivity"
    assert doc["best"]["predicted_relative_se"]["force_sensitivity"][0] >= 0.03 / 2
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("argv, match", [
    (["--k", "0.05", "0.1", "0.2"], "range"),
    (["--k", "-1"], "k"),
    (["--k", "0.05", "--target", "force_sensitivity"], "friction"),
])
def test_design_cli_bad_input(capsys, argv, match):
    code = main(["design", *argv, "--radius-um", "1", "--max-fps", "1000", "--frames", "4096"])
    assert code != 0
    assert match in capsys.readouterr().err
