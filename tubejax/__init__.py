"""tubejax: robust safety controller synthesis with tubes (Hashimoto, Adachi, Dimarogonas), in Python/JAX.

``import tubejax as tj`` gives the main entry points (:mod:`tubejax.api`, :mod:`tubejax.api_control`)::

    ws = tj.grid_map("conf/workspace/maps/paper.txt")
    ts = tj.abstract(ws, tj.paper_system(radius=0.2))       # Algorithm 2, every edge verified
    sim = tj.simulate(ts, tj.plan(ts, [1, 3, 4, 5, 6]), runs=1000)
    print(sim.ok, tj.verify(ts).ok)

Workspaces: :func:`grid_map`, :func:`polygon_workspace`, :func:`box_grid`. Systems:
:class:`LinearSystem`, :func:`box_input_set`, :func:`one_norm_input_set`, :class:`Ball`,
:class:`Polytope`, :class:`Halfspaces`, :func:`paper_system`. Runs: :func:`abstract`, :func:`plan`,
:func:`simulate`, :func:`verify`, :func:`load`, :func:`export_controller`, :func:`limit`,
:func:`winning_set`; per axis group :func:`build_product_abstraction`, :func:`verify_product`
(docs/math/product.md). Figures: ``tj.plot``. Errors: :class:`InputError`, :class:`PlanningError`.
The names are imported on first use (PEP 562), so ``import tubejax.<module>`` stays light;
``tj.verify`` is always :func:`tubejax.api.verify`, even after ``tubejax/verify/`` was imported.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING

from .transitions.provenance import package_version

__version__ = package_version()

#: Public name -> the module that defines it (imported on first access, PEP 562).
_ENTRY_POINTS = {
    "abstract": "tubejax.api", "load": "tubejax.api", "limit": "tubejax.api", "winning_set": "tubejax.api",
    "plan": "tubejax.api_control", "simulate": "tubejax.api_control", "export_controller": "tubejax.api_control",
    "SimulationReport": "tubejax.api_control",
    "Workspace": "tubejax.api_inputs", "grid_map": "tubejax.api_inputs",
    "polygon_workspace": "tubejax.api_inputs", "box_grid": "tubejax.api_inputs",
    "paper_system": "tubejax.api_inputs",
    "LinearSystem": "tubejax.model.system", "box_input_set": "tubejax.model.system",
    "one_norm_input_set": "tubejax.model.system",
    "Ball": "tubejax.model.geometry", "Polytope": "tubejax.model.geometry", "Halfspaces": "tubejax.model.geometry",
    "TransitionSystem": "tubejax.transitions.transition_system", "VerifyReport": "tubejax.verify.verifier",
    "InputError": "tubejax.errors", "PlanningError": "tubejax.analyses.control",
    "build_product_abstraction": "tubejax.abstraction.product_abstraction", "ProductSystem": "tubejax.abstraction.product_abstraction",
    "verify_product": "tubejax.verify.product_check", "NotAProduct": "tubejax.model.product_structure",
}
#: Subpackages reachable as attributes (``tj.plot``) -> the package imported on first access.
_SUBMODULES = {"plot": "tubejax.analyses.plot"}

__all__ = ["__version__", "verify", *_ENTRY_POINTS, *_SUBMODULES]

if TYPE_CHECKING:                                       # for type checkers and IDEs; nothing runs here
    from .analyses import plot
    from .api import abstract, limit, load, verify, winning_set
    from .api_control import SimulationReport, export_controller, plan, simulate
    from .api_inputs import Workspace, box_grid, grid_map, paper_system, polygon_workspace
    from .analyses.control import PlanningError
    from .errors import InputError
    from .model.geometry import Ball, Halfspaces, Polytope
    from .model.system import LinearSystem, box_input_set, one_norm_input_set
    from .transitions.transition_system import TransitionSystem
    from .verify.verifier import VerifyReport
    from .abstraction.product_abstraction import ProductSystem, build_product_abstraction
    from .model.product_structure import NotAProduct
    from .verify.product_check import verify_product


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        value = getattr(importlib.import_module(_ENTRY_POINTS[name]), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(_SUBMODULES[name])
    else:
        raise AttributeError(f"module 'tubejax' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


class _Package(types.ModuleType):
    """The ``tubejax`` package, whose ``verify`` attribute is the API function, not the subpackage.

    Importing the subpackage ``tubejax.verify.verifier`` (or any module in it) would rebind ``tubejax.verify.verifier``
    to it; this data descriptor keeps the function (the subpackage stays in ``sys.modules``).
    """

    @property
    def verify(self):
        own = self.__dict__.get("_verify_function")
        return own if own is not None else importlib.import_module("tubejax.api").verify

    @verify.setter
    def verify(self, value) -> None:
        if not isinstance(value, types.ModuleType):      # the subpackage's binding is ignored; a patch is kept
            self.__dict__["_verify_function"] = value


sys.modules[__name__].__class__ = _Package
