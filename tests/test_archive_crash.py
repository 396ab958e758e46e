"""Crash safety for real: SIGKILL an ingesting process at random moments, many times.

After every kill the archive must open, hold no temporary files, hold every pass the worker had
reported committed, and every stored pass must equal a fresh read of its source file, array for
array; no file may be stored twice. Finally an uninterrupted run completes the archive.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import threading
import time

import h5py
import numpy as np
import pytest

import ingest
from ingest.observation import ARRAY_FIELDS
from rsodb.archive import Archive, layout
from rsodb.samples.synthetic import write_synthetic_corpus

WORKER = Path(__file__).with_name("archive_worker.py")
N_KILLS = 20
SEED = 20261122


class Worker:
    """An ingest subprocess in its own process group, its stdout collected by a thread."""

    def __init__(self, *args: str):
        self.process = subprocess.Popen(
            [sys.executable, str(WORKER), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        self.lines: list[str] = []
        self.received_s: list[float] = []  # monotonic time each line arrived
        self.started = threading.Event()
        self.began = threading.Event()  # set at each BEGIN line
        self.thread = threading.Thread(target=self._collect, daemon=True)
        self.thread.start()

    def _collect(self) -> None:
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))
            self.received_s.append(time.monotonic())
            if line.startswith("START"):
                self.started.set()
            if line.startswith("BEGIN"):
                self.began.set()
        self.started.set()
        self.began.set()

    def kill(self) -> None:
        try:
            os.killpg(self.process.pid, signal.SIGKILL)  # the worker and its reader processes
        except ProcessLookupError:
            pass
        self.finish()

    def finish(self, timeout_s: float = 120.0) -> int:
        code = self.process.wait(timeout=timeout_s)
        self.thread.join(timeout=10.0)
        return code

    def commit_times_s(self) -> list[float]:
        """When each reported commit arrived."""
        return [t for line, t in zip(self.lines, self.received_s) if line.startswith("{")]

    def committed(self) -> dict[str, list[str]]:
        """Source path -> pass ids of every commit the worker reported."""
        result = {}
        for line in self.lines:
            if line.startswith("{"):
                for path, pass_ids in json.loads(line)["files"]:
                    result[path] = pass_ids
        return result

    def killed_mid_commit(self) -> bool:
        """True when the last thing the worker announced was the start of a commit."""
        tail = [line for line in self.lines if line.startswith(("BEGIN", "{"))]
        return bool(tail) and tail[-1].startswith("BEGIN")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """240 files of 600 rows over 12 objects, and the passes a fresh read gives, by SHA-256."""
    directory = tmp_path_factory.mktemp("corpus")
    paths = write_synthetic_corpus(directory, n_files=240, n_points=600, n_objects=12, seed=SEED)
    expected = {}
    for path in paths:
        (expected[hashlib.sha256(path.read_bytes()).hexdigest()],) = ingest.read_file(path)
    return directory, paths, expected


def temp_files(archive: Path) -> list[Path]:
    """Temporary files a killed ingest left: beside the object files, or staged by its readers."""
    objects, staging = archive / layout.OBJECTS_DIR, archive / layout.STAGING_DIR
    found = list(objects.glob(".*.tmp")) if objects.is_dir() else []
    return found + (list(staging.glob("*/*.tmp")) if staging.is_dir() else [])


def check_archive(path: Path, committed: dict[str, list[str]], expected: dict) -> int:
    """Everything the crash guarantee promises; returns the number of stored passes."""
    archive = Archive(path)  # opening removes what killed writers left behind
    assert not [name for name in os.listdir(archive.objects_dir) if name.endswith(".tmp")]
    staging = path / layout.STAGING_DIR
    assert not staging.is_dir() or not os.listdir(staging), "a killed run's staged files were left"
    rows = archive.summaries(all_versions=True)
    # The index, however the kill left it, answers what the object files hold.
    on_disk = set()
    for object_file in archive.objects_dir.glob("*.h5"):
        with h5py.File(object_file, "r") as file:
            on_disk |= {row.pass_id for row in layout.read_catalog(file)}
    assert {row.pass_id for row in rows} == on_disk
    shas = [row.source_sha256 for row in rows]
    assert len(shas) == len(set(shas)), "a file was stored twice"
    stored_ids = {row.pass_id for row in rows}
    for source, pass_ids in committed.items():
        assert set(pass_ids) <= stored_ids, f"{source} was reported committed but is missing"
    for stored in archive.passes(all_versions=True):
        original = expected[stored.source_sha256]
        for name in ARRAY_FIELDS:
            np.testing.assert_array_equal(getattr(stored, name), getattr(original, name), err_msg=name)
        assert stored.version == 1 and stored.pass_id.startswith(str(stored.norad))
    return len(rows)


@pytest.mark.slow
def test_sigkill_at_random_moments_loses_nothing_committed(corpus, tmp_path):
    directory, paths, expected = corpus
    archive = tmp_path / "archive"
    rng = np.random.default_rng(SEED)
    committed: dict[str, list[str]] = {}
    kills = mid_commit = left_temp_files = restarts = 0
    stored = 0
    while kills < N_KILLS:
        worker = Worker("ingest", str(archive), str(directory), "--workers", "1", "--interval", "0.02")
        assert worker.started.wait(60.0), "the worker did not start"
        if kills % 2:
            time.sleep(rng.uniform(0.0, 0.8))
        else:
            # Every other kill lands just after a commit began, while its new file is being
            # written, so the temporary-file path is exercised on every run, fast or slow.
            time.sleep(rng.uniform(0.0, 0.3))
            worker.began.clear()
            worker.began.wait(30.0)
            time.sleep(rng.uniform(0.0, 0.01))
        worker.kill()
        kills += 1
        mid_commit += worker.killed_mid_commit()
        left_temp_files += bool(temp_files(archive))
        committed.update(worker.committed())
        now = check_archive(archive, committed, expected)
        assert now >= stored, "a kill lost passes stored earlier"
        stored = now
        if any(line.startswith("DONE") for line in worker.lines):
            # It finished before the kill (a fast machine): start again from an empty archive.
            shutil.rmtree(archive)
            committed, stored = {}, 0
            restarts += 1
    # The seeded delays must really have interrupted commits, not only parsing.
    assert mid_commit >= 1 and left_temp_files >= 1, (mid_commit, left_temp_files)

    final = Worker("ingest", str(archive), str(directory), "--workers", "1")
    assert final.finish() == 0, "\n".join(final.lines[-5:]) + final.process.stderr.read()
    report = json.loads(next(line for line in final.lines if line.startswith("DONE"))[5:])
    assert report["failed"] == []
    committed.update(final.committed())
    assert check_archive(archive, committed, expected) == len(paths) == len(expected)
    print(
        f"{kills} kills, {mid_commit} during a commit, {left_temp_files} left a temporary file, "
        f"{restarts} restart(s) from an empty archive after a run completed; {stored} of {len(paths)} "
        "passes stored before the final run"
    )
