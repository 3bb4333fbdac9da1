"""From ``naive``, would the camera's whole core (motion_blur + aliasing + tracking_noise,
i.e. the ``standard`` model) be found where the coupled group motion_blur+aliasing is not?

For each ``naive_camera`` record (eps = 2 nm, 16 384 frames; seeds as in the study:
4850..4859 with ``--seed-offset 50``) it fits ``naive`` and ``standard`` with the Whittle
likelihood diagnose screens with (``lines="keep"``), and prints the likelihood-ratio p-value
(chi2_1 / 2, as diagnose refers a one-parameter candidate) and the standard fit's pulls.

Run:  python benchmarks/_diag19_standard_group.py [FIRST_SEED] [N]   (default 4850 10)
"""

from __future__ import annotations

import sys

import _diag19_refits as rf

import blurtrap as bt
from blurtrap.inference.internal import chi2_sf


def main(first=4850, n=10):
    bt.enable_x64()
    bt.enable_compilation_cache()
    for seed in range(first, first + n):
        rec = rf.naive_camera(seed)
        fits = [bt.calibrate(rec, method="likelihood", likelihood="whittle", model=m,
                             strict=False, lines="keep") for m in ("naive", "standard")]
        lr = 2 * (fits[0].extras["nll"] - fits[1].extras["nll"])
        p = 0.5 * float(chi2_sf(max(lr, 0.0), 1))
        pull = rf.fit_pulls(fits[1], rf.K_CAM, rf.GAMMA_CAM)
        print(f"seed {seed}: 2 dlogL = {lr:.2f}, p = {p:.3g}, standard gof p = "
              f"{fits[1].gof['p_value']:.3g}, k pull {pull['k_pull']:+.2f}, gamma pull "
              f"{pull['gamma_pull']:+.2f}", flush=True)


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
