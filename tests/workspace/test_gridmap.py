import numpy as np
import pytest

from tubejax.model.workspace import GridMapError, load_grid_map, parse_grid_map


def test_cell_geometry_numbering_and_labels():
    d = parse_grid_map("1.#\n.#2\n")
    assert d.n_cells == 4
    assert d.labels == ("1", None, None, "2")
    assert d.grid.tolist() == [[0, 0], [0, 1], [1, 0], [1, 2]]
    # cell (r, c) is [c, c+1] x [R-1-r, R-r] with R = 2 rows
    assert np.allclose(d.cells[0].vertices, [[0, 1], [1, 1], [1, 2], [0, 2]])
    assert np.allclose(d.cells[3].vertices, [[2, 0], [3, 0], [3, 1], [2, 1]])
    assert d.cells_with_label("2") == [3] and d.cells_with_label(2) == [3]


def test_free_and_obstacle_pairs():
    d = parse_grid_map("..\n#.\n")
    M = d.obstacle_case_matrix()
    assert not M[0, 1] and not M[1, 2]        # neighbours; hulls only touch the obstacle
    assert M[0, 2] and M[2, 0]                # the diagonal hull cuts the obstacle's corner
    assert not M.diagonal().any()


@pytest.mark.parametrize("text, match", [
    ("..\n...\n", r"line 2: ragged row of length 3, expected 2"),
    ("..\n.?\n", r"line 2, column 2: unknown character '\?'"),
    ("", r"the map is empty"),
    ("\n\n", r"the map is empty"),
    ("##\n##\n", r"no free cell"),
])
def test_bad_maps_are_refused_with_location(text, match):
    with pytest.raises(GridMapError, match=match):
        parse_grid_map(text, name="bad.txt")


def test_error_names_the_file(tmp_path):
    p = tmp_path / "m.txt"
    p.write_text("..\n.?\n")
    with pytest.raises(GridMapError, match=r"m\.txt, line 2, column 2"):
        load_grid_map(p)
    with pytest.raises(GridMapError, match="cannot read"):
        load_grid_map(tmp_path / "missing.txt")


def test_paper_map_has_67_free_cells_and_six_regions():
    from pathlib import Path

    d = load_grid_map(Path(__file__).resolve().parents[2] / "conf/workspace/maps/paper.txt")
    assert d.n_cells == 67
    for lab in "123456":
        assert len(d.cells_with_label(lab)) == 1


def test_non_utf8_map_names_the_file_line_and_column(tmp_path):
    p = tmp_path / "latin1.txt"
    p.write_bytes("..\n.\xe9\n".encode("latin-1"))
    with pytest.raises(GridMapError, match=r"latin1\.txt, line 2, column 2: not valid UTF-8 text \(byte 0xe9\)"):
        load_grid_map(p)


def test_directory_is_not_a_map(tmp_path):
    with pytest.raises(GridMapError, match="it is a directory"):
        load_grid_map(tmp_path)


def test_size_guard_names_the_limit():
    from tubejax.model.workspace.gridmap import MAX_GRID_CELLS

    with pytest.raises(GridMapError, match=rf"1 rows x {MAX_GRID_CELLS + 1} columns .* more than the limit of "
                                           rf"{MAX_GRID_CELLS}"):
        parse_grid_map("." * (MAX_GRID_CELLS + 1), name="huge.txt")
    assert parse_grid_map("." * 2000).n_cells == 2000            # the 1 x 2000 map is accepted


def test_grid_map_error_is_the_project_input_error():
    from tubejax.errors import InputError

    assert issubclass(GridMapError, InputError) and issubclass(GridMapError, ValueError)
