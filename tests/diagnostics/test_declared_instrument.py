"""diagnose on a correctly declared photodiode with anti-aliasing (a fifth independent pass):
every candidate gained ~2e4 in log-likelihood and the model was called NOT adequate on data
it describes (the screening fits ran over every ordinate, the base fit below 0.4 fs); with a
stage drive in volts the declared drive stayed in the base fit (ranked as line noise) and the
candidates' k, in volts, was compared with the base fit's in SI ("adding detector_filter
moves k by -12 SE"); ``blurtrap diagnose`` fitted a camera model by default, whatever the
manifest declared. Data: tests/_instrument_gen.py (exact OU paths, a Kaiser FIR and
decimation in numpy; not blurtrap's simulator).
"""

import json
import math

import pytest
from _instrument_gen import generate

import blurtrap as bt

K, DT = 1e-4, 1e-5
GAMMA = 6 * math.pi * 0.00093 * 0.5e-6
RD = 1e-7  # m per V
META = {"detector": "photodiode", "anti_aliasing": True, "hydrodynamics": False,
        "temperature_K": 296.15}


def _rec(seed, drive=False, volts=False):
    dr = {"amplitude_m": 150e-9, "frequency_Hz": 32.0, "phase": 0.3} if drive else None
    x, stage = generate(K, GAMMA, DT, None, 2**16, seed, anti_aliasing=True, drive=dr,
                        volts_per_m=1 / RD if volts else None, tracking_std=1e-10)
    meta = dict(META, **({"drive": {"frequency_Hz": 32.0}} if drive else {}))
    return bt.Recording(x[0], frame_interval=DT, exposure=DT, temperature=296.15,
                        position_unit="V" if volts else "m",
                        stage=stage, metadata=meta)


@pytest.mark.parametrize("drive, volts", [(False, False), (True, True)],
                         ids=["metres", "volts with a stage drive"])
def test_a_correctly_declared_photodiode_is_adequate(drive, volts):
    for seed in (1, 2):
        rec = _rec(seed, drive, volts)
        d = bt.diagnose(rec)
        c = bt.calibrate(rec)
        assert d.model == "photodiode_aa" and d.adequate, (d.summary(), seed)
        # none gains beyond chance; folding (aliasing) loses: the data reject it
        assert all(x.delta_loglik < 30 for x in d.ranking if x.delta_loglik is not None)
        assert not [n for n in d.notes if "moves" in n or "declared detector" in n], d.notes
        assert d.fit.k == pytest.approx(c.k, rel=1e-6)


def test_the_cli_diagnoses_the_declared_detector(tmp_path, capsys):
    from blurtrap.cli import main

    path = tmp_path / "m.json"
    bt.save_manifest(_rec(3), path)
    assert main(["diagnose", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "photodiode_aa" and out["adequate"], out["notes"]
