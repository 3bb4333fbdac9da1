"""blurtrap: exact, differentiable optical-trap calibration with motion blur and aliasing.

SI units in the Python API. Inference runs in float64 (see ``blurtrap._config``).
Heavy optional pieces (``blurtrap.plotting`` -> matplotlib, posterior sampling -> emcee) are
imported lazily: ``import blurtrap`` imports neither.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from ._config import (
    enable_compilation_cache as enable_compilation_cache,
    enable_x64 as enable_x64,
    x64_enabled as x64_enabled,
)
from .physics import (
    BOLTZMANN as BOLTZMANN,
    ExponentialKernel as ExponentialKernel,
    ProductKernel as ProductKernel,
    RectKernel as RectKernel,
    TrapezoidKernel as TrapezoidKernel,
    blur_factor as blur_factor,
    blur_factor_pade as blur_factor_pade,
    frame_autocovariance as frame_autocovariance,
    lorentzian as lorentzian,
    measured_variance as measured_variance,
    psd_folded as psd_folded,
    psd_measured as psd_measured,
    sample_variance_se as sample_variance_se,
    stiffness_from_variance as stiffness_from_variance,
    transfer_rect as transfer_rect,
    variance_general as variance_general,
)

from .data import (
    Recording as Recording,
    RecordingSet as RecordingSet,
    from_arrays as from_arrays,
    load as load,
    load_csv as load_csv,
    load_manifest as load_manifest,
    load_npz as load_npz,
    save_manifest as save_manifest,
    save_npz as save_npz,
)
from .diagnostics import Diagnosis as Diagnosis, compare as compare, diagnose as diagnose
from .inference import (
    CalibrationResult as CalibrationResult,
    FitError as FitError,
    TrapModel as TrapModel,
    calibrate as calibrate,
    calibrate_batch as calibrate_batch,
    LogUniform as LogUniform,
    Normal as Normal,
    Posterior as Posterior,
    ShortChainWarning as ShortChainWarning,
    sample_posterior as sample_posterior,
    stokes_gamma_prior as stokes_gamma_prior,
    stuck_bead_prior as stuck_bead_prior,
)
from .simulate import (
    ExponentialProfile as ExponentialProfile,
    ExposureWindows as ExposureWindows,
    RandomWalkDrift as RandomWalkDrift,
    SinusoidDrift as SinusoidDrift,
    SubstepBiasWarning as SubstepBiasWarning,
    TrackingNoise as TrackingNoise,
    TrapezoidProfile as TrapezoidProfile,
    quartic_force as quartic_force,
    simulate as simulate,
)

try:
    __version__ = _version("blurtrap")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"
