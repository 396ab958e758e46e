"""Every command the README and docs show runs as written.

Each line beginning with ``rsodb `` inside a ```bash fence of README.md or docs/*.md runs in a
shell, in order within its file, in a directory laid out as the docs assume: the repository's
``data_samples/`` and ``configs/``, ``../shared/data`` beside it, an ``archive`` of the samples and
of the real TOPEX pass with its periods stored, and a ``fit.toml`` (a short fit, so the fitting
examples finish in seconds; what they show is the command, not the result). A line that is
covered by a longer test says so in a comment ``# tested by tests/...`` and is skipped here.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil
import subprocess

import pytest

from rsodb.archive import Archive
from rsodb.campaign.period_survey import survey_periods
from tests.conftest import PROJECT_ROOT, TOPEX_PHV

DOCS = [PROJECT_ROOT / "README.md", *sorted((PROJECT_ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\s*$")
# A fit short enough for an example: the commands are under test here, not the fit's result.
EXAMPLE_FIT = """name = "default"
[data]
max_points = 40
[sampler]
n_walkers = 10
n_steps = 12
search_popsize = 6
search_maxiter = 3
search_points = 30
seed = 0
"""
SECONDS_PER_COMMAND = 600


def shown_commands(path: Path) -> list[tuple[int, str]]:
    """(line number, command) of every ``rsodb`` line inside a bash fence of `path`."""
    commands, language = [], None
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        fence = FENCE.match(line.strip())
        if fence:
            language = fence.group(1) if language is None else None
            continue
        if language in ("bash", "sh", "console") and line.strip().startswith("rsodb "):
            commands.append((number, line.strip()))
    return commands


def test_the_docs_show_commands():
    shown = {path.name: shown_commands(path) for path in DOCS}
    assert len(shown["README.md"]) >= 1
    assert sum(map(len, shown.values())) >= 10, shown


@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_shown_commands_are_commands_not_synopses(path):
    """A synopsis (``[--json]``, ``csv|eossa``, ``N``) cannot run; the docs show real examples."""
    for number, command in shown_commands(path):
        text = command.split("  #")[0]
        assert not re.search(r"\[--|\w\|\w|<\w+>|~/", text), f"{path.name}:{number}: {command!r} is a synopsis"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, shared_data):
    """The directory the docs' commands run in (see the module docstring)."""
    root = tmp_path_factory.mktemp("docs")
    work = root / "project"
    work.mkdir()
    for name in ("data_samples", "configs"):
        (work / name).symlink_to(PROJECT_ROOT / name)
    (root / "shared").symlink_to(shared_data.parent)
    archive = Archive(work / "archive")
    archive.ingest([PROJECT_ROOT / "data_samples", TOPEX_PHV], progress=False)
    survey_periods(archive, processes=1, progress=False)
    (work / "fit.toml").write_text(EXAMPLE_FIT)
    return work


@pytest.mark.slow
@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_shown_commands_run(path, workdir, tmp_path):
    commands = [(n, c) for n, c in shown_commands(path) if "# tested by tests/" not in c]
    if not commands:
        pytest.skip(f"{path.name} shows no command to run here")
    # Each file runs in its own copy, so one file's commands cannot depend on another's.
    work = tmp_path / "project"
    shutil.copytree(workdir, work, symlinks=True)
    (tmp_path / "shared").symlink_to(os.readlink(workdir.parent / "shared"))
    environment = dict(os.environ, PATH=f"{Path(os.sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    environment.pop("RSODB_ARCHIVE", None)
    for number, command in commands:
        done = subprocess.run(
            ["bash", "-c", command],
            cwd=work,
            env=environment,
            capture_output=True,
            text=True,
            timeout=SECONDS_PER_COMMAND,
        )
        assert done.returncode == 0, (
            f"{path.name}:{number}: {command!r} exited {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
        )
