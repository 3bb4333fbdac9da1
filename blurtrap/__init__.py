"""blurtrap: exact, differentiable optical-trap calibration with motion blur and aliasing.

SI units in the Python API. Inference runs in float64 (see ``blurtrap._config``).
Heavy optional pieces (``blurtrap.plotting`` -> matplotlib, posterior sampling -> emcee) are
imported lazily: ``import blurtrap`` imports neither.
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from ._config import (
    enable_compilation_cache as enable_compilation_cache,
)
from ._config import (
    enable_x64 as enable_x64,
)
from ._config import (
    x64_enabled as x64_enabled,
)
from .data import (
    Recording as Recording,
)
from .data import (
    RecordingSet as RecordingSet,
)
from .data import (
    from_arrays as from_arrays,
)
from .data import (
    load as load,
)
from .data import (
    load_csv as load_csv,
)
from .data import (
    load_manifest as load_manifest,
)
from .data import (
    load_npz as load_npz,
)
from .data import (
    save_manifest as save_manifest,
)
from .data import (
    save_npz as save_npz,
)
from .diagnostics import Diagnosis as Diagnosis
from .diagnostics import Selection as Selection
from .diagnostics import compare as compare
from .diagnostics import diagnose as diagnose
from .diagnostics import select_model as select_model
from .inference import (
    CalibrationResult as CalibrationResult,
)
from .inference import (
    FitError as FitError,
)
from .inference import (
    LogUniform as LogUniform,
)
from .inference import (
    Normal as Normal,
)
from .inference import (
    Posterior as Posterior,
)
from .inference import (
    ShortChainWarning as ShortChainWarning,
)
from .inference import (
    TrapModel as TrapModel,
)
from .inference import (
    Uniform as Uniform,
)
from .inference import (
    calibrate as calibrate,
)
from .inference import (
    calibrate_batch as calibrate_batch,
)
from .inference import (
    sample_posterior as sample_posterior,
)
from .inference import (
    stokes_gamma_prior as stokes_gamma_prior,
)
from .inference import (
    stuck_bead_prior as stuck_bead_prior,
)
from .physics import (
    BOLTZMANN as BOLTZMANN,
)
from .physics import (
    ExponentialKernel as ExponentialKernel,
)
from .physics import (
    ProductKernel as ProductKernel,
)
from .physics import (
    RectKernel as RectKernel,
)
from .physics import (
    TrapezoidKernel as TrapezoidKernel,
)
from .physics import (
    blur_factor as blur_factor,
)
from .physics import (
    blur_factor_pade as blur_factor_pade,
)
from .physics import (
    frame_autocovariance as frame_autocovariance,
)
from .physics import (
    lorentzian as lorentzian,
)
from .physics import (
    measured_variance as measured_variance,
)
from .physics import (
    psd_folded as psd_folded,
)
from .physics import (
    psd_measured as psd_measured,
)
from .physics import (
    sample_variance_se as sample_variance_se,
)
from .physics import (
    stiffness_from_variance as stiffness_from_variance,
)
from .physics import (
    transfer_rect as transfer_rect,
)
from .physics import (
    variance_general as variance_general,
)
from .simulate import (
    ExponentialProfile as ExponentialProfile,
)
from .simulate import (
    ExposureWindows as ExposureWindows,
)
from .simulate import (
    RandomWalkDrift as RandomWalkDrift,
)
from .simulate import (
    SinusoidDrift as SinusoidDrift,
)
from .simulate import (
    SubstepBiasWarning as SubstepBiasWarning,
)
from .simulate import (
    TrackingNoise as TrackingNoise,
)
from .simulate import (
    TrapezoidProfile as TrapezoidProfile,
)
from .simulate import (
    quartic_force as quartic_force,
)
from .simulate import (
    simulate as simulate,
)

try:
    __version__ = _version("blurtrap")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"
