"""Pure, differentiable physics of blurred, sampled Brownian motion in a harmonic trap.

Imports nothing else of blurtrap. SI units throughout.
"""

from ._blur import (
    blur_factor as blur_factor,
    blur_factor_pade as blur_factor_pade,
    measured_variance as measured_variance,
    stiffness_from_variance as stiffness_from_variance,
)
from ._constants import BOLTZMANN as BOLTZMANN, DEFAULT_TEMPERATURE as DEFAULT_TEMPERATURE
from ._kernels import (
    AbstractKernel as AbstractKernel,
    ExponentialKernel as ExponentialKernel,
    ProductKernel as ProductKernel,
    RectKernel as RectKernel,
    TrapezoidKernel as TrapezoidKernel,
    psd_folded as psd_folded,
    variance_general as variance_general,
)
from ._spectra import (
    frame_autocovariance as frame_autocovariance,
    lorentzian as lorentzian,
    psd_measured as psd_measured,
    sample_variance_se as sample_variance_se,
    transfer_rect as transfer_rect,
)
