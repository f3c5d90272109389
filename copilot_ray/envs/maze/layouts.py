"""Maze layouts: occupancy grids over the unit square, parsed from text files or generated.

A layout file has one line per row of square cells, from the TOP of the unit square down; `#` is an
obstacle and `.` is free. The border of the unit square is itself a wall, so files need no `#` border.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

OBSTACLE = "#"
FREE = "."
RANDOM_PREFIX = "random15-"
_RANDOM_RE = re.compile(r"^random15-(\d+)$")


class LayoutError(ValueError):
    """A layout that cannot be used; the message names the source, line and column (1-based)."""

    def __init__(self, source: str, line: int, column: int, reason: str):
        super().__init__(f"{source}:{line}:{column}: {reason}")
        self.source, self.line, self.column, self.reason = source, line, column, reason


class BodyDoesNotFitError(LayoutError):
    """An agent's body fits nowhere in a layout (the message names the agent, its body and the layout)."""

    def __init__(self, source: str, reason: str):
        ValueError.__init__(self, f"{source}: {reason}")
        self.source, self.line, self.column, self.reason = source, 0, 0, reason


@dataclass(frozen=True)
class Layout:
    """An occupancy grid: `grid[r, c]` is True where cell (row r from the top, column c) is an obstacle."""

    name: str
    grid: np.ndarray = field(repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid.shape

    @property
    def cell_size(self) -> tuple[float, float]:
        """(width, height) of one cell in unit-square coordinates."""
        rows, cols = self.grid.shape
        return 1.0 / cols, 1.0 / rows

    def to_text(self) -> str:
        return "\n".join("".join(OBSTACLE if v else FREE for v in row) for row in self.grid) + "\n"


def parse_layout(text: str, source: str = "<string>") -> Layout:
    """Parse layout text; any defect raises LayoutError pointing at the offending line and column."""
    lines = text.splitlines()
    while lines and lines[-1].strip() == "":  # a trailing newline (or several) is not a row
        lines.pop()
    if not lines:
        raise LayoutError(source, 1, 1, "empty layout: no rows")
    width = len(lines[0])
    for i, line in enumerate(lines, start=1):
        for j, ch in enumerate(line, start=1):
            if ch not in (OBSTACLE, FREE):
                raise LayoutError(source, i, j, f"invalid character {ch!r}; use '#' (obstacle) or '.' (free)")
        if len(line) != width:
            column = min(len(line), width) + 1
            raise LayoutError(
                source, i, column, f"ragged row: {len(line)} cells, but row 1 has {width}; rows must be equal"
            )
    if width == 0:
        raise LayoutError(source, 1, 1, "empty layout: rows have no cells")
    grid = np.array([[ch == OBSTACLE for ch in line] for line in lines], dtype=bool)
    if grid.all():
        raise LayoutError(source, 1, 1, "layout has no free cell")
    return Layout(name=source, grid=grid)


def builtin_layout_names() -> list[str]:
    """Names of the shipped layout files (random mazes come on top as `random15-<seed>`)."""
    folder = resources.files(__package__) / "layouts"
    return sorted(p.name[: -len(".txt")] for p in folder.iterdir() if p.name.endswith(".txt"))


def load_layout(name_or_path: str | Path | Layout) -> Layout:
    """A built-in name, `random15-<seed>`, or a path to a layout file."""
    if isinstance(name_or_path, Layout):
        return name_or_path
    spec = str(name_or_path)
    match = _RANDOM_RE.match(spec)
    if match:
        return random_maze(int(match.group(1)))
    if spec in builtin_layout_names():
        text = (resources.files(__package__) / "layouts" / f"{spec}.txt").read_text()
        return parse_layout(text, source=spec)
    path = Path(spec)
    if path.is_file():
        layout = parse_layout(path.read_text(), source=str(path))
        return layout
    raise ValueError(
        f"layout {spec!r} is neither a built-in layout nor an existing file; built-ins: "
        f"{', '.join(builtin_layout_names())}, {RANDOM_PREFIX}<seed>"
    )


def random_maze(seed: int, cells: int = 8, extra_openings: int = 6) -> Layout:
    """A seeded perfect maze (randomized depth-first search) with a few extra openings for loops.

    Lattice cells sit on even grid indices and walls on odd ones, so `cells=8` gives a 15 x 15 grid
    (NEXT's size) without a redundant outer `#` ring: the unit square's border is already a wall.
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x4D415A45]))  # "MAZE"
    size = 2 * cells - 1
    grid = np.ones((size, size), dtype=bool)
    grid[::2, ::2] = False  # lattice cells are free
    visited = np.zeros((cells, cells), dtype=bool)
    stack = [(int(rng.integers(cells)), int(rng.integers(cells)))]
    visited[stack[0]] = True
    while stack:
        r, c = stack[-1]
        nbrs = [
            (r + dr, c + dc)
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1))
            if 0 <= r + dr < cells and 0 <= c + dc < cells and not visited[r + dr, c + dc]
        ]
        if not nbrs:
            stack.pop()
            continue
        nr, nc = nbrs[int(rng.integers(len(nbrs)))]
        grid[r + nr, c + nc] = False  # knock down the wall between the two cells (2r + dr = r + nr)
        visited[nr, nc] = True
        stack.append((nr, nc))
    # Remaining walls between two lattice cells: exactly one of (row, col) is odd.
    rr, cc = np.nonzero(grid)
    between = (rr % 2) != (cc % 2)
    candidates = np.stack([rr[between], cc[between]], axis=1)
    if len(candidates) and extra_openings > 0:
        pick = rng.choice(len(candidates), size=min(extra_openings, len(candidates)), replace=False)
        grid[candidates[pick, 0], candidates[pick, 1]] = False
    return Layout(name=f"{RANDOM_PREFIX}{seed}", grid=grid)
