"""Issue 24: the radius bar has a total (the instances solved), which its updates reach."""

from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table


class Recorder:
    """A tqdm-like bar: ``total`` and the updates."""

    def __init__(self):
        self.total, self.updates, self.refreshed = None, [], 0

    def update(self, k):
        assert self.total is not None, "updated before the total was set"
        self.updates.append(k)

    def refresh(self):
        self.refreshed += 1


def solved(table) -> int:
    return table.n_instances - table.stats["n_translated"]


def test_highs_bar_total(corridor):
    dec, sysm, Z = corridor
    bar = Recorder()
    t = solve_radius_table(dec, sysm, Z=Z, options=RadiusTableOptions(form="tube", L_max=4), solver="highs",
                           progress=bar)
    assert bar.total == sum(bar.updates) == solved(t) > 0 and bar.refreshed


def test_pdhg_bar_total(corridor, pdhg_solvers):
    dec, sysm, Z = corridor
    bar = Recorder()
    t = solve_radius_table(dec, sysm, Z=Z, options=RadiusTableOptions(form="tube", L_max=10),
                           solver=pdhg_solvers["tube"], progress=bar)
    assert bar.total == sum(bar.updates) == solved(t) > 0
