"""Recordings and their I/O: containers, validation, CSV / NPZ / manifest files, and
instrument files (HDF5: Bluelake and plain datasets; LabVIEW TDMS).

Positions are in metres (or volts, for a detector signal not yet converted:
``Recording.position_unit``) and times in seconds; the instrument settings (detector, bead,
drive, fit ranges) are in the metadata, read by ``instrument_settings``. numpy only:
importing this subpackage does not import jax itself (JAX arrays are accepted as input). The
instrument-file loaders import their optional dependencies (h5py, npTDMS) only when called.
"""

from ._bluelake import load_bluelake as load_bluelake
from ._csv import ExcludedRowsWarning as ExcludedRowsWarning
from ._csv import infer_frame_interval as infer_frame_interval
from ._csv import load_csv as load_csv
from ._h5 import load_h5 as load_h5
from ._instrument import INSTRUMENT_KEYS as INSTRUMENT_KEYS
from ._instrument import instrument_settings as instrument_settings
from ._io import from_arrays as from_arrays
from ._io import holds_xy as holds_xy
from ._io import load as load
from ._manifest import load_manifest as load_manifest
from ._manifest_save import save_manifest as save_manifest
from ._npz import load_npz as load_npz
from ._npz import save_npz as save_npz
from ._recording import Recording as Recording
from ._recording import TimingJitter as TimingJitter
from ._recording_set import RecordingSet as RecordingSet
from ._tdms import load_tdms as load_tdms
from ._units import ALLOWED_UNITS as ALLOWED_UNITS
from ._xy import XYRecording as XYRecording
from ._xy import load_xy_csv as load_xy_csv
from ._xy import write_xy_csv as write_xy_csv
from ._xy import xy_from_arrays as xy_from_arrays
