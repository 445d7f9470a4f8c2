"""Figures (matplotlib): workspace, tubes, trajectories, transition graph.

:func:`save_figure` writes PNG + PDF inside :func:`figure_style` (TrueType fonts in the PDF).
"""

from .figures import (FIGURE_RC, figure_style, new_axes, plot_transition_graph, plot_trajectories, plot_tube,
                      plot_workspace, save_figure, select_runs)
from .spec import plot_specification

__all__ = ["FIGURE_RC", "figure_style", "new_axes", "plot_specification", "plot_transition_graph",
           "plot_trajectories", "plot_tube", "plot_workspace", "save_figure", "select_runs"]
