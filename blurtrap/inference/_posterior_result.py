"""The result of :func:`sample_posterior`: :class:`Posterior` (samples, diagnostics,
summaries in lab units, arviz export) and the derived quantities of the samples."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from .._constants import BOLTZMANN
from ._fit_inputs import html_table
from ._result import DESCRIBE, LAB, CalibrationResult, Parameter

# lab units for summaries: name -> (factor from SI, unit)
LAB_UNITS = LAB


def _base(name: str) -> str:
    return name.split("[")[0]


@dataclasses.dataclass(frozen=True)
class Posterior:
    """Posterior samples of trap parameters (SI units) with MCMC diagnostics.

    - ``samples``: dict of 1-D arrays (all walkers and kept steps, burn-in removed) keyed like
      :meth:`CalibrationResult.to_dict`: ``k`` (or ``k[...]`` per stiffness parameter, or
      ``c`` and the implied ``k[P=... mW]``), ``gamma``, ``tracking_var`` (models with
      tracking noise) and the derived ``diffusion`` (kT/gamma), ``tau`` (gamma/k),
      ``corner_frequency`` (k/(2 pi gamma)), ``force_per_nm`` (k x 1 nm, [N]), with the same
      ``[...]`` suffix as their k when there are several.
    - ``chain``: (n_kept, n_walkers, n_params) natural parameters in ``param_names`` order.
    - ``acceptance_fraction`` (per walker), ``autocorr_time`` and ``ess`` (dicts over
      ``param_names``; tau in steps, ESS in independent samples), ``burn_in`` (steps).
    - ``evaluation``: how the likelihood was evaluated: ``"whittle_closed_form"`` (lag sums,
      :class:`_RationalWhittleArgs`), ``"whittle_ordinates"`` (``calibrate``'s per-ordinate
      Whittle: models with additive or transfer effects, an ``f_range``, or records short
      compared with tau) or ``"exact"``.
    """

    samples: dict
    param_names: tuple
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance_fraction: np.ndarray
    autocorr_time: dict
    ess: dict
    burn_in: int
    n_steps: int
    n_walkers: int
    likelihood: str
    model: str
    k_mode: str
    temperature: float
    seed: int
    ml: CalibrationResult
    timing: dict = dataclasses.field(default_factory=dict)
    evaluation: str = ""
    pointwise: Any = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def notes(self) -> tuple:
        """The maximum-likelihood start's notes (:attr:`ml`): what the data preparation did
        (lines subtracted, the detector) and what the fit found (a failing goodness of fit,
        recordings that disagree): the posterior inherits them."""
        return tuple(self.ml.notes)

    @property
    def n_samples(self) -> int:
        return int(self.chain.shape[0] * self.chain.shape[1])

    def quantiles(self, name: str, q=(0.025, 0.16, 0.5, 0.84, 0.975)) -> np.ndarray:
        """Quantiles of ``samples[name]`` (SI)."""
        return np.quantile(self.samples[name], q)

    def interval(self, name: str, level: float = 0.68) -> tuple[float, float]:
        """Central credible interval of ``samples[name]`` at ``level`` (SI)."""
        lo, hi = np.quantile(self.samples[name], [0.5 - level / 2, 0.5 + level / 2])
        return float(lo), float(hi)

    def stats(self) -> dict[str, dict[str, float]]:
        """Per quantity: median, 68 % and 95 % central intervals, mean and SD (SI)."""
        out = {}
        for name, s in self.samples.items():
            q = np.quantile(s, [0.025, 0.16, 0.5, 0.84, 0.975])
            out[name] = {"median": float(q[2]), "q16": float(q[1]), "q84": float(q[3]),
                         "q2.5": float(q[0]), "q97.5": float(q[4]),
                         "mean": float(np.mean(s)), "sd": float(np.std(s, ddof=1))}
        return out

    def summary(self) -> str:
        """Table in lab units: median, 68 % and 95 % central intervals, plus diagnostics."""
        head = (f"posterior ({self.likelihood} likelihood, model {self.model}, k {self.k_mode}): "
                f"{self.n_walkers} walkers x {self.n_steps} steps, burn-in {self.burn_in}, "
                f"{self.n_samples} samples, acceptance {np.mean(self.acceptance_fraction):.3f}")
        lines = [head, f"  {'quantity':<26s} {'median':>11s}   {'68 % interval':>25s}   "
                       f"{'95 % interval':>25s}  unit"]
        for name, st in self.stats().items():
            fac, unit = LAB_UNITS.get(_base(name), (1.0, "SI"))
            lines.append(
                f"  {name:<26s} {st['median'] * fac:11.5g}   "
                f"[{st['q16'] * fac:11.5g}, {st['q84'] * fac:11.5g}]   "
                f"[{st['q2.5'] * fac:11.5g}, {st['q97.5'] * fac:11.5g}]  {unit}"
            )
        taus = ", ".join(f"{n} {t:.3g}" for n, t in self.autocorr_time.items())
        esss = ", ".join(f"{n} {e:.0f}" for n, e in self.ess.items())
        lines.append(f"  autocorrelation time [steps]: {taus}")
        lines.append(f"  effective sample size: {esss}")
        lines += [f"  note (ML start): {n}" for n in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:  # pragma: no cover - convenience
        return self.summary()

    def __repr__(self) -> str:
        return (f"Posterior({self.model!r}, {self.likelihood} likelihood, {self.n_walkers} "
                f"walkers x {self.n_steps} steps, {self.n_samples} samples; quantities "
                f"{list(self.samples)})")

    def __getitem__(self, name: str) -> Parameter:
        """A quantity by name, as ``CalibrationResult[name]``: ``value`` = posterior median,
        ``error`` = half the central 68 % interval, ``unit`` (SI), lab-unit value and error,
        ``interval`` = central 95 % credible interval (SI). ``"D"`` is ``"diffusion"``."""
        key = "diffusion" if name == "D" else name
        if key not in self.samples:
            raise KeyError(f"no quantity {name!r} in this posterior; its quantities are "
                           f"{list(self.samples)} (and 'D' for 'diffusion')")
        q = np.quantile(self.samples[key], [0.025, 0.16, 0.5, 0.84, 0.975])
        unit, what = DESCRIBE.get(_base(key), ("SI", _base(key).replace("_", " ")))
        fac, lab_unit = LAB_UNITS.get(_base(key), (1.0, unit))
        value, error = float(q[2]), 0.5 * float(q[3] - q[1])
        return Parameter(key, value, error, unit, what, value * fac, error * fac, lab_unit,
                         (float(q[0]), float(q[4])))

    def _repr_html_(self) -> str:
        """Table in lab units for notebooks: median, 68 % and 95 % central intervals, unit,
        effective sample size and autocorrelation time where the quantity is sampled."""
        rows = []
        for name, st in self.stats().items():
            fac, unit = LAB_UNITS.get(_base(name), (1.0, "SI"))
            ess, tau = self.ess.get(name), self.autocorr_time.get(name)
            rows.append((name, f"{st['median'] * fac:.5g}",
                         f"[{st['q16'] * fac:.5g}, {st['q84'] * fac:.5g}]",
                         f"[{st['q2.5'] * fac:.5g}, {st['q97.5'] * fac:.5g}]", unit,
                         "" if ess is None else f"{ess:.0f}",
                         "" if tau is None else f"{tau:.3g}"))
        cap = (f"posterior ({self.likelihood} likelihood, model {self.model}): "
               f"{self.n_walkers} walkers x {self.n_steps} steps, burn-in {self.burn_in}, "
               f"{self.n_samples} samples, mean acceptance "
               f"{np.mean(self.acceptance_fraction):.3f}")
        return html_table(("quantity", "median", "68 % interval", "95 % interval", "unit",
                           "ESS", "autocorr. time [steps]"), rows, cap)

    def to_dataframe(self):
        """One row per quantity (as ``self[name]``: median, half the 68 % width, unit, lab
        units, 95 % interval ``ci_low``/``ci_high``) plus the 68 % interval ``q16``/``q84``
        and ``ess`` (SI). Needs pandas (``pip install "blurtrap[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError('Posterior.to_dataframe needs pandas: pip install '
                              '"blurtrap[pandas]"') from None
        rows = []
        for name in self.samples:
            row = dataclasses.asdict(self[name])
            row["ci_low"], row["ci_high"] = row.pop("interval")
            row["q16"], row["q84"] = self.interval(name, 0.68)
            row["ess"] = float(self.ess.get(name, np.nan))
            rows.append(row)
        return pd.DataFrame(rows).set_index("name")

    def to_dict(self, include_samples: bool = False) -> dict[str, Any]:
        """JSON-able dict in SI units. Top-level ``k``/``gamma``/``tracking_var``/... hold
        posterior medians and ``*_err`` half the 68 % interval, as in
        :meth:`CalibrationResult.to_dict`; ``stats`` has the intervals."""
        st = self.stats()
        out: dict[str, Any] = {}
        for name, s in st.items():
            out[name] = s["median"]
            out[f"{name}_err"] = 0.5 * (s["q84"] - s["q16"])
        out.update({
            "method": "posterior",
            "likelihood": self.likelihood,
            "model": self.model,
            "k_mode": self.k_mode,
            "param_names": list(self.param_names),
            "stats": st,
            "acceptance_fraction": float(np.mean(self.acceptance_fraction)),
            "autocorr_time": {k: float(v) for k, v in self.autocorr_time.items()},
            "ess": {k: float(v) for k, v in self.ess.items()},
            "burn_in": int(self.burn_in),
            "n_steps": int(self.n_steps),
            "n_walkers": int(self.n_walkers),
            "n_samples": self.n_samples,
            "temperature": float(self.temperature),
            "seed": int(self.seed),
            "evaluation": self.evaluation,
            "ml": self.ml.to_dict(),
            "timing": {k: float(v) for k, v in self.timing.items()},
            "units": "SI",
        })
        if include_samples:
            out["samples"] = {k: [float(x) for x in v] for k, v in self.samples.items()}
        return out

    def draws(self, name: str) -> np.ndarray:
        """``samples[name]`` as (n_walkers, n_kept) (walker-major, steps in order)."""
        return np.asarray(self.samples[name]).reshape(self.chain.shape[0], self.n_walkers).T

    def log_likelihood(self, max_draws: int | None = None):
        """Pointwise log-likelihood of the draws, for LOO/WAIC (e.g. ``arviz.loo``).

        An observation is one frequency band of one recording's periodogram (Whittle
        likelihoods; ordinates summed in log-spaced bands) or one whole recording (the exact
        likelihood: frames are correlated); see ``blurtrap.inference._pointwise``.

        - `max_draws`: keep at most this many draws in all (every walker, steps thinned
          evenly, the last kept); default all draws.

        **Returns:** ``(values, dim, labels, steps)``: ``values`` of shape
        (n_walkers, n_draws, n_obs), the observation axis' name, one label per observation,
        and the kept step indices (into the post-burn-in chain).
        """
        if self.pointwise is None:
            raise ValueError("this Posterior has no likelihood attached (it was not made by "
                             "sample_posterior); the pointwise log-likelihood needs it")
        n_kept = self.chain.shape[0]
        steps = _thinned_steps(n_kept, self.n_walkers, max_draws)
        sel = self.chain[steps]  # (n_sel, n_walkers, d)
        vals = self.pointwise.fn(sel.reshape(-1, sel.shape[-1]))
        vals = vals.reshape(sel.shape[0], sel.shape[1], -1).swapaxes(0, 1)
        return vals, self.pointwise.dim, self.pointwise.labels, steps

    def to_arviz(self, log_likelihood: bool = True, max_draws: int | None = None):
        """An ``arviz.InferenceData`` (arviz 0.x) or ``DataTree`` (arviz >= 1): group
        ``posterior`` holds every entry of :attr:`samples` (SI) with dims ``(chain, draw)``,
        the walkers as chains; ``sample_stats`` holds ``lp`` (log posterior);
        ``log_likelihood`` (with `log_likelihood`, the default) the pointwise log-likelihood
        of :meth:`log_likelihood` under the name ``"periodogram"`` (dim ``band``) or
        ``"frames"`` (dim ``recording``), so that ``arviz.loo``/``arviz.waic`` work.

        - `max_draws`: thin every group evenly to at most this many draws in all (each
          walker keeps the same steps); default all draws. The pointwise log-likelihood
          costs one model spectrum per draw: ~1 s per 10^4 draws of a 65 536-frame record.

        **Raises:** ``ImportError`` when arviz (an optional dependency) is not installed.
        """
        try:
            with warnings.catch_warnings():  # arviz 0.2x warns about its 1.0 refactor
                warnings.simplefilter("ignore", FutureWarning)
                warnings.simplefilter("ignore", DeprecationWarning)
                import arviz as az
        except ImportError:
            raise ImportError(
                "Posterior.to_arviz() needs arviz, which is not installed: pip install arviz"
            ) from None
        steps = _thinned_steps(self.chain.shape[0], self.n_walkers, max_draws)
        post = {name: self.draws(name)[:, steps] for name in self.samples}
        groups = {"posterior": post,
                  "sample_stats": {"lp": np.swapaxes(self.log_prob, 0, 1)[:, steps]}}
        dims: dict = {}
        coords: dict = {}
        if log_likelihood and self.pointwise is not None:
            vals, dim, labels, _ = self.log_likelihood(max_draws)
            var = "periodogram" if dim == "band" else "frames"
            groups["log_likelihood"] = {var: vals}
            dims, coords = {var: [dim]}, {dim: list(labels)}
        major = int(str(az.__version__).split(".")[0])
        if major >= 1:  # arviz-base: one dict of groups
            return az.from_dict(groups, dims=dims or None, coords=coords or None)
        return az.from_dict(**groups, dims=dims or None, coords=coords or None)


def _thinned_steps(n_kept: int, n_walkers: int, max_draws: int | None) -> np.ndarray:
    """Indices of the kept steps: all, or evenly thinned (the last kept) so that
    ``n_walkers x len(steps) <= max_draws``."""
    if max_draws is None or n_kept == 0:
        return np.arange(n_kept)
    if isinstance(max_draws, bool) or not isinstance(max_draws, (int, np.integer)) \
            or max_draws < n_walkers:
        raise ValueError(f"max_draws must be an integer >= n_walkers = {n_walkers} (one draw "
                         f"per walker at least), or None for all; got max_draws = "
                         f"{max_draws!r}")
    per = max(int(max_draws) // n_walkers, 1)
    step = -(-n_kept // per)
    return np.arange(n_kept - 1, -1, -step)[::-1]


def _derived(layout, chain_nat: np.ndarray, temperature: float) -> dict[str, np.ndarray]:
    """Samples keyed like :meth:`CalibrationResult.to_dict` plus derived quantities (SI)."""
    flat = chain_nat.reshape(-1, chain_nat.shape[-1])
    names = layout.names
    samples: dict[str, np.ndarray] = {}
    col = {n: flat[:, i] for i, n in enumerate(names)}
    gamma = col["gamma"]
    ks: dict[str, np.ndarray] = {}
    if layout.linear_power:
        samples["c"] = col["c"]
        p0 = col.get("power_offset", 0.0)  # k = c (P - P0) with the power_offset effect
        for pw in np.unique(np.asarray(layout.power)):
            ks[f"k[P={pw * 1e3:g} mW]"] = col["c"] * (pw - p0)
    else:
        for lab in layout.k_labels:
            ks[lab] = col[lab]
    samples.update(ks)
    samples["gamma"] = gamma
    if "tracking_var" in col:
        samples["tracking_var"] = col["tracking_var"]
    for name in layout.extra_names:
        samples[name] = col[name]
    samples["diffusion"] = BOLTZMANN * temperature / gamma
    for lab, kv in ks.items():
        suffix = lab[1:]  # "" or "[...]"
        samples["tau" + suffix] = gamma / kv
        samples["corner_frequency" + suffix] = kv / (2.0 * np.pi * gamma)
        samples["force_per_nm" + suffix] = kv * 1e-9
    return samples
