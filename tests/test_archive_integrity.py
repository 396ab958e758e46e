"""Damage is detected, named, and isolated (issue 17).

One flipped bit in a stored magnitude (6.851 -> 3.4255) used to be served with exit 0; one
unreadable object file stopped every command. Here each kind of damage is made in a real
archive, and every command is checked: it names the damaged file and goes on with the others,
and no damaged value is ever returned.
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import struct

import h5py
import numpy as np
import pytest

import ingest
from rsodb.archive import Archive, DamagedObjectError, check_archive, layout
from rsodb.cli import main
from tests.conftest import COSMOS2540_PHV, COSMOS2553_JD_PHV, COSMOS2553_PHC, REAL_FILES, TOPEX_PHV

COSMOS2540_ID = "44517-20250130T173650-V-derenivka"


@pytest.fixture
def real_archive(tmp_path, shared_data):
    archive = Archive(tmp_path / "archive")
    assert archive.ingest(REAL_FILES, progress=False, workers=0).ok
    return archive


class Periods:
    def __init__(self, period_s):
        self.period_s = period_s

    def to_hdf5(self, group):
        group.attrs["best_period_s"] = self.period_s
        group.attrs["verdict"] = "confident"
        group.create_dataset("power", data=np.linspace(0, 1, 50))


def flip_bit(path, pass_id: str, row: int, field: str, bit: int) -> tuple[float, float]:
    """Flip one bit of a stored float64 in place, as a failing disk would; returns (before, after)."""
    with h5py.File(path, "r") as file:
        samples = file["passes"][pass_id]["samples"]
        start = samples.id.get_chunk_info(0).byte_offset
        offset = start + row * samples.dtype.itemsize + samples.dtype.fields[field][1]
    with open(path, "r+b") as stream:
        stream.seek(offset)
        raw = bytearray(stream.read(8))
        before = struct.unpack("<d", raw)[0]
        raw[bit // 8] ^= 1 << (bit % 8)
        stream.seek(offset)
        stream.write(raw)
    return before, struct.unpack("<d", raw)[0]


def test_every_stored_table_has_a_checksum(real_archive):
    with h5py.File(real_archive.object_path(51511), "r") as file:
        tables = []
        file.visititems(lambda name, node: tables.append(node) if isinstance(node, h5py.Dataset) else None)
        assert {table.name.rsplit("/", 1)[-1] for table in tables} >= {"catalog", "samples"}
        assert all(table.fletcher32 for table in tables if table.size)
        for pass_id in file["passes"]:
            assert len(file["passes"][pass_id].attrs["content_sha256"]) == 64


def test_a_flipped_bit_in_a_magnitude_is_an_error_naming_the_file(real_archive, capsys):
    path = real_archive.object_path(44517)
    (cosmos,) = ingest.read_file(COSMOS2540_PHV)
    row = int(np.flatnonzero(cosmos.mag == 6.851)[0])
    before, after = flip_bit(path, COSMOS2540_ID, row, "mag", 52)  # the lowest exponent bit: x 1/2
    assert (before, after) == (6.851, 3.4255)
    with pytest.raises(
        DamagedObjectError, match=r"44517\.h5 is damaged: the samples of /passes/44517-.* fail their checksum"
    ):
        real_archive.get("44517")
    # The commands that would serve the value refuse, naming the file; the others are unaffected.
    assert main(["show", "44517", "--archive", str(real_archive.path)]) == 2
    assert "44517.h5 is damaged" in capsys.readouterr().err
    assert main(["export", "44517", "--archive", str(real_archive.path), "--format", "csv"]) == 2
    assert "44517.h5 is damaged" in capsys.readouterr().err
    assert main(["export", "22076", "--archive", str(real_archive.path), "--format", "csv"]) == 0
    capsys.readouterr()
    report = check_archive(real_archive)
    assert list(report.damaged) == [str(path)] and "fail their checksum" in report.damaged[str(path)][0]


def test_damage_that_keeps_the_checksum_is_caught_by_the_content_hash(real_archive):
    # Rewriting the dataset through HDF5 recomputes Fletcher32; the pass's SHA-256 still differs.
    with h5py.File(real_archive.object_path(44517), "r+") as file:
        samples = file["passes"][COSMOS2540_ID]["samples"]
        table = samples[()]
        table["mag"][7] += 1.0
        samples[...] = table
    with pytest.raises(DamagedObjectError, match=r"the content of /passes/44517-.* does not match its SHA-256"):
        real_archive.get("44517")


def test_a_damaged_result_is_not_handed_out(real_archive):
    real_archive.store_result(COSMOS2540_ID, "periods", "default", Periods(6.5))
    assert real_archive.result_values(COSMOS2540_ID, "periods", "default")["best_period_s"] == 6.5
    with h5py.File(real_archive.object_path(44517), "r+") as file:
        file["passes"][COSMOS2540_ID]["periods"]["default"].attrs["best_period_s"] = 3.25
    with pytest.raises(DamagedObjectError, match=r"the result /passes/44517-.*/periods/default does not match"):
        real_archive.result_values(COSMOS2540_ID, "periods", "default")


@pytest.mark.parametrize(
    "damage, reason",
    [
        (lambda path: path.write_bytes(b""), "it is empty"),
        (lambda path: path.write_bytes(path.read_bytes()[: path.stat().st_size // 2]), "it cannot be opened as HDF5"),
        (lambda path: path.write_bytes(np.random.default_rng(1).bytes(4096)), "it cannot be opened as HDF5"),
        (lambda path: (path.unlink(), path.mkdir()), "it is a directory"),
    ],
    ids=["empty", "truncated", "garbage", "directory"],
)
def test_one_damaged_object_never_stops_commands_on_others(real_archive, tmp_path, capsys, damage, reason):
    path = real_archive.object_path(44517)
    damage(path)
    archive = str(real_archive.path)
    # ls lists the others and names the damaged file (exit 1); show/export of others work.
    assert main(["ls", "--archive", archive, "--json"]) == 1
    captured = capsys.readouterr()
    assert {row["norad"] for row in json.loads(captured.out)} == {22076, 51511}
    assert f"{path} is damaged ({reason}" in captured.err
    assert main(["show", "22076", "--archive", archive]) == 0
    assert main(["export", "51511-20250311", "--archive", archive, "--format", "csv"]) == 0
    capsys.readouterr()
    assert main(["show", "44517", "--archive", archive]) == 2
    assert f"{path} is damaged: {reason}" in capsys.readouterr().err
    # Ingest goes on: another object's new file lands; a file of the damaged object is refused.
    other = tmp_path / "topex-copy.phV"
    other.write_bytes(TOPEX_PHV.read_bytes().replace(b"2024-07-30 ", b"2024-07-31 "))
    status = main(["ingest", str(other), str(COSMOS2540_PHV), "--archive", archive, "--no-progress", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert status == 1 and [item["path"] for item in report["ingested"]] == [str(other)]
    (failure,) = report["failed"]
    assert failure["path"] == str(COSMOS2540_PHV) and f"not stored: {path} is damaged" in failure["message"]
    # check names it; --repair moves it aside, and the archive is whole again.
    assert main(["check", "--archive", archive, "--no-progress"]) == 1
    assert f"{path}: {reason}" in capsys.readouterr().out
    assert main(["check", "--archive", archive, "--repair", "--no-progress", "--json"]) == 1
    (item,) = json.loads(capsys.readouterr().out)["damaged"]
    assert item["moved_to"].startswith(str(real_archive.path / "damaged" / "44517.h5."))
    assert not os.path.exists(path)
    assert main(["check", "--archive", archive, "--no-progress"]) == 0
    assert main(["ls", "--archive", archive]) == 0
    capsys.readouterr()
    # The pass comes back by ingesting its file again.
    assert main(["ingest", str(COSMOS2540_PHV), "--archive", archive, "--no-progress"]) == 0
    assert Archive(archive).get("44517").pass_id == COSMOS2540_ID


def test_period_search_of_other_objects_goes_on(real_archive, capsys):
    real_archive.object_path(44517).write_bytes(b"garbage")
    status = main(
        ["periods", "--archive", str(real_archive.path), "--object", "51511", "--band", "B", "--quiet"]
        + ["--processes", "1", "--no-geometry", "--no-store"]
    )
    assert status == 0
    assert "51511-20250130T171941-B-uzhhorod" in capsys.readouterr().out
    # Over every object: the others are searched, the damaged one named on stderr (exit status 1).
    status = main(
        ["periods", "--archive", str(real_archive.path), "--band", "B", "--quiet"]
        + ["--processes", "1", "--no-geometry", "--no-store"]
    )
    captured = capsys.readouterr()
    assert status == 1 and "51511-20250130T171941-B-uzhhorod" in captured.out
    assert f"rsodb periods: warning: {real_archive.object_path(44517)} is damaged" in captured.err


def test_the_index_is_rebuilt_when_missing_damaged_or_stale(real_archive, shared_data):
    index = real_archive.path / layout.INDEX_NAME
    expected = [(row.pass_id, row.n_points) for row in real_archive.summaries(all_versions=True)]
    # Deleted: rebuilt from the object files on the next open.
    for suffix in ("", "-wal", "-shm"):
        (real_archive.path / f"{layout.INDEX_NAME}{suffix}").unlink(missing_ok=True)
    assert [(row.pass_id, row.n_points) for row in Archive(real_archive.path).summaries(all_versions=True)] == expected
    # Garbage: replaced.
    for suffix in ("-wal", "-shm"):
        (real_archive.path / f"{layout.INDEX_NAME}{suffix}").unlink(missing_ok=True)
    index.write_bytes(b"this is not SQLite" * 100)
    assert [(row.pass_id, row.n_points) for row in Archive(real_archive.path).summaries(all_versions=True)] == expected
    # Stale: an object file replaced behind the index's back (a writer killed after its rename,
    # before its index update; or a file restored from a backup) is read again.
    backup = real_archive.path.parent / "backup"
    shutil.copytree(real_archive.path, backup)
    writer = Archive(backup)
    writer.ingest([TOPEX_PHV.parent / COSMOS2553_JD_PHV.name], progress=False, workers=0)
    writer.store_result("22076", "periods", "default", Periods(10.7))
    shutil.copy(backup / "objects" / "22076.h5", real_archive.object_path(22076))
    (row,) = real_archive.summaries(norad=22076, periods_name="default")
    assert row.period_s == 10.7 and row.verdict == "confident"
    assert [r.period_s for r in Archive(real_archive.path).summaries() if r.norad == 22076] == [10.7]


def test_two_archives_see_each_others_commits(real_archive, tmp_path):
    # A reader's index stays true while another process (here another Archive) writes.
    reader = Archive(real_archive.path)
    assert len(reader.summaries()) == 5
    new = tmp_path / "new.phV"
    new.write_bytes(COSMOS2540_PHV.read_bytes().replace(b"2025-01-30 ", b"2025-01-31 "))
    Archive(real_archive.path).ingest([new], progress=False, workers=0)
    assert len(reader.summaries()) == 6
    assert reader.get("44517-20250131").pass_id == "44517-20250131T173650-V-derenivka"
    b, _ = ingest.read_file(COSMOS2553_PHC)
    np.testing.assert_array_equal(reader.get("51511-20250130T171941-B").mag, b.mag)


def test_a_damaged_index_is_replaced_and_a_failing_one_is_a_clear_error(real_archive, capsys):
    index = real_archive.path / layout.INDEX_NAME
    Archive(real_archive.path).summaries()
    with sqlite3.connect(index) as db:  # everything into the main file, then damage all but its first page
        db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    data = bytearray(index.read_bytes())
    data[4096:] = b"\x5a" * (len(data) - 4096)
    index.write_bytes(bytes(data))
    # Opening finds it unreadable and builds a new one from the object files.
    assert main(["ls", "--archive", str(real_archive.path), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 5
    # Damage that shows only later, in an open index, is a one-sentence error naming the fix.
    opened = Archive(real_archive.path)
    opened._index._db.close()
    opened._index._db = sqlite3.connect(":memory:", check_same_thread=False)  # no tables: every query fails
    with pytest.raises(OSError, match=r"the catalog index .* cannot be read .*run 'rsodb check --archive"):
        opened.summaries(norad=22076)
    assert main(["check", "--archive", str(real_archive.path), "--no-progress"]) == 0
    assert "index rebuilt (3 objects)" in capsys.readouterr().out
