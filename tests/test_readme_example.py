"""The README's notebook example runs as written, on an archive of the bundled samples."""

import os
import re

import pytest

import rsodb
from tests.conftest import PROJECT_ROOT

MARKER = "<!-- notebook-example"


def readme_example() -> str:
    text = (PROJECT_ROOT / "README.md").read_text()
    after = text[text.index(MARKER) :]
    return re.search(r"```python\n(.*?)```", after, re.S).group(1)


def test_the_example_uses_only_the_front_doors():
    code = readme_example()
    imports = re.findall(r"^(?:from|import) (\S+)", code, re.M)
    assert set(imports) <= {"rsodb", "raycast", "ingest"}
    assert len(code.strip().splitlines()) <= 16


@pytest.mark.slow
def test_the_readme_example_runs(tmp_path, capsys):
    rsodb.Archive(tmp_path / "archive").ingest([PROJECT_ROOT / "data_samples"], progress=False)
    (tmp_path / "configs").symlink_to(PROJECT_ROOT / "configs")
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        exec(compile(readme_example(), "README.md", "exec"), {})
    finally:
        os.chdir(cwd)
    printed = capsys.readouterr().out
    # The period search finds TOPEX's apparent period (9.8207 s in data_samples/README.md).
    assert re.search(r"P = 9\.8\d+ \+- ", printed), printed
    assert "spin_period_s" in printed
