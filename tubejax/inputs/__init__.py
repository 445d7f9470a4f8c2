"""One typed input model, validated at the boundary (pydantic v2, strict).

Every value a user gives passes through these models; errors are
:class:`~tubejax.errors.InputModelError` naming the field, the value and what was expected. Each
model builds its library object (``ProblemInputs.build_decomposition()``, ``SystemModel.build(W)``,
...), and ``ProblemInputs.record()`` / :func:`from_record` give a versioned provenance record.
Nothing here reads a Hydra config (``experiments/common.py`` passes a plain dict).
"""

from .dynamics import (BallDisturbance, BoxDisturbance, Disturbance, InputSet, PolytopeDisturbance, SystemModel,
                       UBox, UOneNorm, UPolytope)
from .problem_inputs import RECORD_VERSION, ProblemInputs, from_record, validate_section
from .app_settings import BudgetSettings, FigureSettings, RadiusFigureSettings
from .settings import (ZSHAPE_SCALE_RANGE, AbstractionSettings, HighsSolverSettings, PdhgSolverSettings,
                       SimulationSettings, SolverSettings, SpecSettings, ZShapeSettings)
from .workspace_sources import BoxGridSource, FileRef, GridMapSource, PolygonFileSource, WorkspaceSource
from .values import MAX_MAGNITUDE

__all__ = [
    "AbstractionSettings", "BallDisturbance", "BudgetSettings", "BoxDisturbance", "BoxGridSource", "Disturbance", "FigureSettings",
    "FileRef", "GridMapSource", "HighsSolverSettings", "InputSet", "MAX_MAGNITUDE", "PdhgSolverSettings",
    "PolygonFileSource", "PolytopeDisturbance", "ProblemInputs", "RECORD_VERSION", "RadiusFigureSettings",
    "SimulationSettings", "SolverSettings", "SpecSettings", "SystemModel", "UBox", "UOneNorm", "UPolytope",
    "WorkspaceSource", "ZSHAPE_SCALE_RANGE", "ZShapeSettings", "from_record", "validate_section",
]
