"""Figures (matplotlib): workspace, tubes, trajectories, transition graph, sweeps, radius curves.

:func:`save_figure` writes PNG + PDF inside :func:`figure_style`. 3-D workspaces of boxes
(:func:`is_layered`) are drawn layer by layer and in 3-D (:func:`figures_3d`); a state space lifted
from such a map (a drone) in its position projection (:func:`drawn_space`).
"""

from .figures import plot_tube, plot_workspace
from .graph import plot_transition_blocks, plot_transition_graph, plot_transition_graph_layers
from .layer_runs import plot_specification_layers, plot_trajectories_layers
from .layers import drawn_space, is_layered, plot_workspace_layers
from .spec import plot_specification
from .style import FIGURE_RC, figure_style, new_axes, paper_style, save_figure
from .trajectories import RunsStyle, plot_trajectories, select_runs
from .view3d import figures_3d, plot_plan_tubes_3d, plot_tube_3d

__all__ = ["FIGURE_RC", "figure_style", "new_axes", "plot_specification", "plot_transition_graph",
           "plot_trajectories", "RunsStyle", "plot_tube", "plot_workspace", "save_figure", "select_runs",
           "figures_3d", "is_layered", "plot_plan_tubes_3d", "plot_specification_layers",
           "plot_trajectories_layers", "plot_tube_3d", "plot_workspace_layers", "paper_style",
           "plot_transition_blocks", "plot_transition_graph_layers", "drawn_space"]
