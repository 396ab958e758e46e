"""Damage detection: opening object files safely, hashing stored results, verifying whole files.

Every table in an object file carries an HDF5 Fletcher32 checksum, every pass a SHA-256 of its
content (`rsodb.archive.layout.content_sha256`) and every stored result a SHA-256 of its
attributes and datasets (`result_sha256`); object headers written by this schema carry HDF5's own
metadata checksums. Anything that does not match raises `DamagedObjectError`, which names the
object file and what to do, so a damaged file gives an error, never a wrong number.
`verify_object` reads everything in a file (what ``rsodb check`` runs).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
import stat as stat_module

import h5py
import numpy as np

from rsodb.archive import layout
from rsodb.storage import attr_text

__all__ = [
    "DamagedObjectError",
    "open_object",
    "result_sha256",
    "read_attrs",
    "seal_result",
    "check_result",
    "verify_object",
]


class DamagedObjectError(OSError):
    """An object file that cannot be read, or whose content fails its checksums.

    Parameters
    ----------
    path : path
        The object file.
    reason : str
        What is wrong.
    """

    def __init__(self, path, reason: str):
        self.path = str(path)
        self.reason = reason
        archive = Path(path).resolve().parent.parent
        super().__init__(
            f"{path} is damaged: {reason}; the other objects are unaffected. Run 'rsodb check --archive "
            f"{archive} --repair' to move it aside, then restore it from a backup or ingest its files again"
        )

    def __reduce__(self):
        return type(self), (self.path, self.reason)


def open_object(path: Path) -> h5py.File:
    """Open an object file read-only; anything but a readable HDF5 object file is `DamagedObjectError`.

    Raises
    ------
    FileNotFoundError
        When there is no such file (not damage: the object is not stored).
    DamagedObjectError
        A directory or special file in its place, an empty or truncated file, not HDF5, no root
        attributes.
    ValueError
        A file of a newer schema than this rsodb reads (not damage: upgrade rsodb).
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise DamagedObjectError(path, f"it cannot be inspected ({exc.strerror})") from None
    if not stat_module.S_ISREG(mode):
        kind = "a directory" if stat_module.S_ISDIR(mode) else "not a regular file"
        raise DamagedObjectError(path, f"it is {kind}, where an HDF5 object file should be")
    try:
        file = h5py.File(path, "r")
    except FileNotFoundError:
        raise
    except (OSError, RuntimeError, ValueError) as exc:
        reason = "it is empty" if os.path.getsize(path) == 0 else f"it cannot be opened as HDF5 ({_first_line(exc)})"
        raise DamagedObjectError(path, reason) from None
    try:
        if "schema_version" not in file.attrs or "passes" not in file:
            raise DamagedObjectError(path, "it is an HDF5 file without the archive's root attributes and groups")
        layout.check_schema(file, path)
    except (OSError, RuntimeError, KeyError) as exc:
        file.close()
        if isinstance(exc, DamagedObjectError):
            raise
        raise DamagedObjectError(path, f"its root cannot be read ({_first_line(exc)})") from None
    except BaseException:
        file.close()
        raise
    return file


def _first_line(exc: BaseException) -> str:
    return (str(exc) or type(exc).__name__).splitlines()[0]


def result_sha256(group: h5py.Group, attrs: dict | None = None) -> str:
    """SHA-256 of everything a stored result holds: its attributes and datasets, recursively
    (names sorted), its own ``content_sha256`` attribute excluded.

    Parameters
    ----------
    attrs : dict, optional
        The group's own attributes, when the caller has read them already.
    """
    digest = hashlib.sha256()
    if attrs is None:
        attrs = read_attrs(group)

    def add_attrs(values: dict) -> None:
        for name in sorted(values):
            if values is attrs and name == "content_sha256":
                continue
            digest.update(name.encode())
            digest.update(_value_bytes(values[name]))

    add_attrs(attrs)
    names = []
    group.visit(names.append)
    for name in sorted(names):
        node = group[name]
        digest.update(name.encode())
        add_attrs(read_attrs(node))
        if isinstance(node, h5py.Dataset):
            digest.update(_value_bytes(node[()]))
    return digest.hexdigest()


def read_attrs(node) -> dict:
    """Every attribute of an HDF5 group or dataset, read once."""
    return {name: node.attrs[name] for name in node.attrs}


def _value_bytes(value) -> bytes:
    if isinstance(value, bytes):
        return value
    if isinstance(value, str):
        return value.encode("utf-8", "surrogatepass")
    array = np.asarray(value)
    if array.dtype.kind == "O":
        return "\x1f".join(attr_text(item) for item in array.ravel().tolist()).encode("utf-8", "surrogatepass")
    return np.ascontiguousarray(array).tobytes()


def seal_result(group: h5py.Group) -> dict:
    """Give a result just written by its ``to_hdf5`` checksums: each dataset rewritten with a
    Fletcher32 filter (keeping its compression and attributes), then the result's SHA-256.
    Returns the group's attributes (read once, for the caller's summary)."""
    names = []
    group.visit(names.append)
    for name in names:
        node = group.get(name)
        if not isinstance(node, h5py.Dataset) or node.fletcher32 or node.shape in ((), None) or node.size == 0:
            continue
        data = node[()]
        attrs = {key: node.attrs[key] for key in node.attrs}
        compression, options = node.compression, node.compression_opts
        parent = node.parent
        leaf = name.rsplit("/", 1)[-1]
        del parent[leaf]
        copy = parent.create_dataset(
            leaf, data=data, chunks=True, fletcher32=True, compression=compression, compression_opts=options
        )
        for key, value in attrs.items():
            copy.attrs[key] = value
    attrs = read_attrs(group)
    attrs["content_sha256"] = result_sha256(group, attrs)
    group.attrs["content_sha256"] = attrs["content_sha256"]
    return attrs


def check_result(group: h5py.Group, path) -> None:
    """Raise `DamagedObjectError` when a stored result does not match its SHA-256 (results stored
    before schema 2 have none and are not checked)."""
    try:
        expected = group.attrs.get("content_sha256")
        if expected is not None and attr_text(expected) != result_sha256(group):
            raise DamagedObjectError(path, f"the result {group.name} does not match its SHA-256")
    except (OSError, RuntimeError, KeyError) as exc:
        if isinstance(exc, DamagedObjectError):
            raise
        raise DamagedObjectError(path, f"the result {group.name} cannot be read ({_first_line(exc)})") from None


def verify_object(path: Path) -> list[str]:
    """Read everything in an object file; return what is wrong (empty when it is whole).

    Checks the root, the catalog, results and duplicates tables, every pass (checksums and
    content hash), every stored result (its SHA-256), and that the catalog lists exactly the
    stored passes.
    """
    problems: list[str] = []
    try:
        file = open_object(path)
    except DamagedObjectError as exc:
        return [exc.reason]
    with file:
        try:
            rows = layout.read_catalog(file)
            layout.read_results(file)
            layout.read_duplicates(file)
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            return [f"its tables cannot be read ({_first_line(exc)})"]
        try:
            stored = set(file["passes"])
        except (OSError, RuntimeError, KeyError) as exc:
            return [f"its passes cannot be listed ({_first_line(exc)})"]
        listed = {row.pass_id for row in rows}
        if listed != stored:
            missing, extra = sorted(listed - stored), sorted(stored - listed)
            problems.append(f"its catalog lists {len(missing)} pass(es) not stored and omits {len(extra)}")
        for pass_id in sorted(stored & listed):
            try:
                group = file["passes"][pass_id]
                layout.read_pass(group)
                for kind in layout.RESULT_KINDS:
                    if kind in group:
                        for name in group[kind]:
                            check_result(group[kind][name], path)
            except DamagedObjectError as exc:
                problems.append(exc.reason)
            except layout.DamagedPassError as exc:
                problems.append(str(exc))
            except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
                problems.append(f"pass {pass_id} cannot be read ({_first_line(exc)})")
    return problems
