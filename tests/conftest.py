import shutil
from pathlib import Path

import pytest

from odomgraph.io.log import write_log
from odomgraph.sim.scenarios import paper
from odomgraph.sim.simulate import simulate


@pytest.fixture(scope="session")
def paper_log():
    """The paper scenario, seed 3, as a Log (in memory)."""
    return simulate(paper(), 3)


@pytest.fixture(scope="session")
def paper_log_dir(tmp_path_factory, paper_log):
    """The same log written to disk (treat as read-only)."""
    d = tmp_path_factory.mktemp("logs") / "paper3"
    write_log(paper_log, d)
    return d


@pytest.fixture
def log_copy(tmp_path, paper_log_dir):
    """A private copy of the paper log directory, safe to corrupt."""
    d = tmp_path / "log"
    shutil.copytree(paper_log_dir, d)
    return d


def replace_line(path: Path, lineno: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[lineno - 1] = text
    path.write_text("\n".join(lines) + "\n")
