"""Two ingests of overlapping file sets and a reader, as three separate processes, at once.

Neither ingest may lose the other's passes, a file both ingest is stored once, and the reader,
which rereads the whole archive in a loop while they run, must only ever see complete passes
equal to their source files.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

import ingest
from ingest.observation import ARRAY_FIELDS
from rsodb.archive import Archive
from rsodb.samples.synthetic import write_synthetic_corpus
from tests.test_archive_crash import Worker


@pytest.mark.slow
def test_two_ingests_and_a_reader_at_once(tmp_path):
    paths = write_synthetic_corpus(tmp_path / "corpus", n_files=120, n_points=600, n_objects=6, seed=11)
    archive = tmp_path / "archive"
    manifest = tmp_path / "manifest.json"
    manifest.write_text(json.dumps([str(path) for path in paths]))
    stop = tmp_path / "stop"

    reader = Worker("read", str(archive), str(manifest), str(stop))
    # Both start together once each has imported, and pause after every commit, so they overlap
    # whatever else the machine is doing (without the gate one spawned reader pool started a
    # second late on a loaded machine and the first ingest had finished).
    go = tmp_path / "go"
    options = ("--workers", "1", "--interval", "0.01", "--start-after", str(go), "--commit-pause", "0.05")
    first = Worker("ingest", str(archive), *map(str, paths[:80]), *options)
    second = Worker("ingest", str(archive), *map(str, paths[40:]), *options)
    assert first.started.wait(120) and second.started.wait(120)
    go.touch()
    assert first.finish() == 0 and second.finish() == 0, first.process.stderr.read() + second.process.stderr.read()
    stop.touch()  # the reader makes one more round, over the final state
    assert reader.finish() == 0, "\n".join(line for line in reader.lines if line.startswith("ERROR"))

    reports = [
        json.loads(next(line for line in worker.lines if line.startswith("DONE"))[5:]) for worker in (first, second)
    ]
    ingested = [item["path"] for report in reports for item in report["ingested"]]
    present = [path for report in reports for path in report["already_present"]]
    # Each of the 40 shared files was stored by exactly one of the two ingests.
    assert sorted(ingested) == sorted(map(str, paths))
    assert len(present) == 40 and set(present) <= set(map(str, paths[40:80]))
    # Both ingests really ran at the same time: each committed while the other was committing.
    first_times, second_times = first.commit_times_s(), second.commit_times_s()
    assert min(first_times) < max(second_times) and min(second_times) < max(first_times)
    assert len(first_times) + len(second_times) > 6

    rounds, checked = map(int, next(line for line in reader.lines if line.startswith("DONE")).split()[1:])
    assert rounds >= 3 and checked > 0, reader.lines[-3:]
    reads = [int(line.split()[1]) for line in reader.lines if line.startswith("READ")]
    assert reads == sorted(reads), "the reader saw passes disappear"
    assert reads[-1] == 120

    final = Archive(archive)
    stored = final.passes()
    assert len(stored) == 120 == len({p.source_sha256 for p in stored})
    for path in paths:
        sha = hashlib.sha256(path.read_bytes()).hexdigest()
        (original,) = ingest.read_file(path)
        (match,) = [p for p in stored if p.source_sha256 == sha]
        for name in ARRAY_FIELDS:
            np.testing.assert_array_equal(getattr(match, name), getattr(original, name), err_msg=name)
