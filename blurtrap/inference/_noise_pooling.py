"""Does one tracking noise eps^2 describe every recording of a joint fit?

A joint fit shares eps^2 across its recordings, but a camera's tracking error grows in
dimmer light and at shorter exposures (fewer photons per frame), so recordings at several
laser powers or exposures often differ in it. An independent pass: four powers with 4, 2.8,
2 and 1.4 nm of noise fitted with ``k='linear_power'``: c 7 SE and gamma 11 SE low, goodness
of fit p = 0.63, no note (the Cochran test of :mod:`._pooling` runs only when the goodness of
fit fails, and one recording alone often cannot identify its own eps^2).

The check needs no fit per recording: the spectrum is linear in eps^2, so the joint
objective with ``eps^2_i = eps^2 + delta_i`` (``delta_0 = 0``) is evaluated from the compiled
model spectrum and its finite-difference derivatives (nothing is compiled for it). Where Rao's
efficient score test of the offsets at the joint estimate has p < :data:`_SCORE_GATE`, Fisher
scoring refits the enlarged model (stopping after one step when it is far from the note). The
note appears when the likelihood ratio against one shared eps^2 has p < :data:`NOISE_ALPHA`
or a Hausman |z| exceeds :data:`NOISE_HAUSMAN_Z`, and k, c or gamma moves by more than
:data:`NOISE_SHIFT_SE` of its joint standard error; not beside a note that finds a recording
not stationary (:func:`without_drift_confusion`).
"""

from __future__ import annotations

import math

import numpy as np

from ._chi2 import chi2_sf
from ._spectral import _psd_jit

#: the likelihood ratio of one eps^2 per recording against the shared one rejects below this p
NOISE_ALPHA = 0.01
#: ... and the refit with one eps^2 per recording moves k, c or gamma by more than this many
#: of its joint standard errors
NOISE_SHIFT_SE = 0.5
_H = 1e-5  # relative step of the forward differences (log parameters)


def _derivatives(p, args, free):
    """``dS/dlog p_j`` for the free parameters ``j`` (``dS/d eps^2`` for tracking_var, which
    may sit at 0), each of shape (R, M), by forward differences (the information and score
    need ~5 digits; one spectrum per parameter)."""
    out = []
    base = np.asarray(_psd_jit(p, args), dtype=float)
    for j, name in free:
        if name == "tracking_var":
            # S is linear in eps^2: any step is exact; eps^2 itself, or (at 0) a small one
            step = max(abs(float(p[j])), float(np.max(base)) * 1e-6)
            q = np.array(p, dtype=float)
            q[j] += step
            out.append((np.asarray(_psd_jit(q, args), dtype=float) - base) / step)
            continue
        up = np.array(p, dtype=float)
        up[j] *= math.exp(_H)
        out.append((np.asarray(_psd_jit(up, args), dtype=float) - base) / _H)
    return base, out


def _enlarged_pass(p, delta, args, free, ie, n_rec):
    """At ``p`` (free parameters) and eps^2 offsets ``delta`` (recordings 1..R-1): the
    Whittle/Gamma nll of the enlarged model, its score and expected information in (log p
    free but eps^2, eps^2, delta). The spectrum is linear in eps^2, so recording i's is
    ``S(p) + delta_i dS/d eps^2`` exactly."""
    base, dfree = _derivatives(p, args, free)
    g = dfree[ie]
    rows = np.arange(n_rec)[:, None]
    s = base + np.where(rows >= 1, np.concatenate([[0.0], delta])[:, None], 0.0) * g
    w = np.asarray(args.weight, dtype=float)
    power = np.asarray(args.power, dtype=float)
    ok = (w > 0) & (s > 0) & np.isfinite(s)
    if np.any((w > 0) & ~ok):
        return math.inf, None, None
    s = np.where(ok, s, 1.0)
    nll = float(np.sum(np.where(ok, w * (np.log(s) + power / s), 0.0)))
    cols = list(dfree) + [np.where(rows == i, g, 0.0) for i in range(1, n_rec)]
    d = np.stack([c.reshape(-1) for c in cols])
    info = (d * np.where(ok, w / s**2, 0.0).reshape(-1)) @ d.T
    score = -(d @ np.where(ok, w * (1.0 / s - power / s**2), 0.0).reshape(-1))
    return nll, score, info


def _apply(p, delta, step, free, ie, nf):
    q = np.array(p, dtype=float)
    for k, (j, _) in enumerate(free):
        q[j] = q[j] + step[k] if k == ie else q[j] * math.exp(float(np.clip(step[k], -1.0, 1.0)))
    dl = delta + step[nf:]
    q[free[ie][0]] = max(q[free[ie][0]], 0.0)  # eps^2 of recording 0 >= 0
    return q, np.maximum(dl, -q[free[ie][0]])  # and of the others


def _summary(p, q, dl, info, nll0, nll, cov, free, ie, n_rec) -> dict:
    """The result of the refit at ``(q, dl)`` (see :func:`noise_heterogeneity`)."""
    inv = np.linalg.inv(info)
    nf = len(free)
    lr = max(2.0 * (nll0 - nll), 0.0)
    lin = np.zeros((n_rec, nf + n_rec - 1))  # eps^2_i as a linear map of the parameters
    lin[:, ie] = 1.0
    lin[np.arange(1, n_rec), nf + np.arange(n_rec - 1)] = 1.0
    e0 = float(q[free[ie][0]])
    se_joint = np.sqrt(np.abs(np.diag(np.asarray(cov, dtype=float))))
    shift = {}
    for k, (j, n) in enumerate(free):
        if (n in ("k", "c", "gamma") or n.startswith("k[")) and se_joint[j] > 0:
            # Hausman, in log p (the scale of inv): the change against the variance the shared
            # eps^2 removes, floored at a quarter of the joint variance (a refit whose error
            # is within a few % of the joint one would make any change look significant)
            joint = (float(se_joint[j]) / float(p[j])) ** 2
            extra = max(float(inv[k, k]) - joint, 0.25 * joint)
            z = math.log(float(q[j]) / float(p[j])) / math.sqrt(extra) if q[j] > 0 else math.inf
            shift[n] = (float(q[j]), float(q[j] - p[j]) / float(se_joint[j]), z)
    return {"lr": lr, "dof": n_rec - 1, "p": chi2_sf(lr, n_rec - 1),
            "eps2": np.concatenate([[e0], e0 + dl]),
            "eps2_se": np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", lin, inv, lin), 0.0)), "shift": shift}


#: the refit runs only where Rao's efficient score test of one eps^2 per recording (at the
#: joint estimate, from the pass the refit starts with) has p below this
_SCORE_GATE = 0.2


def _score_p(score, info, nf: int) -> float:
    """Rao's efficient score test of the offsets (the parameters after the first ``nf``)."""
    try:
        a = info[nf:, :nf] @ np.linalg.solve(info[:nf, :nf], np.eye(nf))
        u = score[nf:] - a @ score[:nf]
        stat = float(u @ np.linalg.solve(info[nf:, nf:] - a @ info[:nf, nf:], u))
    except np.linalg.LinAlgError:
        return 0.0
    return chi2_sf(stat, len(score) - nf)


#: after the first Fisher-scoring step, the refit stops when the likelihood ratio's p is above
#: this and no Hausman |z| reaches 2 (the note is far from firing)
_EARLY_P = 0.1


def noise_heterogeneity(layout, args, value, cov, fixed, n_iter: int = 30) -> dict | None:
    """The joint fit refitted with one eps^2 per recording (Fisher scoring on the Whittle
    objective from the joint estimate ``value``): ``{"lr", "dof", "p", "eps2", "eps2_se",
    "shift"}``: the likelihood-ratio statistic against the shared eps^2 (chi^2, R - 1 dof),
    each recording's eps^2 and SE [m^2], and for k/c and gamma ``(value, change in SE of the
    joint fit, Hausman z)``; None where it does not apply (one recording, eps^2 held or
    absent) or the refit fails."""
    names = list(layout.names)
    n_rec = int(np.shape(args.power)[0])
    if n_rec < 2 or "tracking_var" not in names or "tracking_var" in (fixed or {}):
        return None
    p = np.asarray(value, dtype=float)
    free = [(j, n) for j, n in enumerate(names) if n not in (fixed or {})]
    ie, nf = [n for _, n in free].index("tracking_var"), len(free)
    nll0, score, info = _enlarged_pass(p, np.zeros(n_rec - 1), args, free, ie, n_rec)
    if score is None or info is None or _score_p(score, info, nf) > _SCORE_GATE:
        return None
    nll, q, dl = nll0, p, np.zeros(n_rec - 1)
    try:
        for it in range(n_iter):
            step = np.linalg.solve(info, score)
            for _half in range(20):  # step halving until the nll falls
                q_new, dl_new = _apply(q, dl, step, free, ie, nf)
                nll_new, score_new, info_new = _enlarged_pass(q_new, dl_new, args, free, ie, n_rec)
                if nll_new <= nll:
                    break
                step = step / 2
            else:
                break
            done = nll - nll_new < 1e-8 * max(1.0, abs(nll))
            assert score_new is not None and info_new is not None  # a finite nll has them
            q, dl, nll, score, info = q_new, dl_new, nll_new, score_new, info_new
            if it == 0 and not done:
                t = _summary(p, q, dl, info, nll0, nll, cov, free, ie, n_rec)
                done = t["p"] > _EARLY_P and all(abs(v[2]) < 2.0 for v in t["shift"].values())
            if done:
                break
        return _summary(p, q, dl, info, nll0, nll, cov, free, ie, n_rec)
    except np.linalg.LinAlgError:
        return None


#: ... or the refit moves k, c or gamma by more than this many SE of its own change
#: (Hausman's z: the change against the variance the shared eps^2 removes)
NOISE_HAUSMAN_Z = 3.0


def _lab(name: str, v: float) -> str:
    if name == "gamma":
        return f"{v * 1e6:.4g} pN s/um"
    return f"{v * 1e3:.4g} pN/nm" + ("/W" if name == "c" else "")


def noise_note(layout, args, value, cov, fixed) -> str | None:
    """The note when the recordings' tracking noise differs enough to move k or gamma."""
    t = noise_heterogeneity(layout, args, value, cov, fixed)
    if t is None:
        return None
    moved = {n: v for n, v in t["shift"].items() if abs(v[1]) > NOISE_SHIFT_SE}
    if not moved or not (t["p"] < NOISE_ALPHA or any(abs(v[2]) > NOISE_HAUSMAN_Z for v in moved.values())):
        return None
    each = ", ".join(f"{i}: {e * 1e18:.3g} +- {s * 1e18:.2g}" for i, (e, s)
                     in enumerate(zip(t["eps2"], t["eps2_se"])))
    how = "; ".join(f"{n} = {_lab(n, v[0])} ({v[1]:+.2g} SE of the joint fit; Hausman z = {v[2]:+.2g})"
                    for n, v in moved.items())
    return (f"the recordings' tracking noise differs: refitted with one eps^2 per recording (Whittle), "
            f"eps^2 = {each} nm^2 by recording (likelihood ratio against one shared eps^2: "
            f"chi^2 = {t['lr']:.3g}, {t['dof']} dof, p = {t['p']:.2g}), and {how}. The joint fit "
            "shares one eps^2, which biases k and gamma when it differs, with errors too small; a "
            "camera's tracking error grows in dimmer light and at shorter exposures. Report the "
            "refitted values (their errors are larger), or calibrate each recording alone where its "
            "frames resolve the relaxation, or pool only recordings of one exposure and illumination")


#: the openings of the notes that say a recording is not stationary (a drift or step of its
#: mean, a change of its variance): low-frequency power that one eps^2 per recording absorbs
#: as if the white noise differed
_NOT_STATIONARY = ("the mean position of recording", "the variance of recording")


def without_drift_confusion(notes: tuple) -> tuple:
    """``notes`` without the tracking-noise note when another note finds a recording not
    stationary: a reviewer found drift in one of four recordings (equal noise) named as
    noise differing in 18/20 datasets, its refit making gamma 1.56x the truth; with the drift
    in the model (``standard+drift``) the note did not appear (0/10)."""
    if not any(n.lower().startswith(_NOT_STATIONARY) for n in notes):
        return notes
    return tuple(n for n in notes if not n.startswith("the recordings' tracking noise differs"))
