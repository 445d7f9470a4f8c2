"""Figures (matplotlib): workspace, tubes, trajectories, transition graph.

:func:`save_figure` writes PNG + PDF inside :func:`figure_style` (TrueType fonts in the PDF).

Modules: :mod:`~tubejax.analyses.plot.style` (figure style, fresh axes, saving),
:mod:`~tubejax.analyses.plot.figures` (workspace, tube), :mod:`~tubejax.analyses.plot.graph`
(the transition graph, by blocks of cells when large, per layer in 3-D),
:mod:`~tubejax.analyses.plot.trajectories` (closed-loop runs), :mod:`~tubejax.analyses.plot.spec`
(a temporal specification), :mod:`~tubejax.analyses.plot.state_constraints` (state constraints
hatched), :mod:`~tubejax.analyses.plot.sweeps` (parameter sweeps) and
:mod:`~tubejax.analyses.plot.radius_curves` (``radius.json``).

3-D workspaces of boxes (voxel maps, 3-D box grids; :func:`is_layered`) are drawn layer by layer
instead of projected onto ``(x_1, x_2)``: :mod:`~tubejax.analyses.plot.layers` (the layers, the
workspace in one panel per layer, paths cut at the layers), :mod:`~tubejax.analyses.plot.layer_runs`
(Figs. 7 and 8 per layer) and :mod:`~tubejax.analyses.plot.view3d` (the tubes in 3-D: Fig. 6 and
the plan's tubes, ``fig9_tubes3d``; :func:`figures_3d` lists the figures of a 3-D run). A state
space lifted from such a map (a drone, ``workspace.velocity_divisions``) is drawn over the map in
its position projection (:func:`drawn_space`).
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
