"""Figures (matplotlib): workspace, tubes, trajectories, transition graph.

:func:`save_figure` writes PNG + PDF inside :func:`figure_style` (TrueType fonts in the PDF).

Modules: :mod:`~tubejax.analyses.plot.style` (figure style, fresh axes, saving),
:mod:`~tubejax.analyses.plot.figures` (workspace, tube, transition graph),
:mod:`~tubejax.analyses.plot.trajectories` (closed-loop runs), :mod:`~tubejax.analyses.plot.spec`
(a temporal specification), :mod:`~tubejax.analyses.plot.state_constraints` (state constraints
hatched), :mod:`~tubejax.analyses.plot.sweeps` (parameter sweeps) and
:mod:`~tubejax.analyses.plot.radius_curves` (``radius.json``).
"""

from .figures import plot_transition_graph, plot_tube, plot_workspace
from .spec import plot_specification
from .style import FIGURE_RC, figure_style, new_axes, save_figure
from .trajectories import plot_trajectories, select_runs

__all__ = ["FIGURE_RC", "figure_style", "new_axes", "plot_specification", "plot_transition_graph",
           "plot_trajectories", "plot_tube", "plot_workspace", "save_figure", "select_runs"]
