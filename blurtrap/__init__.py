"""blurtrap: exact, differentiable optical-trap calibration with motion blur and aliasing.

SI units in the Python API. Inference runs in float64 (see ``blurtrap._config``).

``import blurtrap`` is light: the public names below are imported from their subpackage on
first use (PEP 562 module ``__getattr__``), so ``import blurtrap`` alone imports no jax,
and ``import blurtrap.data`` (numpy only) never does. Importing blurtrap changes no JAX
setting, now as before: float64 is switched on by :func:`enable_x64` or inside the
estimators, never at import. Heavy optional pieces (``blurtrap.plotting`` -> matplotlib,
posterior sampling -> emcee) are only imported on request.
"""

from __future__ import annotations

import importlib as _importlib
import sys as _sys
import types as _types
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # static tools see every public name as a plain import
    from ._config import enable_compilation_cache as enable_compilation_cache
    from ._config import enable_x64 as enable_x64
    from ._config import x64_enabled as x64_enabled
    from ._constants import BOLTZMANN as BOLTZMANN
    from .data import Recording as Recording
    from .data import RecordingSet as RecordingSet
    from .data import XYRecording as XYRecording
    from .data import from_arrays as from_arrays
    from .data import load as load
    from .data import load_bluelake as load_bluelake
    from .data import load_csv as load_csv
    from .data import load_h5 as load_h5
    from .data import load_manifest as load_manifest
    from .data import load_npz as load_npz
    from .data import load_tdms as load_tdms
    from .data import load_xy_csv as load_xy_csv
    from .data import save_manifest as save_manifest
    from .data import save_npz as save_npz
    from .data import xy_from_arrays as xy_from_arrays
    from .design import DesignResult as DesignResult
    from .design import design as design
    from .diagnostics import Diagnosis as Diagnosis
    from .diagnostics import Selection as Selection
    from .diagnostics import compare as compare
    from .diagnostics import diagnose as diagnose
    from .diagnostics import select_model as select_model
    from .inference import AllanVariance as AllanVariance
    from .inference import CalibrationResult as CalibrationResult
    from .inference import FitError as FitError
    from .inference import LogUniform as LogUniform
    from .inference import Normal as Normal
    from .inference import Posterior as Posterior
    from .inference import ShortChainWarning as ShortChainWarning
    from .inference import TrapModel as TrapModel
    from .inference import Uniform as Uniform
    from .inference import XYCalibration as XYCalibration
    from .inference import allan_variance as allan_variance
    from .inference import calibrate as calibrate
    from .inference import calibrate_anharmonic as calibrate_anharmonic
    from .inference import calibrate_batch as calibrate_batch
    from .inference import calibrate_xy as calibrate_xy
    from .inference import fit_psd as fit_psd
    from .inference import sample_posterior as sample_posterior
    from .inference import stokes_gamma_prior as stokes_gamma_prior
    from .inference import stuck_bead_prior as stuck_bead_prior
    from .physics import ExponentialKernel as ExponentialKernel
    from .physics import ProductKernel as ProductKernel
    from .physics import RectKernel as RectKernel
    from .physics import TrapezoidKernel as TrapezoidKernel
    from .physics import blur_factor as blur_factor
    from .physics import blur_factor_pade as blur_factor_pade
    from .physics import frame_autocovariance as frame_autocovariance
    from .physics import lorentzian as lorentzian
    from .physics import measured_variance as measured_variance
    from .physics import psd_folded as psd_folded
    from .physics import psd_measured as psd_measured
    from .physics import sample_variance_se as sample_variance_se
    from .physics import stiffness_from_variance as stiffness_from_variance
    from .physics import transfer_rect as transfer_rect
    from .physics import variance_general as variance_general
    from .simulate import ExponentialProfile as ExponentialProfile
    from .simulate import ExposureWindows as ExposureWindows
    from .simulate import RandomWalkDrift as RandomWalkDrift
    from .simulate import SinusoidDrift as SinusoidDrift
    from .simulate import SubstepBiasWarning as SubstepBiasWarning
    from .simulate import TrackingNoise as TrackingNoise
    from .simulate import TrapezoidProfile as TrapezoidProfile
    from .simulate import quartic_force as quartic_force
    from .simulate import simulate as simulate
    from .simulate import simulate_xy as simulate_xy
    from .sweeps import SweepResult as SweepResult
    from .sweeps import sweep as sweep

# public name -> the submodule that defines it (imported on first access)
_LAZY = {
    # _config
    "enable_compilation_cache": "_config", "enable_x64": "_config", "x64_enabled": "_config",
    # _constants
    "BOLTZMANN": "_constants",
    # data
    "Recording": "data", "RecordingSet": "data", "from_arrays": "data", "load": "data",
    "load_csv": "data", "load_manifest": "data", "load_npz": "data", "save_manifest": "data",
    "save_npz": "data",
    # diagnostics
    "Diagnosis": "diagnostics", "Selection": "diagnostics", "compare": "diagnostics",
    "diagnose": "diagnostics", "select_model": "diagnostics",
    # inference
    "CalibrationResult": "inference", "FitError": "inference", "LogUniform": "inference",
    "Normal": "inference", "Posterior": "inference", "ShortChainWarning": "inference",
    "TrapModel": "inference", "Uniform": "inference", "calibrate": "inference",
    "calibrate_batch": "inference", "fit_psd": "inference", "sample_posterior": "inference",
    "calibrate_anharmonic": "inference",
    "stokes_gamma_prior": "inference", "stuck_bead_prior": "inference",
    # physics
    "ExponentialKernel": "physics", "ProductKernel": "physics", "RectKernel": "physics",
    "TrapezoidKernel": "physics", "blur_factor": "physics", "blur_factor_pade": "physics",
    "frame_autocovariance": "physics", "lorentzian": "physics", "measured_variance": "physics",
    "psd_folded": "physics", "psd_measured": "physics", "sample_variance_se": "physics",
    "stiffness_from_variance": "physics", "transfer_rect": "physics",
    "variance_general": "physics",
    # simulate
    "ExponentialProfile": "simulate", "ExposureWindows": "simulate",
    "RandomWalkDrift": "simulate", "SinusoidDrift": "simulate", "SubstepBiasWarning": "simulate",
    "TrackingNoise": "simulate", "TrapezoidProfile": "simulate", "quartic_force": "simulate",
    "simulate": "simulate",
    # design
    "design": "design", "DesignResult": "design",
    # Allan variance
    "allan_variance": "inference", "AllanVariance": "inference",
    # instrument files
    "load_bluelake": "data", "load_h5": "data", "load_tdms": "data",
    # sweeps
    "sweep": "sweeps", "SweepResult": "sweeps",
    # x/y recordings
    "XYRecording": "data", "load_xy_csv": "data", "xy_from_arrays": "data",
    "XYCalibration": "inference", "calibrate_xy": "inference", "simulate_xy": "simulate",
}
# subpackages that ``import blurtrap`` used to make available as attributes
_SUBMODULES = ("_config", "data", "diagnostics", "effects", "inference", "physics")

# derived from _LAZY rather than written out a third time; the TYPE_CHECKING imports above
# declare the same names to static tools
__all__ = sorted(_LAZY)  # pyright: ignore[reportUnsupportedDunderAll]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is not None:
        value = getattr(_importlib.import_module(f".{module}", __name__), name)
    elif name in _SUBMODULES:
        value = _importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # cached: later look-ups do not come back here
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES))


# subpackages whose entry point has the package's name: the attribute is the function
_FUNCTION_PACKAGES = ("simulate", "design")


class _Package(_types.ModuleType):
    """``blurtrap.simulate`` (and ``blurtrap.design``) is the function, as it always was,
    although a subpackage of that name exists: importing the subpackage (``import
    blurtrap.simulate``, or any module that uses it) binds it as an attribute of this
    package, and this puts the function there."""

    def __setattr__(self, name, value):
        if (
            name in _FUNCTION_PACKAGES
            and isinstance(value, _types.ModuleType)
            and value.__name__ == f"{__name__}.{name}"
        ):
            value = getattr(value, name, value)
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package

try:
    __version__ = _version("blurtrap")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"
