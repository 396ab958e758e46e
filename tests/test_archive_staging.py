"""Object files staged by an ingest's reader processes (rsodb.archive.commits, "hand_over"/"adopt").

A reader stages an object's next file without the object's lock, from the object file as it
was then; the commit publishes it only if the object file is still that one, and otherwise stages
the object again from what is there now. These tests build the race by hand: a file staged,
then another writer commits the same object before the staged file is offered.
"""

from __future__ import annotations

import os

import h5py
import numpy as np
import pytest

import ingest
from rsodb.archive import Archive, layout
from rsodb.archive.commits import ObjectTransaction, stage_files
from rsodb.archive.ingest_report import PendingFile
from rsodb.archive.locking import ObjectLock
from rsodb.samples.synthetic import write_synthetic_corpus

NORAD = 90001


@pytest.fixture
def files(tmp_path):
    """Four 200-row files of one object (NORAD 90001), passes five hours apart."""
    return write_synthetic_corpus(tmp_path / "corpus", n_files=4, n_points=200, n_objects=1, seed=3)


def staged_elsewhere(archive: Archive, path, staging) -> PendingFile:
    """What a reader hands over for `path`: its passes and the object's next file, staged now."""
    passes = tuple(ingest.read_file(path))
    sha = passes[0].source_sha256  # the reader's hash of the file
    transaction = ObjectTransaction(archive.objects_dir, None, durable=False, temp_dir=staging)
    with transaction:
        stage_files(transaction, NORAD, [PendingFile(str(path), sha, passes)])
        (item,) = transaction.hand_over()
        item = item.without_unchanged_rows()  # as a reader sends it
    assert item.tmp.is_file() and item.tmp.parent == staging  # kept after the transaction ended
    return PendingFile(str(path), sha, passes, item)


def stored_sources(archive: Archive) -> list[str]:
    return sorted(row.source_name for row in archive.summaries(norad=NORAD, all_versions=True))


def test_a_staged_file_is_published_when_the_object_is_unchanged(tmp_path, files):
    archive = Archive(tmp_path / "archive")
    archive.ingest(files[:1], progress=False, workers=0)
    staging = tmp_path / "staging"
    staging.mkdir()
    pending = staged_elsewhere(archive, files[1], staging)
    inode = os.stat(pending.prepared.tmp).st_ino
    events, failures = archive.commit_many({NORAD: [pending]})
    assert not failures and [event.norad for event in events] == [NORAD]
    # The reader's file itself became the object file (renamed, not rebuilt).
    assert os.stat(archive.object_path(NORAD)).st_ino == inode
    assert stored_sources(archive) == sorted(path.name for path in files[:2])
    assert len(archive.passes(norad=NORAD)) == 2  # both read back, checksums and hashes verified


def test_a_staged_file_sent_without_its_rows_is_indexed_from_its_file(tmp_path, files):
    """A reader sends only the catalog rows that changed; if the index did not describe the file
    the reader copied, the object is marked stale and read again from its file on the next look."""
    archive = Archive(tmp_path / "archive")
    archive.ingest(files[:2], progress=False, workers=0)
    staging = tmp_path / "staging"
    staging.mkdir()
    pending = staged_elsewhere(archive, files[2], staging)
    assert pending.prepared.rows is None and [row.source_name for row in pending.prepared.changed] == [files[2].name]
    archive._index.remove_objects([NORAD])  # the index no longer describes the copied file
    events, failures = archive.commit_many({NORAD: [pending]})
    assert not failures and [len(event.ingested) for event in events] == [1]
    assert stored_sources(archive) == sorted(path.name for path in files[:3])
    assert sorted(row.source_name for row in archive.summaries()) == sorted(path.name for path in files[:3])


@pytest.mark.parametrize("object_exists", [True, False])
def test_a_staged_file_is_not_published_over_a_newer_commit(tmp_path, files, object_exists):
    archive = Archive(tmp_path / "archive")
    if object_exists:
        archive.ingest(files[:1], progress=False, workers=0)
    staging = tmp_path / "staging"
    staging.mkdir()
    pending = staged_elsewhere(archive, files[2], staging)
    # Another writer commits the object between the staging and the commit.
    archive.ingest([files[3]], progress=False, workers=0)
    events, failures = archive.commit_many({NORAD: [pending]})
    assert not failures and [len(event.ingested) for event in events] == [1]
    assert not pending.prepared.tmp.exists()  # dropped, not published
    expected = files[:1] + files[2:] if object_exists else files[2:]
    assert stored_sources(archive) == sorted(path.name for path in expected)


def test_ingest_with_readers_stores_what_one_process_stores(tmp_path):
    """A night of one file per object (staged by the readers) and a stretch of several files per
    object (staged by the committing process) give the same archive as reading in one process."""
    night = write_synthetic_corpus(tmp_path / "night", n_files=24, n_points=150, n_objects=24, seed=5)
    many = write_synthetic_corpus(tmp_path / "many", n_files=24, n_points=150, n_objects=3, seed=6, first_norad=91001)
    tables = {}
    for workers in (0, 2):
        archive = Archive(tmp_path / f"archive-{workers}")
        report = archive.ingest([*night, *many], progress=False, workers=workers)
        assert report.ok and len(report.ingested) == 48
        assert not list((archive.path / layout.STAGING_DIR).glob("*")), "the run's staging directory was left"
        tables[workers] = {
            row.pass_id: (row.source_sha256, row.n_points, row.version) for row in archive.summaries(all_versions=True)
        }
        samples = {stored.pass_id: stored.mag for stored in archive.passes(all_versions=True)}
        tables[workers, "mag"] = samples
    assert tables[0] == tables[2] and len(tables[0]) == 48
    for pass_id, mag in tables[0, "mag"].items():
        np.testing.assert_array_equal(tables[2, "mag"][pass_id], mag)


def test_opening_removes_only_abandoned_staging(tmp_path, files):
    archive = Archive(tmp_path / "archive")
    root = archive.path / layout.STAGING_DIR
    for name in ("1.dead", "2.alive"):
        (root / name).mkdir(parents=True)
        (root / name / ".90001.h5.1.x.tmp").write_bytes(b"partial")
        (root / f"{name}.lock").touch()
    alive = ObjectLock(root / "2.alive.lock", timeout_s=0)
    assert alive.acquire(blocking=False)
    try:
        Archive(archive.path)
        assert sorted(os.listdir(root)) == ["2.alive", "2.alive.lock"]
    finally:
        alive.release()
    Archive(archive.path)
    assert os.listdir(root) == []


def test_fast_attributes_read_back_as_h5py_writes_them(tmp_path):
    values = {"text": "Kosmos 2502 ☉", "count": 7, "numpy int": np.int64(-3), "ratio": 0.25, "empty": ""}
    with h5py.File(tmp_path / "a.h5", "w") as fast, h5py.File(tmp_path / "b.h5", "w") as plain:
        layout.set_attrs(fast, values)
        layout.set_attrs(fast, {"count": 8})  # replaces
        for name, value in values.items():
            plain.attrs[name] = value
        plain.attrs["count"] = 8
    with h5py.File(tmp_path / "a.h5", "r") as fast, h5py.File(tmp_path / "b.h5", "r") as plain:
        for name in values:
            assert fast.attrs[name] == plain.attrs[name] and type(fast.attrs[name]) is type(plain.attrs[name])
            assert fast.attrs.get_id(name).dtype == plain.attrs.get_id(name).dtype
        read = layout.get_attrs(fast, [*values, "absent"])
        assert read == {**values, "count": 8} and isinstance(read["text"], str)
