"""Every command the README and docs show runs as written.

Each line beginning with ``rsodb `` inside a ```bash fence of README.md or docs/*.md, and each
```rsodb ...``` example in a table row, runs in a shell, in order within its file, in a
directory laid out as the docs assume: the repository's ``data_samples/``, ``../shared/data``
beside it, an ``archive`` of the samples and of the real TOPEX pass with its periods stored, and
``configs/`` and a ``fit.toml`` with the repository's fit settings but a sampler of a few steps
(what the examples show is the command, not the result). Commands that a longer test already
runs as written are listed in `COVERED` and skipped here.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil
import subprocess
import tomllib

import pytest

from rsodb.archive import Archive
from rsodb.campaign.period_survey import survey_periods
from rsodb.fit.config import FitConfig
from rsodb.fit.runner import FitProblem, load_periods, shape_store_for
from tests.conftest import PROJECT_ROOT, TOPEX_PHV

DOCS = [PROJECT_ROOT / "README.md", *sorted((PROJECT_ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\s*$")
INLINE = re.compile(r"`(rsodb [^`]+)`")
# A fit short enough for an example: the commands are under test here, not the fit's result.
SHORT_SAMPLER = {
    "n_steps": 8,
    "search_popsize": 5,
    "search_maxiter": 2,
    "search_points": 30,
}
SHORT_DATA = {"max_points": 40}
# A model band of a few draws: each draw is a model curve over the whole pass (about 1 s on the
# real TOPEX pass), and the examples' plots need a band, not a smooth one.
SHORT_BAND_DRAWS = 4
# Commands another test runs exactly as the docs show them, or that are too long for the suite
# (the real-pass ladder is a 22-minute campaign; docs/real_passes.md records its run).
COVERED = {
    "rsodb pipeline data_samples --archive archive --out reports": "tests/test_pipeline_samples.py",
    "rsodb ladder --archive archive --config configs/real_passes.toml --ingest ../shared/data/observations "
    "--report ladders.html": "docs/real_passes.md (27 min)",
    "rsodb ladder --archive archive --config configs/real_passes.toml --ingest ../shared/data/observations "
    "--report reports/real_passes.html": "docs/real_passes.md (27 min)",
}
# Commands a file shows exactly as README.md does, on the same kind of archive, and after which the
# file runs nothing: README.md's run of them is the test (each costs 20-40 s of the suite).
SHOWN_IN_README = {
    "fitting.md": {
        "rsodb campaign --archive archive --object 22076 --config configs/short.toml --report topex_fits.html"
    },
}
# Files whose commands need the 22-minute real-pass campaign or a running Dask scheduler.
RUN_BY_HAND = {"real_passes.md": "its commands continue the 22-minute real-pass campaign and use a Dask scheduler"}
SECONDS_PER_COMMAND = 600


def shown_commands(path: Path) -> list[tuple[int, str]]:
    """(line number, command) of every ``rsodb`` line inside a bash fence of `path`, and of every
    inline ```rsodb ...``` in a table row."""
    commands, language = [], None
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        fence = FENCE.match(line.strip())
        if fence:
            language = fence.group(1) if language is None else None
            continue
        if language in ("bash", "sh", "console") and commands and commands[-1][1].endswith("\\"):
            commands[-1] = (commands[-1][0], commands[-1][1][:-1].rstrip() + " " + line.strip())
        elif language in ("bash", "sh", "console") and line.strip().startswith("rsodb "):
            commands.append((number, line.strip()))
        elif language is None and line.startswith("|"):
            commands.extend((number, command) for command in INLINE.findall(line))
    return commands


def bare(command: str) -> str:
    """A shown command without its trailing ``  # comment``."""
    return command.split("  #")[0].strip()


def _toml(record: dict, prefix: str = "") -> str:
    """A TOML text of a configuration record (tables, strings, numbers, booleans, inline tables)."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    lines = [f"{k} = {value(v)}" for k, v in record.items() if not isinstance(v, dict)]
    for k, v in record.items():
        if isinstance(v, dict):
            lines += ["", f"[{prefix}{k}]", _toml(v, f"{prefix}{k}.")]
    return "\n".join(lines)


def short_config(path: Path) -> str:
    """The fit configuration of `path` with a sampler of a few steps and few samples."""
    record = tomllib.loads(path.read_text())
    record["sampler"] = {**record.get("sampler", {}), **SHORT_SAMPLER}
    record["data"] = {**record.get("data", {}), **SHORT_DATA}
    record["band_draws"] = SHORT_BAND_DRAWS
    return _toml(record)


def test_the_docs_show_commands():
    shown = {path.name: shown_commands(path) for path in DOCS}
    assert len(shown["README.md"]) >= 12  # the command table and the main job
    assert sum(map(len, shown.values())) >= 30, shown


def test_commands_left_to_the_readme_are_the_readmes_own():
    readme = {bare(c) for _, c in shown_commands(PROJECT_ROOT / "README.md")}
    for name, commands in SHOWN_IN_README.items():
        shown = [bare(c) for _, c in shown_commands(PROJECT_ROOT / "docs" / name)]
        shown = [c for c in shown if c not in COVERED]
        assert commands <= readme and set(shown[-len(commands) :]) == commands, name


def test_short_configs_keep_every_other_setting():
    for config in (PROJECT_ROOT / "configs").glob("*.toml"):
        original = tomllib.loads(config.read_text())
        short = tomllib.loads(short_config(config))
        assert short["sampler"]["n_steps"] == SHORT_SAMPLER["n_steps"]
        assert short["band_draws"] == SHORT_BAND_DRAWS
        shortened = ("sampler", "data", "band_draws")
        assert {k: v for k, v in short.items() if k not in shortened} == {
            k: v for k, v in original.items() if k not in shortened
        }, config.name


@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_shown_commands_are_commands_not_synopses(path):
    """A synopsis (``[--json]``, ``csv|eossa``, ``N``) cannot run; the docs show real examples."""
    for number, command in shown_commands(path):
        text = command.split("  #")[0]
        assert not re.search(r"\[--|\w\|\w|<\w+>|~/", text), f"{path.name}:{number}: {command!r} is a synopsis"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, shared_data, shared_shapes):
    """The directory the docs' commands run in (see the module docstring)."""
    root = tmp_path_factory.mktemp("docs")
    work = root / "project"
    (work / "configs").mkdir(parents=True)
    (work / "data_samples").symlink_to(PROJECT_ROOT / "data_samples")
    (root / "shared").symlink_to(shared_data.parent)
    for config in (PROJECT_ROOT / "configs").glob("*.toml"):
        (work / "configs" / config.name).write_text(short_config(config))
    (work / "fit.toml").write_text(short_config(PROJECT_ROOT / "configs" / "short.toml"))
    archive = Archive(work / "archive")
    archive.ingest([PROJECT_ROOT / "data_samples", TOPEX_PHV], progress=False)
    survey_periods(archive, processes=1, progress=False)
    # The shape caches every file's fits share, built once here rather than once per file, in
    # the run's shared store (the paper mesh's cache is also a test's of the fast path).
    (work / "archive" / "shapes").symlink_to(shared_shapes, target_is_directory=True)
    config = FitConfig.from_toml(work / "fit.toml")
    for norad in (22076, 40358):
        stored = archive.passes(norad=norad)[0]
        FitProblem.build(stored, config, load_periods(archive, stored.pass_id), store=shape_store_for(archive))
    return work


@pytest.mark.slow
@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_shown_commands_run(path, workdir, tmp_path):
    if path.name in RUN_BY_HAND:
        pytest.skip(f"{path.name}: {RUN_BY_HAND[path.name]}")
    commands = [(n, c) for n, c in shown_commands(path) if bare(c) not in COVERED]
    again = SHOWN_IN_README.get(path.name, set())
    while commands and bare(commands[-1][1]) in again:
        commands.pop()  # only trailing ones: nothing after them in the file depends on them
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
