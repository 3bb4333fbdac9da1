"""Units, lab units, descriptions and plausible ranges of every quantity blurtrap reports:
the trap's core parameters, derived quantities and recording settings here; each effect's
own parameters live in its module (``Param`` entries of its ``params``). Results, reports,
plots, the CLI and the default priors all read this one table (:data:`QUANTITIES`)."""

from __future__ import annotations

from ._base import Param

#: the trap's own parameters (``tracking_var`` is the tracking_noise effect's)
CORE = (
    Param("k", "N/m", 1e3, "pN/nm", "trap stiffness", bounds=(1e-10, 1.0)),
    Param("c", "N/m/W", 1e3, "pN/nm/W", "stiffness per laser power (k = c P)",
          bounds=(1e-10, 1e2)),
    Param("gamma", "N s/m", 1e6, "pN s/um", "friction coefficient", bounds=(1e-13, 1e-3)),
)

#: quantities derived from the parameters, and recording settings (not fitted)
DERIVED = (
    Param("diffusion", "m^2/s", 1e12, "um^2/s", "diffusion coefficient D = kT/gamma"),
    Param("tau", "s", 1e3, "ms", "relaxation time tau = gamma/k"),
    Param("corner_frequency", "Hz", 1.0, "Hz", "corner frequency f_c = k/(2 pi gamma)"),
    Param("force_per_nm", "N", 1e12, "pN", "force at 1 nm from the trap centre (k x 1 nm)"),
    Param("displacement_sensitivity", "m/V", 1e9, "nm/V",
          "displacement sensitivity Rd (metres per volt)"),
    Param("force_sensitivity", "N/V", 1e12, "pN/V",
          "force sensitivity Rf = k Rd (newtons per volt)"),
    Param("exposure", "s", 1e3, "ms", "exposure time W"),
    Param("frame_interval", "s", 1e3, "ms", "frame interval dt"),
    Param("position", "m", 1e9, "nm", "bead position"),
    Param("laser_power", "W", 1e3, "mW", "laser power"),
    Param("temperature", "K", 1.0, "K", "temperature at the bead"),
)
