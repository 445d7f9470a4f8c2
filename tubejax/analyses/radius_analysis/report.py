"""``radius.json`` (``experiments/radius.py``; layout: docs/reference/formats.md#radiusjson).

``rho_star`` of an instance is the estimate (HiGHS's value where ``exact`` is not ``null``), ``[lower,
upper]`` its bracket (``upper`` a rigorous float64 dual bound). With ``exact_curve`` the pairs' values
at ``L_max`` are HiGHS's, so ``n_edges`` is exact (to ~1e-9); smaller ``L_max`` use the engine's
estimates. ``systems`` lists the verified transition systems written at the requested radii: their
counts are HiGHS's verdicts, the authority where some ``rho*`` ties a radius, and replace the
curve's in ``n_edges_vs_L_max`` (``source`` ``"system"``).
"""

from __future__ import annotations

import numpy as np

from ...model.geometry import Ball
from ...transitions.file_format import json_safe
from .step_functions import StepFunction
from .systems import n_edges_vs_L_max
from .radius_table import RadiusTable

__all__ = ["RADIUS_FORMAT", "RADIUS_VERSION", "radius_document", "disturbance_units", "step_json",
           "radius_directory", "record_at_radius"]

RADIUS_FORMAT = "tubejax.radius"
RADIUS_VERSION = 1


def radius_directory(rho: float) -> str:
    """``'r<radius>'``: the shortest decimal that gives ``rho`` back (``r0.05``, ``r0.2``, ``r0``, ``r1e-05``)."""
    s = repr(float(rho))
    return "r" + (s[:-2] if s.endswith(".0") else s)


def record_at_radius(record: dict, rho: float, radius_of_inputs: float = 1.0) -> dict:
    """The inputs record ``record`` (:meth:`tubejax.inputs.ProblemInputs.record`) with ``W = rho W0``: a ball
    of radius ``rho``, a box of half-width ``rho``, or the polytope's vertices times ``rho / radius_of_inputs``
    (the record's ``W`` is ``radius_of_inputs W0``).

    Raises
    ------
    ValueError
        ``rho = 0`` for a box or polytope (the input model has no box or polytope of size 0).
    """
    rho = float(rho)
    d = dict(record["disturbance"])
    kind = d.get("kind")
    if kind == "ball":
        d["radius"] = rho
    elif rho <= 0:
        raise ValueError(f"radius {rho!r}: a {kind} disturbance of size 0 is not a valid W (its radii must be > 0; "
                         "W = {0} is disturbance=ball with radius 0)")
    elif kind == "box":
        d["half_width"] = rho
    elif kind == "polytope":
        d["vertices"] = (rho / float(radius_of_inputs) * np.asarray(d["vertices"], float)).tolist()
    else:
        raise ValueError(f"disturbance kind {kind!r} has no radius form")
    return {**record, "disturbance": d}


def step_json(step: StepFunction) -> dict:
    """``{"rho": [...], "n_edges": [...]}``."""
    return {"rho": step.rho.tolist(), "n_edges": step.n.tolist()}


def disturbance_units(W0, radius_of_inputs: float) -> dict:
    """What ``rho`` means: ``W = rho W0``."""
    if isinstance(W0, Ball):
        return {"W0": {"kind": "ball", "dim": W0.dim, "radius": W0.radius}, "unit": "the radius of the ball W",
                "radius_of_inputs": radius_of_inputs}
    unit = ("the half-width of the cube W" if W0.n_vertices == 2 ** W0.dim and np.allclose(np.abs(W0.vertices), 1.0)
            else "the scale factor of the polytope W of the inputs")
    return {"W0": {"kind": "polytope", "vertices": W0.vertices.tolist()}, "unit": unit,
            "radius_of_inputs": radius_of_inputs}


def _form_section(table: RadiusTable, radii) -> dict:
    crit = table.critical()
    Ls = list(range(1, table.L_max + 1))
    steps = [table.n_edges(L) for L in Ls]
    return {
        "instances": {"from": table.src, "to": table.dst, "L": table.L, "rho_star": table.value,
                      "lower": table.lower, "upper": table.upper,
                      "exact": [None if np.isnan(v) else v for v in table.exact.tolist()],
                      "status": table.status, "provenance": table.provenance},
        "pairs": {"from": crit.src, "to": crit.dst, "rho_star": crit.value, "lower": crit.lower,
                  "upper": crit.upper, "exact": crit.exact, "best_L": crit.best_L},
        "n_edges": step_json(steps[-1]),
        "n_edges_upper_bound": step_json(table.n_edges(which="upper")),
        "n_edges_by_L_max": {"L_max": Ls, "steps": [step_json(s) for s in steps]},
        "n_edges_vs_L_max": {"L_max": Ls, "radii": list(radii),
                             "n_edges": [[int(s(r)) for s in steps] for r in radii],
                             "source": ["curve"] * len(radii)},
        "stats": table.stats,
    }


def radius_document(tables: dict, inputs_record: dict | None, radius_of_inputs: float, radii=(),
                    systems: dict | None = None, stats: dict | None = None) -> dict:
    """The JSON-safe ``radius.json`` content (see the module docstring).

    Parameters
    ----------
    tables : dict of str -> RadiusTable
        One per form, same problem and ``L_max``.
    inputs_record : dict or None
    radius_of_inputs : float
        The radius the inputs give (``W = radius_of_inputs W0``).
    radii : sequence of float
        Radii at which ``n_edges`` against ``L_max`` is reported (the requested radii and the
        inputs' own).
    systems : dict of float -> (str, TransitionSystem), optional
        The verified systems written at requested radii, with their directories.
    """
    first = next(iter(tables.values()))
    radii = sorted(set(float(r) for r in radii))
    forms = {form: _form_section(t, radii) for form, t in tables.items()}
    for r, (_, ts) in (systems or {}).items():       # the verified systems' counts are the authority
        vs = forms.get(ts.method, {}).get("n_edges_vs_L_max")
        if vs is not None and float(r) in vs["radii"] and ts.stats.get("L_max") == first.L_max:
            k = vs["radii"].index(float(r))
            vs["n_edges"][k] = n_edges_vs_L_max(ts).tolist()
            vs["source"][k] = "system"
    return json_safe({
        "format": RADIUS_FORMAT, "version": RADIUS_VERSION, "inputs": inputs_record,
        "disturbance": disturbance_units(first.W0, float(radius_of_inputs)),
        "L_max": first.L_max, "radii": radii,
        "forms": forms,
        "systems": {repr(float(r)): {"directory": d, "method": ts.method, "n_edges": ts.n_edges,
                                     "n_edges_vs_L_max": n_edges_vs_L_max(ts).tolist(), "stats": ts.stats}
                    for r, (d, ts) in (systems or {}).items()},
        "stats": stats or {},
    })
