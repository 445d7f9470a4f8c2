"""Shared problems and rho* tables of the radius-analysis tests (session scope: one compile per form)."""

import numpy as np
import pytest

from tubejax.abstraction import cross_sections
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import load_grid_map

FORMS = ("tube", "openloop")


@pytest.fixture(scope="session")
def corridor(corridor_path):
    """``(decomposition, system at r = 0.2, Z)`` of the validation corridor map."""
    dec = load_grid_map(corridor_path)
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return dec, sysm, cross_sections(dec, "box", 1.0)


@pytest.fixture(scope="session")
def pdhg_solvers():
    """The batched engine per form (one padded horizon, one width: one executable per form)."""
    from tubejax.lp.batch.batch_solver import pdhg_solver

    return {form: pdhg_solver(form, radius=True, pool=64, min_bucket=64, l_buckets=(10,)) for form in FORMS}


@pytest.fixture(scope="session")
def pdhg_tables(corridor, pdhg_solvers):
    """The batched engine's tables."""
    from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table

    dec, sysm, Z = corridor
    return {form: solve_radius_table(dec, sysm, Z=Z, options=RadiusTableOptions(form=form, L_max=10),
                                     solver=pdhg_solvers[form])
            for form in FORMS}


@pytest.fixture(scope="session")
def highs_tables(corridor):
    """The reference: HiGHS's rho* of every candidate, one solve per translation class (each translate's
    value is checked against its own HiGHS solve in test_radius_table.py)."""
    from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table

    dec, sysm, Z = corridor
    return {form: solve_radius_table(dec, sysm, Z=Z, solver="highs", options=RadiusTableOptions(form=form, L_max=10))
            for form in FORMS}
