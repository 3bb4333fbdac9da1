"""Estimators: variances, spectra, exact and Whittle likelihoods, joint fits."""

from ..effects import EFFECTS as EFFECTS
from ..effects import AbstractEffect as AbstractEffect
from ..effects import make_effect as make_effect
from ._allan import AllanVariance as AllanVariance
from ._allan import allan_variance as allan_variance
from ._anharmonic import AnharmonicResult as AnharmonicResult
from ._anharmonic import calibrate_anharmonic as calibrate_anharmonic
from ._batch import calibrate_batch as calibrate_batch
from ._batch_result import BatchCalibration as BatchCalibration
from ._calibrate import calibrate as calibrate
from ._drift import (
    drift_extrapolation as drift_extrapolation,
)
from ._drift import (
    highpass_variance_curve as highpass_variance_curve,
)
from ._fit import FitOutput as FitOutput
from ._fit import fit_ml as fit_ml
from ._likelihood import (
    arma_loglik as arma_loglik,
)
from ._likelihood import (
    block_periodogram as block_periodogram,
)
from ._likelihood import (
    periodogram as periodogram,
)
from ._likelihood import (
    whittle_loglik as whittle_loglik,
)
from ._models import TrapModel as TrapModel
from ._models import get_model as get_model
from ._posterior import Posterior as Posterior
from ._posterior import ShortChainWarning as ShortChainWarning
from ._posterior import sample_posterior as sample_posterior
from ._priors import (
    DEFAULT_BOUNDS as DEFAULT_BOUNDS,
)
from ._priors import (
    InverseGamma as InverseGamma,
)
from ._priors import (
    LogNormal as LogNormal,
)
from ._priors import (
    LogUniform as LogUniform,
)
from ._priors import (
    Normal as Normal,
)
from ._priors import (
    Prior as Prior,
)
from ._priors import (
    Uniform as Uniform,
)
from ._priors import (
    stokes_gamma as stokes_gamma,
)
from ._priors import (
    stokes_gamma_prior as stokes_gamma_prior,
)
from ._priors import (
    stuck_bead_prior as stuck_bead_prior,
)
from ._result import CalibrationResult as CalibrationResult
from ._result import FitError as FitError
from ._starts import moment_start as moment_start
from ._stored import fit_psd as fit_psd
from ._variance import (
    empirical_variance_se as empirical_variance_se,
)
from ._xy import XYCalibration as XYCalibration
from ._xy import calibrate_xy as calibrate_xy
