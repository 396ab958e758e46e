"""The archive: exact round trip of real files, no-op re-ingest, versions, results, layout, errors.

Every comparison of stored arrays is exact: HDF5 stores float64 and int64 bit for bit, so any
difference is a bug, not rounding.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import re
import shutil

import h5py
import numpy as np
import pytest

import ingest
from ingest.observation import ARRAY_FIELDS
from rsodb.archive import Archive, StoredPass, UnknownPassError, layout
from rsodb.archive.index import StoredSources
from rsodb.archive.locking import ObjectLock
from rsodb.samples.synthetic import synthetic_pass
from tests.conftest import COSMOS2540_PHV, COSMOS2553_PHC, PROJECT_ROOT, REAL_FILES, TOPEX_PHV


def assert_same_pass(stored, original) -> None:
    """Every array bit for bit and every field of `original` equal in `stored`."""
    for name in ARRAY_FIELDS:
        np.testing.assert_array_equal(getattr(stored, name), getattr(original, name), err_msg=name)
    if original.mag_corrected is None:
        assert stored.mag_corrected is None
    else:
        np.testing.assert_array_equal(stored.mag_corrected, original.mag_corrected)
    for name in (
        "norad",
        "name",
        "band",
        "site",
        "exposure_s",
        "cospar",
        "tle",
        "time_convention",
        "time_shift_s",
        "mag_convention",
        "source_name",
        "source_sha256",
        "source_format",
    ):
        assert getattr(stored, name) == getattr(original, name), name
    assert (stored.omm is None) == (original.omm is None)
    if original.reduction is None:
        assert stored.reduction is None
    else:
        for name, value in vars(original.reduction).items():
            np.testing.assert_equal(getattr(stored.reduction, name), value, err_msg=name)
    assert dict(stored.header) == json.loads(json.dumps(dict(original.header), default=list))


@pytest.fixture
def real_archive(tmp_path, shared_data):
    archive = Archive(tmp_path / "archive")
    report = archive.ingest(REAL_FILES, progress=False, workers=0)
    assert report.ok, report.summary()
    return archive


def test_real_files_round_trip_exactly(real_archive):
    originals = [p for path in REAL_FILES for p in ingest.read_file(path)]
    stored = real_archive.passes()
    assert len(stored) == len(originals) == 5  # three ccd_phot passes, B and V of the phc file
    by_key = {(p.source_sha256, p.band): p for p in originals}
    for item in stored:
        assert isinstance(item, StoredPass)
        assert item.version == 1 and item.is_current
        assert_same_pass(item, by_key[(item.source_sha256, item.band)])
    starts = [p.start_utc for p in stored]
    assert starts == sorted(starts)


def test_pass_ids_are_readable_and_stable(real_archive, tmp_path):
    ids = {row.pass_id for row in real_archive.summaries()}
    assert ids == {
        "22076-20240730T212240-V-derenivka",
        "44517-20250130T173650-V-derenivka",
        "51511-20250311T173120-V-derenivka",
        "51511-20250130T171941-B-uzhhorod",
        "51511-20250130T171941-V-uzhhorod",
    }
    again = Archive(tmp_path / "again")
    again.ingest(list(reversed(REAL_FILES)), progress=False, workers=0)
    assert {row.pass_id for row in again.summaries()} == ids


def test_filters_and_prefix_lookup(real_archive):
    assert [p.norad for p in real_archive.passes(norad=51511)] == [51511, 51511, 51511]
    assert {p.band for p in real_archive.passes(norad=51511, band="B")} == {"B"}
    assert len(real_archive.passes(site="UZHHOROD")) == 2
    assert real_archive.passes(norad=12345) == []
    assert real_archive.get("44517").pass_id == "44517-20250130T173650-V-derenivka"
    with pytest.raises(UnknownPassError, match=r"pass id prefix '51511' matches 3 passes .*; give more of the id"):
        real_archive.get("51511")
    with pytest.raises(UnknownPassError, match=r"no pass '99999-x' in archive .*; run 'rsodb ls --archive"):
        real_archive.get("99999-x")
    with pytest.raises(TypeError, match=r"norad='22076' must be an integer"):
        real_archive.passes(norad="22076")


def test_objects_summary(real_archive):
    objects = {o.norad: o for o in real_archive.objects()}
    assert sorted(objects) == [22076, 44517, 51511]
    cosmos = objects[51511]
    assert (cosmos.n_passes, cosmos.n_versions, cosmos.bands) == (3, 3, ("B", "V"))
    assert cosmos.first_utc == np.datetime64("2025-01-30T17:19:41.500", "ns")
    assert objects[22076].name == "TOPEX/POSEIDON"


def test_reingest_is_a_no_op(real_archive):
    files = sorted(real_archive.objects_dir.glob("*.h5"))
    before = {path: (path.stat().st_ino, path.stat().st_mtime_ns, path.read_bytes()) for path in files}
    report = real_archive.ingest(REAL_FILES, progress=False, workers=0)
    assert report.ok and not report.ingested
    assert sorted(report.already_present) == sorted(str(path) for path in REAL_FILES)
    after = {path: (path.stat().st_ino, path.stat().st_mtime_ns, path.read_bytes()) for path in files}
    assert after == before  # not even rewritten


def test_changed_file_becomes_a_new_version(tmp_path, shared_data):
    source = tmp_path / "in" / TOPEX_PHV.name
    source.parent.mkdir()
    shutil.copy(TOPEX_PHV, source)
    archive = Archive(tmp_path / "archive")
    archive.ingest([source], progress=False, workers=0)
    (first,) = archive.passes()

    # The observer re-reduces the file: one magnitude changes, the name stays.
    lines = source.read_text().splitlines(keepends=True)
    row = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    lines[row] = lines[row].replace(" 4.467 ", " 4.567 ", 1)
    source.write_text("".join(lines))
    report = archive.ingest([source], progress=False, workers=0)
    assert [item.pass_ids for item in report.ingested] == [(first.pass_id + "-v2",)]
    assert report.ingested[0].superseded == (first.pass_id,)
    assert "new version of 22076-20240730T212240-V-derenivka" in report.summary()

    (current,) = archive.passes()
    assert (current.version, current.supersedes, current.superseded_by) == (2, first.pass_id, None)
    assert current.mag[0] == 4.567 and first.mag[0] == 4.467
    old = archive.get(first.pass_id)  # the old version stays, byte for byte
    assert old.superseded_by == current.pass_id and not old.is_current
    assert_same_pass(old, first)
    assert [p.version for p in archive.passes(all_versions=True)] == [1, 2]
    assert archive.get("22076-2024").pass_id == current.pass_id  # a prefix names the current version

    # Ingesting the first content again changes nothing: its hash is stored.
    shutil.copy(TOPEX_PHV, source)
    assert archive.ingest([source], progress=False, workers=0).already_present == (str(source),)


def test_index_written_row_by_row_equals_one_read_from_the_files(tmp_path, shared_data):
    """A commit to an object the index already describes writes only the rows that changed (the
    new pass, the superseded row); the index must then hold what a rebuild from the files gives."""
    source = tmp_path / "in" / TOPEX_PHV.name
    source.parent.mkdir()
    shutil.copy(TOPEX_PHV, source)
    archive = Archive(tmp_path / "archive")
    archive.ingest([source], progress=False, workers=0)
    lines = source.read_text().splitlines(keepends=True)
    row = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    lines[row] = lines[row].replace(" 4.467 ", " 4.567 ", 1)
    source.write_text("".join(lines))
    archive.ingest([source], progress=False, workers=0)  # a new version: the old row changes
    rng = np.random.default_rng(5)
    start = np.datetime64("2025-03-01T18:00", "ns")
    archive.add([synthetic_pass(22076, start + np.timedelta64(k, "D"), 50, rng) for k in range(3)])
    archive.add([synthetic_pass(22076, start + np.timedelta64(9, "D"), 50, rng)])

    def index_rows():
        return sorted((vars(row) for row in archive.summaries(all_versions=True)), key=lambda row: row["pass_id"])

    incremental = index_rows()
    assert len(incremental) == 6
    assert sum(row["superseded_by"] is not None for row in incremental) == 1
    archive.rebuild_index()
    assert [str(row) for row in index_rows()] == [str(row) for row in incremental]


def test_same_observation_under_another_name_is_a_version(tmp_path, shared_data):
    archive = Archive(tmp_path / "archive")
    archive.ingest([COSMOS2540_PHV], progress=False, workers=0)
    renamed = tmp_path / "re-export.phV"
    # A re-reduced re-export: same start second, band and site, one magnitude changed.
    renamed.write_text(COSMOS2540_PHV.read_text().replace(" 6.124 ", " 6.125 ", 1))
    report = archive.ingest([renamed], progress=False, workers=0)
    assert report.ingested[0].pass_ids == ("44517-20250130T173650-V-derenivka-v2",)


def test_same_rows_under_another_name_are_a_duplicate_source(tmp_path, shared_data):
    archive = Archive(tmp_path / "archive")
    archive.ingest([COSMOS2540_PHV], progress=False, workers=0)
    renamed = tmp_path / "re-export.phV"
    renamed.write_text(COSMOS2540_PHV.read_text().replace("2025-01-30 17:41:04.985058", "2025-01-30 17:41:04.985"))
    report = archive.ingest([renamed], progress=False, workers=0)
    assert not report.ingested
    assert [(item.path, item.pass_ids) for item in report.duplicates] == [
        (str(renamed), ("44517-20250130T173650-V-derenivka",))
    ]
    (source,) = archive.duplicate_sources("44517")
    assert source.source_name == "re-export.phV" and len(source.sha256) == 64
    assert archive.ingest([renamed], progress=False, workers=0).already_present == (str(renamed),)


def test_layout_schema_and_plain_h5py(real_archive):
    marker = json.loads((real_archive.path / layout.MARKER_NAME).read_text())
    assert marker["schema_version"] == layout.SCHEMA_VERSION == 2
    with h5py.File(real_archive.object_path(51511), "r") as file:
        assert file.attrs["schema_version"] == 2
        assert file.attrs["norad"] == 51511
        assert sorted(file["passes"]) == sorted(row.pass_id for row in real_archive.summaries(norad=51511))
        samples = file["passes/51511-20250130T171941-B-uzhhorod/samples"]
        assert samples.shape == (692,)
        assert set(json.loads(file.attrs["sample_units"])) >= set(samples.dtype.names)
        metadata = json.loads(file["passes/51511-20250130T171941-B-uzhhorod"].attrs["metadata"])
        assert metadata["site"]["name"] == "Uzhhorod" and metadata["exposure_s"] == 1.0


def _doc_snippet() -> str:
    text = (PROJECT_ROOT / "docs" / "archive.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    (snippet,) = [block for block in blocks if "# reading an archive without rsodb" in block]
    return snippet


def test_documented_snippet_reads_the_archive_with_h5py_and_pandas(real_archive):
    namespace = {"ARCHIVE": str(real_archive.path)}
    exec(compile(_doc_snippet(), "docs/archive.md", "exec"), namespace)
    catalog, samples = namespace["catalog"], namespace["samples"]
    rows = real_archive.summaries(all_versions=True)
    assert sorted(catalog["pass_id"]) == sorted(row.pass_id for row in rows)
    assert catalog["start_utc"].dtype.kind == "M"
    (topex,) = ingest.read_file(TOPEX_PHV)
    np.testing.assert_array_equal(samples.index.values, topex.time_utc)
    np.testing.assert_array_equal(samples["mag"].to_numpy(), topex.mag)
    np.testing.assert_array_equal(samples["range_km"].to_numpy(), topex.range_km)
    assert samples["saturated"].dtype == bool


class Periods:
    """A stand-in result with the contract's to_hdf5/from_hdf5 pair."""

    def __init__(self, best_period_s, power):
        self.best_period_s, self.power = best_period_s, np.asarray(power)

    def to_hdf5(self, group):
        group.attrs["best_period_s"] = self.best_period_s
        group.create_dataset("power", data=self.power)

    @classmethod
    def from_hdf5(cls, group):
        return cls(float(group.attrs["best_period_s"]), group["power"][()])


class Broken:
    def to_hdf5(self, group):
        group.create_dataset("half", data=np.arange(10))
        raise RuntimeError("disk on fire")


def test_results_are_stored_atomically(real_archive):
    pass_id = "22076-20240730T212240-V-derenivka"
    real_archive.store_result(pass_id, "periods", "lomb-scargle", Periods(10.73, [1.0, 2.0, 3.0]))
    real_archive.store_result("22076", "fits", "paper", Periods(9.86, [0.5]))
    loaded = real_archive.load_result(pass_id, "periods", "lomb-scargle", Periods.from_hdf5)
    assert loaded.best_period_s == 10.73
    np.testing.assert_array_equal(loaded.power, [1.0, 2.0, 3.0])
    assert real_archive.result_names(pass_id, "periods") == ["lomb-scargle"]
    assert real_archive.result_names(pass_id, "fits") == ["paper"]
    assert real_archive.result_names("44517", "fits") == []

    # Storing under the same name replaces; the pass itself is untouched.
    real_archive.store_result(pass_id, "periods", "lomb-scargle", Periods(10.5, [7.0]))
    assert real_archive.load_result(pass_id, "periods", "lomb-scargle", Periods.from_hdf5).best_period_s == 10.5
    (topex,) = ingest.read_file(TOPEX_PHV)
    assert_same_pass(real_archive.get(pass_id), topex)

    # A result that fails while writing leaves the object file exactly as it was.
    path = real_archive.object_path(22076)
    before = path.read_bytes()
    with pytest.raises(RuntimeError, match="disk on fire"):
        real_archive.store_result(pass_id, "fits", "broken", Broken())
    assert path.read_bytes() == before
    assert real_archive.result_names(pass_id, "fits") == ["paper"]
    assert not [name for name in os.listdir(real_archive.objects_dir) if name.endswith(".tmp")]


def test_batched_results_make_one_commit_per_object(real_archive):
    v, b = "51511-20250130T171941-V-uzhhorod", "51511-20250130T171941-B-uzhhorod"
    topex = "22076-20240730T212240-V-derenivka"
    before = {norad: real_archive.object_path(norad).stat().st_mtime_ns for norad in (22076, 44517, 51511)}
    commits = real_archive.store_results(
        [
            (v, "periods", "default", Periods(4.93, [1.0])),
            (b, "periods", "default", Periods(4.926, [2.0])),
            (topex, "periods", "default", Periods(9.48, [3.0])),
            (v, "periods", "default", Periods(4.9299, [4.0])),  # later items replace earlier ones
        ]
    )
    assert commits == 2
    after = {norad: real_archive.object_path(norad).stat().st_mtime_ns for norad in (22076, 44517, 51511)}
    assert after[44517] == before[44517] and after[22076] != before[22076] and after[51511] != before[51511]
    loaded = {pid: real_archive.load_result(pid, "periods", "default", Periods.from_hdf5) for pid in (v, b, topex)}
    assert [loaded[pid].best_period_s for pid in (v, b, topex)] == [4.9299, 4.926, 9.48]
    np.testing.assert_array_equal(loaded[v].power, [4.0])

    # A bad item anywhere in the batch is refused before anything is written.
    with pytest.raises(ValueError, match=r"result kind 'period' is not one of periods, fits"):
        real_archive.store_results(
            [(topex, "periods", "second", Periods(1.0, [1])), (v, "period", "x", Periods(1.0, [1]))]
        )
    assert real_archive.result_names(topex, "periods") == ["default"]


def test_result_arguments_are_checked(real_archive):
    pass_id = "44517-20250130T173650-V-derenivka"
    with pytest.raises(ValueError, match=r"result kind 'period' is not one of periods, fits"):
        real_archive.store_result(pass_id, "period", "x", Periods(1.0, [1]))
    with pytest.raises(ValueError, match=r"result name '\.\./x' must start with a letter or digit"):
        real_archive.store_result(pass_id, "fits", "../x", Periods(1.0, [1]))
    with pytest.raises(TypeError, match=r"list has no to_hdf5\(group\) method"):
        real_archive.store_result(pass_id, "fits", "x", [1, 2])
    with pytest.raises(UnknownPassError, match=r"has no periods result named 'nope'; stored: none"):
        real_archive.load_result(pass_id, "periods", "nope", Periods.from_hdf5)


def test_chain_path_is_inside_the_archive(real_archive):
    path = real_archive.chain_path("44517", "spin-fit")
    assert path == real_archive.path / "chains" / "44517" / "44517-20250130T173650-V-derenivka" / "spin-fit.h5"
    assert path.parent.is_dir()
    with pytest.raises(ValueError, match="result name 'a/b'"):
        real_archive.chain_path("44517", "a/b")


def test_replaced_results_do_not_grow_the_file_forever(real_archive):
    """Each replacement leaves dead space; past 25% of the file (and 4 MiB) the file is repacked."""
    pass_id = "44517"
    payload = np.arange(2**17, dtype=np.float64)  # 1 MiB
    for k in range(8):
        # Alternating two names: a replaced result is never the file's last block, whose space
        # HDF5 would give back by itself.
        real_archive.store_result(pass_id, "fits", "first", Periods(float(k), payload))
        real_archive.store_result(pass_id, "fits", "second", Periods(float(k) + 0.5, payload))
    size_mib = real_archive.object_path(44517).stat().st_size / 2**20
    # Without repacking the file grows by 2 MiB per round, to 16 MiB. With it: live data (the
    # pass 0.4 MiB, two results 2 MiB) + at most the 4 MiB of dead space + one round's 2 MiB.
    assert size_mib < 8.5
    assert real_archive.load_result(pass_id, "fits", "first", Periods.from_hdf5).best_period_s == 7.0
    assert real_archive.load_result(pass_id, "fits", "second", Periods.from_hdf5).best_period_s == 7.5
    (cosmos,) = ingest.read_file(COSMOS2540_PHV)
    assert_same_pass(real_archive.get(pass_id), cosmos)


def test_opening_checks_the_directory(tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("x")
    with pytest.raises(ValueError, match=r"'.*notes' is a non-empty directory without rsodb-archive.json"):
        Archive(tmp_path / "notes")
    with pytest.raises(ValueError, match=r"no archive at '.*missing'; create one with 'rsodb ingest"):
        Archive(tmp_path / "missing", create=False)
    assert not (tmp_path / "missing").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match=r"archive path '.*file' is a file"):
        Archive(tmp_path / "file")
    future = Archive(tmp_path / "future")
    (future.path / layout.MARKER_NAME).write_text(json.dumps({"format": "rsodb archive", "schema_version": 99}))
    with pytest.raises(ValueError, match=r"has schema_version 99, newer than this rsodb reads \(2\); upgrade rsodb"):
        Archive(future.path)


def test_stale_temp_files_are_removed_unless_their_writer_is_alive(real_archive):
    stale = real_archive.objects_dir / ".22076.h5.4242.deadbeef.tmp"
    live = real_archive.objects_dir / ".44517.h5.4343.cafebabe.tmp"
    stale.write_bytes(b"half an HDF5 file")
    live.write_bytes(b"a file being written")
    with ObjectLock(real_archive.objects_dir / layout.lock_file_name(44517)):  # a writer holds 44517
        reopened = Archive(real_archive.path)
    assert not stale.exists() and live.exists()
    assert len(reopened.passes()) == 5  # temp files are never read as passes


def test_a_result_commit_removes_a_writer_s_file_listed_at_open_without_listing_again(real_archive, monkeypatch):
    """A writer alive when the archive was opened leaves its file; once it is gone, the next commit
    of that object removes it, from the names listed at open (a directory of 20 000 objects is
    not listed again for each commit)."""
    import rsodb.archive.commits

    live = real_archive.objects_dir / ".22076.h5.4343.cafebabe.tmp"
    live.write_bytes(b"a file being written")
    with ObjectLock(real_archive.objects_dir / layout.lock_file_name(22076)):
        reopened = Archive(real_archive.path)
    assert live.exists()  # its writer held the lock at open
    late = real_archive.objects_dir / ".22076.h5.4444.feedface.tmp"  # a writer killed after the open
    late.write_bytes(b"half an HDF5 file")

    def no_listing(objects_dir):
        raise AssertionError("the objects directory was listed again")

    monkeypatch.setattr(rsodb.archive.commits, "list_temp_names", no_listing)
    topex = "22076-20240730T212240-V-derenivka"
    assert reopened.store_results([(topex, "periods", "default", Periods(9.48, [3.0]))]) == 1
    assert not live.exists() and late.exists()  # the late one waits for the next open
    monkeypatch.undo()
    Archive(real_archive.path)
    assert not late.exists()


def test_a_commit_removes_what_a_killed_writer_of_its_object_left(tmp_path, shared_data):
    """Temporary files left after the archive was opened go when their object is next committed
    (listed once per ingest run, whatever its number of commit rounds)."""
    archive = Archive(tmp_path / "archive")
    archive.ingest([COSMOS2540_PHV], progress=False, workers=0)
    left = archive.objects_dir / ".44517.h5.4242.deadbeef.tmp"
    other = archive.objects_dir / ".22076.h5.4242.deadbeef.tmp"
    left.write_bytes(b"half an HDF5 file")
    other.write_bytes(b"half an HDF5 file")
    source = tmp_path / "copy.phV"
    source.write_bytes(COSMOS2540_PHV.read_bytes().replace(b"\n", b"\r\n"))  # new bytes, same pass
    assert archive.ingest([source], progress=False, workers=0).ok
    assert not left.exists() and other.exists()  # 22076 was not committed, so it was not locked


def test_add_in_memory_passes(tmp_path):
    rng = np.random.default_rng(7)
    made = [
        synthetic_pass(90001, np.datetime64("2025-03-01T18:00:00", "ns"), 300, rng),
        synthetic_pass(90002, np.datetime64("2025-03-01T19:00:00", "ns"), 300, rng),
    ]
    archive = Archive(tmp_path / "archive")
    report = archive.add(made)
    assert len(report.pass_ids) == 2
    assert archive.add(made).already_present and not archive.add(made).ingested  # hashed by content
    for original, stored in zip(made, archive.passes()):
        np.testing.assert_array_equal(stored.mag, original.mag)
        np.testing.assert_array_equal(stored.time_utc, original.time_utc)
        assert len(stored.source_sha256) == 64


def test_ingest_arguments_are_checked(tmp_path):
    archive = Archive(tmp_path / "archive")
    with pytest.raises(ValueError, match=r"workers=-1 must be a non-negative integer"):
        archive.ingest([COSMOS2553_PHC], workers=-1)
    report = archive.ingest([tmp_path / "nothing-here.phV"], progress=False)
    assert [str(error) for error in report.failed] == [f"{tmp_path / 'nothing-here.phV'}: no such file or directory"]


def test_process_pool_gives_the_same_archive(tmp_path, shared_data):
    """Reading in worker processes must store exactly what reading in-process stores."""
    serial = Archive(tmp_path / "serial")
    pooled = Archive(tmp_path / "pooled")
    serial.ingest(REAL_FILES, progress=False, workers=0)
    pooled.ingest(REAL_FILES, progress=False, workers=2)
    for a, b in zip(serial.passes(), pooled.passes()):
        assert a.pass_id == b.pass_id
        assert_same_pass(b, a)


def test_stored_sources_answer_from_the_index_in_other_processes(real_archive, tmp_path):
    """The readers of an ingest ask the index whether a file is stored, one hash at a time."""
    import pickle

    stored = {row.source_sha256 for row in real_archive.summaries()}
    sources = pickle.loads(pickle.dumps(real_archive.stored_sources()))  # as a reader receives it
    assert len(pickle.dumps(sources)) < 1000  # the path, not the hashes
    assert stored and all(sha in sources for sha in stored)
    assert "0" * 64 not in sources and next(iter(stored)).upper() not in sources
    assert Archive(tmp_path / "empty").stored_sources() == frozenset()  # nothing stored: no hashing first
    damaged = tmp_path / layout.INDEX_NAME
    damaged.write_bytes(b"not SQLite")  # unreadable: "not stored", and the commit decides
    assert next(iter(stored)) not in StoredSources(damaged)


def test_a_pooled_reingest_finds_every_file_stored(real_archive):
    report = real_archive.ingest(REAL_FILES, progress=False, workers=2)
    assert report.ok and not report.ingested
    assert sorted(report.already_present) == sorted(str(path) for path in REAL_FILES)


def test_a_file_the_stale_index_lists_is_stored_again(real_archive):
    """The readers trust the index without a sweep; the parent checks a hit against the object file."""
    (row,) = [row for row in real_archive.summaries() if row.norad == 44517]
    real_archive.object_path(44517).unlink()  # behind the archive's back: the index still lists it
    report = real_archive.ingest(REAL_FILES, progress=False, workers=2)
    assert report.ok and [Path(item.path).name for item in report.ingested] == [row.source_name]
    assert len(report.already_present) == len(REAL_FILES) - 1
    assert [summary.source_sha256 for summary in real_archive.summaries(44517)] == [row.source_sha256]


def test_a_damaged_object_file_is_named_and_the_others_are_listed(real_archive):
    real_archive.object_path(44517).write_bytes(b"not HDF5 at all")
    reopened = Archive(real_archive.path)
    assert {row.norad for row in reopened.summaries()} == {22076, 51511}
    (damaged,) = reopened.damaged()
    assert damaged.norad == 44517 and damaged.reason.startswith("it cannot be opened as HDF5")
    with pytest.raises(OSError, match=r"44517\.h5 is damaged: it cannot be opened as HDF5 .*rsodb check --archive"):
        reopened.get("44517")


def test_a_killed_creation_does_not_block_the_next(tmp_path):
    target = tmp_path / "archive"
    target.mkdir()
    (target / f".{layout.MARKER_NAME}.999.abcdef01.tmp").write_text("{")  # killed before its rename
    archive = Archive(target)
    assert archive.passes() == [] and (target / layout.MARKER_NAME).is_file()
