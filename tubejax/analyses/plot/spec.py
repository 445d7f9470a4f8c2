"""Figure of a temporal specification: trajectories, avoided regions shaded, the product plan."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch, Patch

from ..spec.regions import region_pieces
from .figures import _poly2d, plot_workspace
from .constraint_layer import outside_text, system_constraints
from .style import PALETTE, paper_style
from .trajectories import RUN_COLOURS, _chosen, _draw_runs

__all__ = ["plot_specification", "spec_legend", "spec_title", "spec_regions", "spec_violations",
           "region_styles"]


def plot_specification(ts, spec_plan, simulation=None, ax=None, max_runs: int | None = 50,
                       seed: int | None = None, density: bool = True):
    """Trajectories over the map with the avoided regions shaded and the plan drawn (arrows: its direction).

    Regions are drawn as they are defined (:mod:`tubejax.analyses.spec.regions`): their cells, or
    on a box grid the label boxes themselves, also where they cut through cells.

    Parameters
    ----------
    ts : TransitionSystem
    spec_plan : SpecPlan
        From :func:`tubejax.analyses.spec.plan_formula`, :func:`~tubejax.analyses.spec.plan_patrol`, ...
    simulation : SpecSimulation, optional
        Runs to draw (``trajectories (runs, T+1, n)``; first two coordinates); runs that
        violate the specification, leave their tubes or a state constraint are red.
    ax : Axes, optional
    max_runs, seed, density :
        As in :class:`~tubejax.analyses.plot.trajectories.RunsStyle` (``seed`` default: the simulation's).

    Returns
    -------
    Axes
        Its title says how many runs of how many are drawn.
    """
    d = ts.decomposition
    ax = plot_workspace(d, ax, state_constraints=system_constraints(ts), labels_aside=True)
    for name, labels, style in region_styles(spec_plan):
        polys = [_poly2d(P) for _, P in region_pieces(d, sorted(labels))]   # the regions as named
        if polys:
            ax.add_collection(PolyCollection(polys, zorder=3, label=name, **style))
    caption = None
    if simulation is not None:
        chosen = _chosen(simulation.result, max_runs, seed, spec_violations(simulation))
        caption = _draw_runs(ax, np.asarray(simulation.trajectories)[:, :, :2], chosen, d.bounds(), density,
                             ends=("start",))[2]
    C = np.array([d.cells[c].centroid[:2] for c in spec_plan.plan.cells])
    for a, b in zip(C[:-1], C[1:]):
        ax.add_patch(FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=9, color="black",
                                     linewidth=1.2, connectionstyle="arc3,rad=0.12", zorder=9))
    ax.plot(C[:1, 0], C[:1, 1], "o", color="black", ms=5, zorder=10)
    ax.legend(handles=spec_legend(spec_plan, simulation is not None), loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=3,
              fontsize=7, frameon=False)
    ax.set_title(spec_title(spec_plan, simulation, caption), fontsize=8)
    return ax


def spec_regions(spec_plan) -> tuple[set, set]:
    """``(avoided labels, specified labels)`` of a specification (the regions it names besides those avoided)."""
    avoid = {str(a) for a in spec_plan.avoid}
    return avoid, {str(label) for label in spec_plan.dfa.labels} - avoid


def region_styles(spec_plan) -> list:
    """``[(name, labels, style), ...]``: the avoided and the specified regions of a specification
    (:func:`spec_regions`) as the figures shade them (colour-blind-safe palette) and name them."""
    return [(name, labels, dict(facecolor=PALETTE[c], edgecolor=PALETTE[c], alpha=0.35, linewidth=1.0, hatch=hatch))
            for name, labels, c, hatch in zip(("avoided region", "specified region"), spec_regions(spec_plan),
                                              ("vermillion", "green"), ("//", None))]


def spec_violations(simulation) -> np.ndarray:
    """The runs ``(runs,)`` of a specification's simulation that fail it or enter an avoided region."""
    return ~np.asarray(simulation.check.satisfied) | np.asarray(simulation.check.avoided_entry)


def spec_legend(spec_plan, runs: bool = True) -> list:
    """The legend entries of a specification figure, each drawn as the figure draws it: the avoided and
    specified regions (shaded; each only when the specification has one), the plan (a black line with an
    arrowhead, from a black dot) and the runs."""
    return [*(Patch(label=name, **style) for name, labels, style in region_styles(spec_plan) if labels),
            Line2D([], [], color="black", lw=1.2, marker=">", ms=5, label=f"plan ({spec_plan.plan.cost} steps)"),
            Line2D([], [], ls="none", marker="o", color="black", ms=5, label="plan start"),
            *([Line2D([], [], color=RUN_COLOURS["run"], lw=1.0, label="run")] if runs else [])]


def spec_title(spec_plan, simulation, caption: str) -> str:
    """The title of a specification figure: the specification and, with runs (``draft`` style), their
    counts; in the ``paper`` style one line."""
    title = f"{spec_plan.spec}"
    if paper_style():
        return title + (f" ({simulation.summary()['runs']} runs)" if simulation is not None else "")
    if simulation is not None:
        s = simulation.summary()
        title += (f"\n{s['runs']} runs ({s['mode']}): {s['runs_satisfying_spec']} satisfy, "
                  f"{s['avoided_region_entries']} avoided-region entries, {s['obstacle_entries']} "
                  f"obstacle entries, {s['tube_exits']} tube exits{outside_text(s)}\n{caption}")
    return title
