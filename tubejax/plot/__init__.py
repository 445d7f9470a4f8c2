"""Figures (matplotlib): workspace, tubes, trajectories, transition graph."""

from .figures import (new_axes, plot_transition_graph, plot_trajectories, plot_tube,
                      plot_workspace, save_figure)
from .spec import plot_specification

__all__ = ["new_axes", "plot_specification", "plot_transition_graph", "plot_trajectories", "plot_tube",
           "plot_workspace", "save_figure"]
