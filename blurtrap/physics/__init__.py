"""Pure, differentiable physics of blurred, sampled Brownian motion in a harmonic trap.

Imports nothing else of blurtrap. SI units throughout.
"""

from ._allan import allan_from_moments as allan_from_moments
from ._allan import allan_variance_model as allan_variance_model
from ._allan import frame_moments as frame_moments
from ._blur import (
    blur_factor as blur_factor,
)
from ._blur import (
    blur_factor_pade as blur_factor_pade,
)
from ._blur import blur_factor_unchecked as blur_factor_unchecked
from ._blur import (
    measured_variance as measured_variance,
)
from ._blur import rho_b_unchecked as rho_b_unchecked
from ._blur import (
    stiffness_from_variance as stiffness_from_variance,
)
from ._constants import BOLTZMANN as BOLTZMANN
from ._constants import DEFAULT_TEMPERATURE as DEFAULT_TEMPERATURE
from ._effects import drift_psd as drift_psd
from ._effects import fold_sum as fold_sum
from ._effects import line_psd as line_psd
from ._effects import photodiode_transfer as photodiode_transfer
from ._hydro import POLYSTYRENE_DENSITY as POLYSTYRENE_DENSITY
from ._hydro import WATER_TEMPERATURE_RANGE as WATER_TEMPERATURE_RANGE
from ._hydro import brenner_factor as brenner_factor
from ._hydro import complex_friction as complex_friction
from ._hydro import faxen_factor as faxen_factor
from ._hydro import hydro_lorentzian as hydro_lorentzian
from ._hydro import hydro_psd as hydro_psd
from ._hydro import iapws_viscosity as iapws_viscosity
from ._hydro import stokes_friction as stokes_friction
from ._hydro import viscous_frequency as viscous_frequency
from ._hydro import water_density as water_density
from ._hydro import water_viscosity as water_viscosity
from ._kernels import (
    AbstractKernel as AbstractKernel,
)
from ._kernels import (
    ExponentialKernel as ExponentialKernel,
)
from ._kernels import (
    ProductKernel as ProductKernel,
)
from ._kernels import (
    RectKernel as RectKernel,
)
from ._kernels import (
    TrapezoidKernel as TrapezoidKernel,
)
from ._kernels import (
    psd_folded as psd_folded,
)
from ._kernels import (
    variance_general as variance_general,
)
from ._spectra import (
    autocovariance_unchecked as autocovariance_unchecked,
)
from ._spectra import (
    discrete_psd_unchecked as discrete_psd_unchecked,
)
from ._spectra import (
    expected_block_periodogram_unchecked as expected_block_periodogram_unchecked,
)
from ._spectra import (
    frame_autocovariance as frame_autocovariance,
)
from ._spectra import (
    lorentzian as lorentzian,
)
from ._spectra import (
    psd_coeffs_unchecked as psd_coeffs_unchecked,
)
from ._spectra import (
    psd_measured as psd_measured,
)
from ._spectra import (
    sample_variance_se as sample_variance_se,
)
from ._spectra import (
    sample_variance_var_unchecked as sample_variance_var_unchecked,
)
from ._spectra import (
    transfer_rect as transfer_rect,
)
