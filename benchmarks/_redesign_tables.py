"""Tables of ``compare_redesign.py``: old vs new side by side with Monte-Carlo errors.

"Within MC error" means |new - old| <= 2 x the Monte-Carlo standard error of the statistic
(that of one study of this size; the two trees fit the *same* data, so this is conservative:
the paired columns show how far the individual estimates actually moved).
"""

from __future__ import annotations

import math
import pickle
import statistics

import numpy as np

GAMMA = 6 * math.pi * 0.00093 * 1.53e-6
EPS2 = 4e-18
K_CAL = (1e-5, 5e-5)
PARAMS = (("k", 0), ("gamma", 2), ("eps^2", 4))


def _maxdiff(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = np.std(a) if a.size > 1 else 1.0
    return {"n_values": int(a.size), "bitwise_equal": bool(np.array_equal(a, b)),
            "max_abs_diff_over_sd": float(np.max(np.abs(a - b)) / scale)}


def parity(d_old, d_new):
    """The new tree's draws against the old tree's (same keys)."""
    out = {}
    for name in ("calib.npy", "post_y.npy"):
        if (d_old / name).exists():
            out[name] = _maxdiff(np.load(d_old / name), np.load(d_new / name))
    if (d_old / "diag_data.pkl").exists():
        a = pickle.loads((d_old / "diag_data.pkl").read_bytes())
        b = pickle.loads((d_new / "diag_data.pkl").read_bytes())
        per = {}
        for ia, ib in zip(a, b):
            xa = np.concatenate([r["x"] for r in ia["recs"]])
            xb = np.concatenate([r["x"] for r in ib["recs"]])
            m = _maxdiff(xa, xb)
            cur = per.setdefault(ia["scenario"], {"records": 0, "bitwise_equal": 0,
                                                  "max_abs_diff_over_sd": 0.0})
            cur["records"] += 1
            cur["bitwise_equal"] += int(m["bitwise_equal"])
            cur["max_abs_diff_over_sd"] = max(cur["max_abs_diff_over_sd"],
                                              m["max_abs_diff_over_sd"])
        out["diagnose"] = per
    return out


def _stats(v, e, t):
    ok = np.isfinite(v) & np.isfinite(e)
    v, e = v[ok], e[ok]
    n = v.size
    sd = v.std(ddof=1)
    rel = 1.0 / math.sqrt(2 * (n - 1))
    cov = float(np.mean(np.abs(v - t) <= 1.959964 * e))
    return {"n": n, "bias": 100 * (v.mean() - t) / t, "bias_mc": 100 * sd / math.sqrt(n) / t,
            "sd": 100 * sd / t, "sd_mc": 100 * sd / t * rel, "se_sd": e.mean() / sd,
            "se_sd_mc": e.mean() / sd * rel, "cov": cov,
            "cov_mc": math.sqrt(0.95 * 0.05 / n)}


def _within(o, n, keys=("bias", "sd", "se_sd", "cov")):
    return all(abs(n[k] - o[k]) <= 2 * o[k + "_mc"] for k in keys)


def calib_table(res):
    lines = ["\n## (a) Default calibrate: bias, SD, SE/SD, 95 % Wald coverage (old / new)\n",
             "bias and SD in % of the truth; (MC SE) of the old value; 'paired' = largest "
             "|new - old| / old SE over the records; 'within' = every new statistic within "
             "2 MC SE of the old one.\n",
             "| k [pN/nm] | fit | param | n (fails) old / new | bias [%] | SD [%] | SE/SD | "
             "95 % coverage | paired max |diff|/SE | within |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for j, k in enumerate(K_CAL):
        for fit in ("single", "batch"):
            o = np.asarray(res["old"][fit][j], float)
            n = np.asarray(res["new"][fit][j], float)
            for pname, c in PARAMS:
                t = {0: k, 2: GAMMA, 4: EPS2}[c]
                so, sn = _stats(o[:, c], o[:, c + 1], t), _stats(n[:, c], n[:, c + 1], t)
                fo, fn = int(np.isnan(o[:, c]).sum()), int(np.isnan(n[:, c]).sum())
                both = np.isfinite(o[:, c]) & np.isfinite(n[:, c]) & (o[:, c + 1] > 0)
                pd = (float(np.max(np.abs(n[both, c] - o[both, c]) / o[both, c + 1]))
                      if both.any() else float("nan"))
                label = "calibrate" if fit == "single" else "calibrate_batch"
                lines.append(
                    f"| {k * 1e3:g} | {label} | {pname} | {so['n']} ({fo}) / {sn['n']} ({fn}) "
                    f"| {so['bias']:+.3f} / {sn['bias']:+.3f} ({so['bias_mc']:.3f}) "
                    f"| {so['sd']:.3f} / {sn['sd']:.3f} ({so['sd_mc']:.3f}) "
                    f"| {so['se_sd']:.3f} / {sn['se_sd']:.3f} ({so['se_sd_mc']:.3f}) "
                    f"| {so['cov']:.3f} / {sn['cov']:.3f} ({so['cov_mc']:.3f}) "
                    f"| {pd:.2e} | {'yes' if _within(so, sn) else 'NO'} |")
    return "\n".join(lines)


def _post_cov(rows, name, lev):
    lo, hi = {"68": (1, 3), "95": (0, 4)}[lev]
    return [int(r[name]["q"][lo] <= r[name]["truth"] <= r[name]["q"][hi]) for r in rows]


def posterior_table(res):
    o, n = res["old"], res["new"]
    nd = len(o)
    lines = [f"\n## (b) Posterior: central credible-interval coverage, {nd} datasets "
             "(old / new)\n",
             "(binomial SE at the nominal level); 'paired': |median new - median old| in units "
             "of the old posterior half-width (q84 - q16) / 2, median and max over datasets; "
             "'flips' = datasets whose interval covers the truth in one tree only.\n",
             "| param | 68 % coverage | 95 % coverage | paired |diff| median / max | flips "
             "68 / 95 | within |", "|---|---|---|---|---|---|"]
    names = (("k", "k"), ("gamma", "gamma"), ("tracking_var", "eps^2"))
    for key, label in names:
        cells, flips, ok = [], [], True
        for lev, q in (("68", 0.68), ("95", 0.95)):
            co, cn = _post_cov(o, key, lev), _post_cov(n, key, lev)
            se = math.sqrt(q * (1 - q) / nd)
            ro, rn = sum(co) / nd, sum(cn) / nd
            ok &= abs(rn - ro) <= 2 * se
            cells.append(f"{ro:.3f} / {rn:.3f} ({se:.3f})")
            flips.append(str(sum(a != b for a, b in zip(co, cn))))
        d = [abs(b[key]["q"][2] - a[key]["q"][2]) / ((a[key]["q"][3] - a[key]["q"][1]) / 2)
             for a, b in zip(o, n)]
        lines.append(f"| {label} | {cells[0]} | {cells[1]} | {np.median(d):.3f} / "
                     f"{np.max(d):.3f} | {' / '.join(flips)} | {'yes' if ok else 'NO'} |")
    wo = statistics.median(r["wall_s"] for r in o[1:])
    wn = statistics.median(r["wall_s"] for r in n[1:])
    lines.append(f"\nmedian wall time per sample_posterior call (first call excluded, the "
                 f"other jobs sequential): old {wo:.2f} s, new {wn:.2f} s")
    return "\n".join(lines)


def diagnose_table(res):
    rows = {tag: {(r["scenario"], r["seed"]): r for r in res[tag]} for tag in ("old", "new")}
    scen = list(dict.fromkeys(r["scenario"] for r in res["old"]))
    lines = ["\n## (c) diagnose: identification per hidden effect (old / new, same records)\n",
             "controls: rate flagged inadequate (false alarm); effects: hidden effect ranked "
             "first and significant, and 'all ok' = identified + refit passes gof + k, gamma "
             "within 3 SE; (binomial SE of the old rate); 'top differs' = seeds whose "
             "first-ranked candidate differs.\n",
             "| scenario | n | identified (controls: false alarm) | all ok | top differs | "
             "errors old / new | median wall [s] old / new | within |",
             "|---|---|---|---|---|---|---|---|"]
    for s in scen:
        keys = [k for k in rows["old"] if k[0] == s]
        rate, allok, err, wall = {}, {}, {}, {}
        for tag in ("old", "new"):
            rr = [rows[tag].get(k, {"error": "missing"}) for k in keys]
            good = [r for r in rr if "error" not in r]
            err[tag] = len(rr) - len(good)
            wall[tag] = statistics.median(r["wall_s"] for r in good) if good else float("nan")
            if s.startswith("control"):
                rate[tag] = sum(not r["adequate"] for r in good) / len(keys)
            else:
                rate[tag] = sum(r["identified"] for r in good) / len(keys)
                allok[tag] = sum(r["fixed_ok"] for r in good) / len(keys)
        se = math.sqrt(max(rate["old"] * (1 - rate["old"]), 0.25 / len(keys)) / len(keys))
        ok = abs(rate["new"] - rate["old"]) <= 2 * se
        diff = sum(rows["old"].get(k, {}).get("top") != rows["new"].get(k, {}).get("top")
                   for k in keys)
        a = (f"{allok['old']:.2f} / {allok['new']:.2f}" if allok else "-")
        lines.append(f"| {s} | {len(keys)} | {rate['old']:.2f} / {rate['new']:.2f} ({se:.2f}) "
                     f"| {a} | {diff} | {err['old']} / {err['new']} | {wall['old']:.2f} / "
                     f"{wall['new']:.2f} | {'yes' if ok else 'NO'} |")
    return "\n".join(lines)


LABELS = {"calibrate": "calibrate, 65 536 frames (default)",
          "calibrate_keep": "calibrate, 65 536 frames, new: lines='keep' (old: default)",
          "batch": "calibrate_batch, {b} x 65 536",
          "sim_substep": "simulate method='exact' (substeps), 64 x 16 384 frames",
          "sim_exact_frames": "simulate method='exact_frames', 64 x 65 536 frames",
          "posterior": "sample_posterior, 32 walkers x 500 steps, 65 536 frames"}


def speed_table(sp, first, n_batch, repeat):
    lines = [f"\n## Speed: {repeat} interleaved repeats (order alternating), medians [s]; "
             "calibrate = mean of 10 calls on different records\n",
             "| case | clock | old | new | new/old (median of ratios) | ratio range | within "
             "10 % |", "|---|---|---|---|---|---|---|"]
    for key, r in sp["rows"].items():
        case, clock = key.split("/")
        lab = LABELS[case].format(b=n_batch)
        lines.append(f"| {lab} | {'wall' if clock == 't' else 'CPU'} | {r['old']:.4g} | "
                     f"{r['new']:.4g} | {r['ratio']:.3f} | {r['lo']:.2f}-{r['hi']:.2f} | "
                     f"{'yes' if r['ratio'] <= 1.10 else 'NO'} |")
    lines += ["\nFirst call in a fresh process (compilation included) and the second call, "
              f"{len(first['old'])} processes per tree, alternating old/new [s] "
              "(each value: the processes' results):\n",
              "| case | first old | first new | second old | second new |",
              "|---|---|---|---|---|"]
    for case, lab in LABELS.items():
        if case == "calibrate_keep":  # runs after "calibrate": nothing left to compile
            continue
        c = [", ".join(f"{p[k][case]:.2f}" for p in first[t]) for k in ("first", "second")
             for t in ("old", "new")]
        lines.append(f"| {lab.format(b=n_batch)} | {c[0]} | {c[1]} | {c[2]} | {c[3]} |")
    return "\n".join(lines)
