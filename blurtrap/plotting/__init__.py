"""blurtrap.plotting: matplotlib figures of recordings and calibrations (lab units).

Imported only on request (``import blurtrap.plotting``); ``import blurtrap`` never imports
matplotlib. Every function returns a ``matplotlib.figure.Figure``, takes SI inputs
(recordings, ``CalibrationResult`` objects, arrays) and labels its axes in lab units. Plots
compute no fits: fit with :func:`blurtrap.calibrate` and pass the results in.

Where the figure goes: with ``ax=`` (one-axes figures) or ``fig=`` (an empty figure, for the
multi-axes ones) the function draws there and makes no new figure; otherwise it makes a new
figure with pyplot, so that Jupyter's inline backend shows it at the end of the cell (don't also
end the cell with the figure, or it shows twice: ``fig = bp.fig6_psd(...)``) and a script can
``plt.show()`` it. Code that only writes files should close what it saves:
``blurtrap.plotting.save(fig, path)`` saves and closes, :func:`close` closes.

The paper's figures (Wong & Halvorsen 2006): :func:`fig1a_universal_curve`,
:func:`fig1b_histogram`, :func:`fig3_fractional_variance`, :func:`fig4_stiffness_vs_power`,
:func:`fig5_highpass`, :func:`fig6_psd`, :func:`fig7_deviation`. Beyond it: :func:`corner`,
:func:`residuals_before_after`, :func:`naive_error_map`, :func:`diagnose_ranking`.
A calibration's own figures: :func:`fit_spectrum` and :func:`fit_residuals` (also
``CalibrationResult.plot()`` and ``.plot_residuals()``).
Experiment design: :func:`design_se` (also ``DesignResult.plot()``).
"""

from ._blur_figs import fig1a_universal_curve as fig1a_universal_curve
from ._blur_figs import fig1b_histogram as fig1b_histogram
from ._blur_figs import naive_error_map as naive_error_map
from ._common import LAB_UNITS as LAB_UNITS
from ._common import close as close
from ._common import save as save
from ._corner import corner as corner
from ._design import design_se as design_se
from ._drift_fig import fig5_highpass as fig5_highpass
from ._psd_figs import fig6_psd as fig6_psd
from ._psd_figs import fig7_deviation as fig7_deviation
from ._psd_figs import residuals_before_after as residuals_before_after
from ._ranking import diagnose_ranking as diagnose_ranking
from ._result_figs import fit_residuals as fit_residuals
from ._result_figs import fit_spectrum as fit_spectrum
from ._variance_figs import fig3_fractional_variance as fig3_fractional_variance
from ._variance_figs import fig4_stiffness_vs_power as fig4_stiffness_vs_power

__all__ = [
    "LAB_UNITS",
    "close",
    "corner",
    "design_se",
    "diagnose_ranking",
    "fig1a_universal_curve",
    "fig1b_histogram",
    "fig3_fractional_variance",
    "fig4_stiffness_vs_power",
    "fig5_highpass",
    "fig6_psd",
    "fig7_deviation",
    "fit_residuals",
    "fit_spectrum",
    "naive_error_map",
    "residuals_before_after",
    "save",
]
