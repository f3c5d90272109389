"""Layout parsing, its error messages, built-ins and random mazes."""

from collections import deque

import numpy as np
import pytest

from copilot_ray.envs.maze import LayoutError, builtin_layout_names, load_layout, parse_layout, random_maze


def test_parse_orientation_and_shape():
    layout = parse_layout("#..\n...\n", source="x.txt")
    assert layout.shape == (2, 3)
    assert layout.grid[0, 0] and not layout.grid[1, 0]  # row 0 is the top row
    assert layout.to_text() == "#..\n...\n"


@pytest.mark.parametrize(
    ("text", "line", "column", "words"),
    [
        ("...\n.x.\n", 2, 2, "invalid character 'x'"),
        ("...\n.. \n", 2, 3, "invalid character ' '"),
        ("...\n..\n", 2, 3, "ragged"),
        ("...\n....\n", 2, 4, "ragged"),
        ("...\n\n...\n", 2, 1, "ragged"),
        ("", 1, 1, "empty"),
        ("\n\n", 1, 1, "empty"),
        ("##\n##\n", 1, 1, "no free cell"),
    ],
)
def test_parse_errors_name_file_line_column(tmp_path, text, line, column, words):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(LayoutError) as err:
        load_layout(str(path))
    message = str(err.value)
    assert f"{path}:{line}:{column}:" in message
    assert words in message
    assert (err.value.line, err.value.column) == (line, column)
    assert isinstance(err.value, ValueError)


def test_layout_file_round_trip(tmp_path):
    path = tmp_path / "mine.txt"
    path.write_text(".#.\n...\n")
    layout = load_layout(path)
    assert layout.name == str(path) and layout.grid.sum() == 1


def test_unknown_layout_name_lists_builtins():
    with pytest.raises(ValueError, match="no-such-maze.*four-rooms.*random15-<seed>"):
        load_layout("no-such-maze")


def test_builtins_parse():
    names = builtin_layout_names()
    assert {"empty", "u-maze", "four-rooms", "spiral"} <= set(names)
    for name in names:
        assert not load_layout(name).grid.all()


def _connected(grid: np.ndarray) -> bool:
    free = list(zip(*np.nonzero(~grid), strict=True))
    seen, todo = {free[0]}, deque([free[0]])
    while todo:
        r, c = todo.popleft()
        for nb in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
            if 0 <= nb[0] < grid.shape[0] and 0 <= nb[1] < grid.shape[1] and not grid[nb] and nb not in seen:
                seen.add(nb)
                todo.append(nb)
    return len(seen) == len(free)


def test_random_mazes_are_seeded_connected_and_15x15():
    a, b, c = random_maze(7), load_layout("random15-7"), random_maze(8)
    np.testing.assert_array_equal(a.grid, b.grid)
    assert not np.array_equal(a.grid, c.grid)
    for seed in range(5):
        grid = random_maze(seed).grid
        assert grid.shape == (15, 15) and _connected(grid)
        # A spanning tree over 64 cells opens 63 walls; the extra openings make loops.
        assert (~grid).sum() > 64 + 63
