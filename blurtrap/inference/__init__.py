"""Estimators: variances, spectra, exact and Whittle likelihoods, joint fits."""

from ._calibrate import calibrate as calibrate, moment_start as moment_start
from ._fit import FitOutput as FitOutput, fit_ml as fit_ml, fit_ml_batch as fit_ml_batch
from ._likelihood import (
    arma_loglik as arma_loglik,
    block_periodogram as block_periodogram,
    periodogram as periodogram,
    whittle_loglik as whittle_loglik,
)
from ._effects import EFFECTS as EFFECTS, AbstractEffect as AbstractEffect, make_effect as make_effect
from ._models import TrapModel as TrapModel, get_model as get_model
from ._result import CalibrationResult as CalibrationResult, FitError as FitError
from ._variance import (
    drift_extrapolation as drift_extrapolation,
    empirical_variance_se as empirical_variance_se,
    highpass_variance_curve as highpass_variance_curve,
)
from ._batch import BatchCalibration as BatchCalibration, calibrate_batch as calibrate_batch
from ._posterior import Posterior as Posterior, ShortChainWarning as ShortChainWarning
from ._posterior import sample_posterior as sample_posterior
from ._priors import (
    DEFAULT_BOUNDS as DEFAULT_BOUNDS,
    InverseGamma as InverseGamma,
    LogNormal as LogNormal,
    LogUniform as LogUniform,
    Normal as Normal,
    Prior as Prior,
    stokes_gamma as stokes_gamma,
    stokes_gamma_prior as stokes_gamma_prior,
    stuck_bead_prior as stuck_bead_prior,
)
