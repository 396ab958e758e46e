"""The on-disk layout of an archive: directory names, ids, and how a pass maps to HDF5.

An archive is a directory::

    rsodb-archive.json          marker: {"format": "rsodb archive", "schema_version": 2}
    catalog.sqlite              derived index of every pass and result (rsodb.archive.index)
    objects/<NORAD>.h5          everything about one object: passes, periods, fits
    objects/<NORAD>.lock        advisory lock file of that object's writers
    chains/<NORAD>/<pass_id>/<name>.h5   emcee HDFBackend files (written in place by the sampler)
    damaged/                    object files moved aside by ``rsodb check --repair``

and one object file holds (all names below are literal HDF5 paths)::

    /                      attrs: schema_version, format, norad, name, cospar, updated_utc,
                           sample_units (JSON: the unit of every samples column),
                           catalog_time_units
    /catalog               (m,) compound table, one row per stored pass version
    /results               one row per stored result: pass, kind, name, period, verdict
    /duplicates            one row per file recorded as a duplicate source of a stored pass
    /passes/<pass_id>      attrs: metadata (JSON: everything that is not a per-sample array),
                           content_sha256 (of samples, metadata and row problems)
    /passes/<pass_id>/samples   (n,) compound table: time_utc (int64 ns since 1970-01-01 UTC),
                           mag, mag_err, flux, flux_err, az_deg, el_deg, range_km, saturated,
                           valid[, mag_corrected]
    /passes/<pass_id>/row_problems   rows the reader set aside: line, reason, text
    /passes/<pass_id>/periods/<name>   written by a result's to_hdf5(group)
    /passes/<pass_id>/fits/<name>

Every table is written with an HDF5 Fletcher32 checksum, and each pass carries a SHA-256 of its
content checked on every read, so damage is an error naming the file, never a wrong number.
docs/archive.md is the reader's guide to this layout.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import h5py
import numpy as np

from ingest.observation import ARRAY_FIELDS, Pass
from ingest.problems import FileWarning, RowProblem
from ingest.reduction import Reduction
from ingest.site import Site
from rsodb.archive.stored import DuplicateSource, PassSummary, ResultSummary, StoredPass, utc_text
from rsodb.storage import attr_text, to_json

__all__ = [
    "SCHEMA_VERSION",
    "FORMAT_NAME",
    "MARKER_NAME",
    "INDEX_NAME",
    "OBJECTS_DIR",
    "CHAINS_DIR",
    "DAMAGED_DIR",
    "STAGING_DIR",
    "RESULT_KINDS",
    "TIME_UNITS",
    "object_file_name",
    "lock_file_name",
    "band_key",
    "natural_pass_id",
    "versioned_pass_id",
    "samples_table",
    "content_sha256",
    "pass_metadata",
    "write_pass",
    "rewrite_metadata",
    "write_file_attributes",
    "read_pass",
    "read_samples",
    "write_catalog",
    "read_catalog",
    "write_results",
    "read_results",
    "result_summary",
    "write_duplicates",
    "read_duplicates",
    "check_schema",
    "DamagedPassError",
]

SCHEMA_VERSION = 2
FORMAT_NAME = "rsodb archive"
MARKER_NAME = "rsodb-archive.json"
INDEX_NAME = "catalog.sqlite"
OBJECTS_DIR = "objects"
CHAINS_DIR = "chains"
DAMAGED_DIR = "damaged"
STAGING_DIR = "staging"  # an ingest's reader processes stage next object files here
RESULT_KINDS = ("periods", "fits")
TIME_UNITS = "ns since 1970-01-01T00:00:00 UTC (POSIX: leap seconds not counted), mid-exposure"

# Units of the sample columns, written once per samples table so the file explains itself.
SAMPLE_UNITS = {
    "time_utc": TIME_UNITS,
    "mag": "mag",
    "mag_err": "mag",
    "flux": "counts per exposure",
    "flux_err": "counts per exposure",
    "az_deg": "deg",
    "el_deg": "deg (refraction included)",
    "range_km": "km",
    "saturated": "bool",
    "valid": "bool",
    "mag_corrected": "mag",
}

# Table columns: a numpy dtype, or TEXT for UTF-8 text. Text is stored as fixed-length bytes
# sized to the longest value of each table (see text_table), inline in the table's chunk, so the table's Fletcher32
# checksum covers it (HDF5's variable-length strings live in a heap no checksum covers).
TEXT = "text"
# Text columns of the tables rewritten at every commit are padded to a multiple of this width.
_WIDTH_STEP = 16
CATALOG_FIELDS = (
    ("pass_id", TEXT),
    ("lineage_id", TEXT),
    ("natural_id", TEXT),
    ("version", "<i4"),
    ("supersedes", TEXT),
    ("superseded_by", TEXT),
    ("norad", "<i8"),
    ("name", TEXT),
    ("band", TEXT),
    ("site", TEXT),
    ("start_utc", "<i8"),
    ("end_utc", "<i8"),
    ("n_points", "<i8"),
    ("exposure_s", "<f8"),
    ("source_name", TEXT),
    ("source_sha256", TEXT),
    ("source_format", TEXT),
    ("ingested_utc", TEXT),
    ("n_row_problems", "<i8"),
    ("n_warnings", "<i8"),
    ("elements", TEXT),
)
RESULTS_FIELDS = (
    ("pass_id", TEXT),
    ("kind", TEXT),
    ("name", TEXT),
    ("stored_utc", TEXT),
    ("result_type", TEXT),
    ("period_s", "<f8"),
    ("period_err_s", "<f8"),
    ("verdict", TEXT),
)
DUPLICATES_FIELDS = (
    ("sha256", TEXT),
    ("source_name", TEXT),
    ("pass_id", TEXT),
    ("ingested_utc", TEXT),
    ("note", TEXT),
)
ROW_PROBLEMS_FIELDS = (("line", "<i8"), ("reason", TEXT), ("text", TEXT))
# HDF5 1.10 object headers carry checksums, so attributes (not only tables) are checked on read.
LIBVER = ("v110", "latest")


def text_table(fields, rows: list[tuple], width_step: int = 1) -> np.ndarray:
    """A structured array of `rows` with `fields`; text encoded as UTF-8 fixed-length bytes.

    Each text column is as wide as its longest value, rounded up to a multiple of `width_step`
    (read back the same: NUL padding is dropped). A step above 1 lets tables rewritten often share
    a few HDF5 types, which are costly to build.
    """
    columns = list(zip(*rows)) if rows else [()] * len(fields)
    values, dtype = {}, []
    for (name, kind), column in zip(fields, columns):  # column by column: one C loop a column
        if kind == TEXT:
            column = [value.encode("utf-8") for value in column]
            width = max([1, *map(len, column)])
            kind = f"S{-(-width // width_step) * width_step}"
        values[name] = column
        dtype.append((name, kind))
    table = np.empty(len(rows), dtype=dtype)
    if rows:
        for name, column in values.items():
            table[name] = column
    return table


class DamagedPassError(OSError):
    """A stored pass whose content no longer matches its checksum or hash."""


def object_file_name(norad: int) -> str:
    """File name of an object's HDF5 file inside ``objects/``."""
    return f"{int(norad)}.h5"


def lock_file_name(norad: int) -> str:
    """File name of an object's lock file inside ``objects/``."""
    return f"{int(norad)}.lock"


def band_key(band: str) -> str:
    """The band as it appears in a pass id: letters and digits as they are, a prime as ``p``
    and any other character as ``xNN`` (its code), so distinct bands give distinct ids.

    >>> band_key("V"), band_key("V'"), band_key("R_c")
    ('V', 'Vp', 'Rx5fc')
    """
    return "".join(c if c.isascii() and c.isalnum() else "p" if c == "'" else f"x{ord(c):02x}" for c in band) or "band"


def natural_pass_id(pass_: Pass) -> str:
    """``NORAD-YYYYmmddTHHMMSS-BAND-site`` from the pass's own data.

    The start is the first sample's time to the second. It is rounded to the millisecond first:
    a Julian date printed as a float64 holds 01:07:14.000 as 01:07:13.9999952, which is the same
    instant as far as any file can say (ccd_phot writes milliseconds), not the second before.
    """
    start = utc_text(pass_.start_utc, "s").replace("-", "").replace(":", "")
    return f"{pass_.norad}-{start}-{band_key(pass_.band)}-{pass_.site.key}"


def versioned_pass_id(lineage_id: str, version: int) -> str:
    """The id of `version` of the pass whose first version is `lineage_id`."""
    return lineage_id if version == 1 else f"{lineage_id}-v{version}"


# -- samples -------------------------------------------------------------------------------
def _samples_dtype(with_corrected: bool) -> np.dtype:
    fields = [
        (name, "<i8" if dtype.startswith("datetime64") else np.dtype(dtype).str) for name, dtype in ARRAY_FIELDS.items()
    ]
    if with_corrected:
        fields.append(("mag_corrected", "<f8"))
    return np.dtype(fields)


def samples_table(pass_: Pass) -> np.ndarray:
    """(n,) structured array of the pass's per-sample arrays; times as int64 ns since 1970 UTC."""
    table = np.empty(len(pass_), dtype=_samples_dtype(pass_.mag_corrected is not None))
    for name in ARRAY_FIELDS:
        value = getattr(pass_, name)
        table[name] = value.view("int64") if name == "time_utc" else value
    if pass_.mag_corrected is not None:
        table["mag_corrected"] = pass_.mag_corrected
    return table


def _row_problems_table(problems) -> np.ndarray:
    return text_table(ROW_PROBLEMS_FIELDS, [(problem.line, problem.reason, problem.text) for problem in problems])


def content_sha256(samples: np.ndarray, metadata_json: str, row_problems: np.ndarray | None = None) -> str:
    """SHA-256 of what a pass group holds: its samples' bytes, its metadata text and its row
    problems. Stored as the group's ``content_sha256`` and checked on every read."""
    digest = hashlib.sha256(np.ascontiguousarray(samples).tobytes())
    digest.update(metadata_json.encode("utf-8"))
    if row_problems is not None and len(row_problems):
        for line, reason, text in row_problems.tolist():
            digest.update(f"{line}\t{attr_text(reason)}\t{attr_text(text)}\n".encode())
    return digest.hexdigest()


def memory_sha256(pass_: Pass) -> str:
    """SHA-256 of a pass's samples and identity, for passes that did not come from a file."""
    digest = hashlib.sha256(samples_table(pass_).tobytes())
    identity = [pass_.norad, pass_.band, pass_.site.name, float(pass_.exposure_s), pass_.source_name]
    digest.update(json.dumps(identity).encode())
    return digest.hexdigest()


# -- metadata ------------------------------------------------------------------------------
def _elements_kind(pass_: Pass) -> str:
    if pass_.tle is None and pass_.omm is None:
        return ""
    return "catalogue" if pass_.elements_source else "header"


def pass_metadata(
    pass_: Pass,
    *,
    pass_id: str,
    lineage_id: str,
    natural_id: str,
    version: int,
    supersedes: str | None,
    ingested_utc: str,
) -> dict:
    """Everything about a pass except its per-sample arrays, as a JSON-ready dict."""
    reduction = pass_.reduction
    return {
        "pass_id": pass_id,
        "lineage_id": lineage_id,
        "natural_id": natural_id,
        "version": version,
        "supersedes": supersedes,
        "ingested_utc": ingested_utc,
        "norad": int(pass_.norad),
        "name": pass_.name,
        "cospar": pass_.cospar,
        "band": pass_.band,
        "site": {
            "name": pass_.site.name,
            "lat_deg": pass_.site.lat_deg,
            "lon_deg": pass_.site.lon_deg,
            "elevation_m": pass_.site.elevation_m,
        },
        "exposure_s": float(pass_.exposure_s),
        "n_points": len(pass_),
        "start_utc": np.datetime_as_string(pass_.start_utc, unit="ns") + "Z",
        "end_utc": np.datetime_as_string(pass_.end_utc, unit="ns") + "Z",
        "time_convention": pass_.time_convention,
        "time_shift_s": float(pass_.time_shift_s),
        "mag_convention": pass_.mag_convention,
        "tle": list(pass_.tle) if pass_.tle is not None else None,
        "omm": dict(pass_.omm) if pass_.omm is not None else None,
        "elements_source": dict(pass_.elements_source) if pass_.elements_source else None,
        "source_name": pass_.source_name,
        "source_sha256": pass_.source_sha256,
        "source_format": pass_.source_format,
        "reduction": None
        if reduction is None
        else {
            name: (value.item() if isinstance(value, np.generic) else value)
            for name, value in dataclasses.asdict(reduction).items()
        },
        "warnings": [warning.to_dict() for warning in pass_.warnings],
        "n_row_problems": len(pass_.row_problems),
        "header": dict(pass_.header),
    }


_TYPE_IDS: dict[np.dtype, h5py.h5t.TypeID] = {}
# Attributes as h5py's high-level API stores them (text: variable-length UTF-8; integers: int64;
# both scalar), written and read through its low-level API: the high-level one costs ~0.15 ms per
# attribute, and a commit of one small pass writes eleven.
_TEXT_DTYPE = h5py.string_dtype()
_ATTR_TYPES = {str: h5py.h5t.py_create(_TEXT_DTYPE, logical=True), int: h5py.h5t.py_create(np.dtype(np.int64))}


def set_attrs(node: h5py.HLObject, values: dict) -> None:
    """``node.attrs[name] = value`` for each item (text and integers fast, anything else as h5py does)."""
    for name, value in values.items():
        kind = str if isinstance(value, str) else int if isinstance(value, (int, np.integer)) else None
        if kind is None or isinstance(value, bool):
            node.attrs[name] = value
            continue
        key = name.encode()
        if h5py.h5a.exists(node.id, key):
            h5py.h5a.delete(node.id, key)
        data = np.array(value, dtype=_TEXT_DTYPE if kind is str else np.int64)
        h5py.h5a.create(node.id, key, _ATTR_TYPES[kind], h5py.h5s.create(h5py.h5s.SCALAR)).write(data)


# Numpy dtypes (and their HDF5 memory types) of stored types, by the stored type's encoding:
# h5py derives them anew on every high-level read, ~0.1 ms a field for a table's compound type.
_MEMORY_TYPES: dict[bytes, tuple[np.dtype, h5py.h5t.TypeID]] = {}


def _memory_type(type_id: h5py.h5t.TypeID) -> tuple[np.dtype, h5py.h5t.TypeID]:
    key = type_id.encode()
    found = _MEMORY_TYPES.get(key)
    if found is None:
        if len(_MEMORY_TYPES) > 256:
            _MEMORY_TYPES.clear()
        dtype = type_id.dtype
        found = _MEMORY_TYPES[key] = (dtype, h5py.h5t.py_create(dtype))  # as h5py reads
    return found


def read_table(node: h5py.Group, name: str) -> np.ndarray:
    """``node[name][()]`` through h5py's low-level API with cached types (a KeyError if absent).

    A failed Fletcher32 checksum raises OSError, as the high-level read does.
    """
    dataset = h5py.h5d.open(node.id, name.encode())
    dtype, memory_type = _memory_type(dataset.get_type())
    data = np.empty(dataset.shape, dtype=dtype)
    if data.size:
        dataset.read(h5py.h5s.ALL, h5py.h5s.ALL, data, memory_type)
    return data


def get_attrs(node: h5py.HLObject, names) -> dict:
    """``{name: node.attrs[name]}`` for those of `names` that `node` has (variable-length text as str)."""
    found = {}
    for name in names:
        key = name.encode()
        if not h5py.h5a.exists(node.id, key):
            continue
        attr = h5py.h5a.open(node.id, key)
        dtype, memory_type = _memory_type(attr.get_type())
        data = np.empty(attr.shape, dtype=dtype)
        attr.read(data, memory_type)
        value = data[()]
        if isinstance(value, bytes):
            # The cached dtype's string info (``attr.dtype`` derives a new dtype, ~0.05 ms).
            string = h5py.check_string_dtype(dtype)
            if string is not None:
                value = value.decode(string.encoding)
        found[name] = value
    return found


def _create_table(group: h5py.Group, name: str, table: np.ndarray) -> None:
    """``group[name] = table`` with a Fletcher32 checksum and a cached HDF5 compound type.

    h5py's high-level ``create_dataset`` rebuilds the compound type on every call, which was a
    third of the time to store a pass. The checksum needs a chunked layout: one chunk holds the
    whole table (an empty table has nothing to protect and stays contiguous).
    """
    type_id = _TYPE_IDS.get(table.dtype)
    if type_id is None:
        if len(_TYPE_IDS) > 256:  # text widths vary from table to table
            _TYPE_IDS.clear()
        type_id = _TYPE_IDS[table.dtype] = h5py.h5t.py_create(table.dtype, logical=True)
    plist = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    if len(table):
        plist.set_chunk((len(table),))
        plist.set_fletcher32()
    dataset = h5py.h5d.create(group.id, name.encode(), type_id, h5py.h5s.create_simple(table.shape), plist)
    # The cached type as the memory type too: without it h5py builds the compound type again.
    dataset.write(h5py.h5s.ALL, h5py.h5s.ALL, table, type_id)


def write_pass(passes_group: h5py.Group, pass_: Pass, metadata: dict) -> None:
    """Create ``passes_group[metadata['pass_id']]`` holding the pass's samples and metadata."""
    group = passes_group.create_group(metadata["pass_id"])
    samples = samples_table(pass_)
    text = to_json(metadata)
    problems = _row_problems_table(pass_.row_problems) if pass_.row_problems else None
    set_attrs(group, {"metadata": text, "content_sha256": content_sha256(samples, text, problems)})
    _create_table(group, "samples", samples)
    if problems is not None:
        _create_table(group, "row_problems", problems)


def rewrite_metadata(group: h5py.Group, metadata: dict) -> None:
    """Replace a stored pass's metadata (e.g. elements added later), keeping its hash true."""
    samples = read_samples(group)
    problems = group["row_problems"][()] if "row_problems" in group else None
    text = to_json(metadata)
    group.attrs["metadata"] = text
    group.attrs["content_sha256"] = content_sha256(samples, text, problems)


def write_file_attributes(file: h5py.File, norad: int) -> None:
    """The root attributes of a new object file: format, schema version, units of the tables."""
    set_attrs(
        file,
        {
            "format": FORMAT_NAME,
            "schema_version": SCHEMA_VERSION,
            "norad": norad,
            "sample_units": json.dumps(SAMPLE_UNITS),
            "catalog_time_units": TIME_UNITS,  # of the catalog's start_utc and end_utc
        },
    )


def read_samples(group: h5py.Group) -> np.ndarray:
    """The samples table of a pass group; a failed Fletcher32 checksum raises `DamagedPassError`."""
    try:
        return read_table(group, "samples")
    except OSError as exc:
        raise DamagedPassError(f"the samples of {group.name} fail their checksum ({exc})") from None


def read_metadata(group: h5py.Group) -> dict:
    """The metadata of a pass group, after checking the group's content hash (when it has one)."""
    text = attr_text(group.attrs["metadata"])
    expected = group.attrs.get("content_sha256")
    if expected is not None:
        samples = read_samples(group)
        problems = None
        if "row_problems" in group:
            try:
                problems = read_table(group, "row_problems")
            except OSError as exc:
                raise DamagedPassError(f"the row problems of {group.name} fail their checksum ({exc})") from None
        if content_sha256(samples, text, problems) != attr_text(expected):
            raise DamagedPassError(f"the content of {group.name} does not match its SHA-256")
    try:
        return json.loads(text)
    except ValueError as exc:
        raise DamagedPassError(f"the metadata of {group.name} is not valid JSON ({exc})") from None


def read_pass(group: h5py.Group, superseded_by: str | None = None) -> StoredPass:
    """The `StoredPass` stored in `group` (a ``/passes/<pass_id>`` group), verified.

    Raises
    ------
    DamagedPassError
        When a checksum or the content hash does not match: the stored values are not used.
    """
    meta = read_metadata(group)
    table = read_samples(group)
    arrays = {name: np.ascontiguousarray(table[name]) for name in ARRAY_FIELDS if name != "time_utc"}
    reduction = meta["reduction"]
    problems = ()
    if "row_problems" in group:
        problems = tuple(
            RowProblem(int(line), attr_text(reason), attr_text(text))
            for line, reason, text in read_table(group, "row_problems").tolist()
        )
    return StoredPass(
        norad=meta["norad"],
        name=meta["name"],
        band=meta["band"],
        site=Site(**meta["site"]),
        exposure_s=meta["exposure_s"],
        time_utc=table["time_utc"].astype("datetime64[ns]"),
        **arrays,
        cospar=meta["cospar"],
        tle=None if meta["tle"] is None else tuple(meta["tle"]),
        omm=meta["omm"],
        time_convention=meta["time_convention"],
        time_shift_s=meta["time_shift_s"],
        mag_convention=meta["mag_convention"],
        source_name=meta["source_name"],
        source_sha256=meta["source_sha256"],
        source_format=meta["source_format"],
        reduction=None if reduction is None else Reduction(**reduction),
        mag_corrected=(np.ascontiguousarray(table["mag_corrected"]) if "mag_corrected" in table.dtype.names else None),
        header=meta["header"],
        row_problems=problems,
        warnings=tuple(FileWarning(item["line"], item["reason"]) for item in meta.get("warnings", ())),
        elements_source=meta.get("elements_source"),
        pass_id=meta["pass_id"],
        version=meta["version"],
        supersedes=meta["supersedes"],
        superseded_by=superseded_by,
        ingested_utc=meta["ingested_utc"],
    )


# -- tables --------------------------------------------------------------------------------
def _has(node: h5py.Group, name: str) -> bool:
    """``name in node`` for a plain name, without h5py's high-level path handling."""
    return node.id.links.exists(name.encode())


def table_bytes(file: h5py.File, name: str) -> int:
    """Bytes stored for the table ``file[name]`` (0 when there is none)."""
    if not _has(file, name):
        return 0
    return int(h5py.h5d.open(file.id, name.encode()).get_storage_size())


def _replace_table(file: h5py.File, name: str, table: np.ndarray) -> None:
    if _has(file, name):
        file.id.unlink(name.encode())
    _create_table(file, name, table)


def _read_table(file: h5py.File, name: str) -> np.ndarray | None:
    if not _has(file, name):
        return None
    try:
        return read_table(file, name)
    except OSError as exc:
        raise DamagedPassError(f"the /{name} table fails its checksum ({exc})") from None


def summary_row(pass_: Pass, metadata: dict) -> PassSummary:
    """The catalog row of a pass about to be stored with `metadata`."""
    return PassSummary(
        pass_id=metadata["pass_id"],
        lineage_id=metadata["lineage_id"],
        natural_id=metadata["natural_id"],
        version=metadata["version"],
        supersedes=metadata["supersedes"],
        superseded_by=None,
        norad=int(pass_.norad),
        name=pass_.name,
        band=pass_.band,
        site=pass_.site.name,
        start_utc=pass_.start_utc,
        end_utc=pass_.end_utc,
        n_points=len(pass_),
        exposure_s=float(pass_.exposure_s),
        source_name=pass_.source_name,
        source_sha256=pass_.source_sha256,
        source_format=pass_.source_format,
        ingested_utc=metadata["ingested_utc"],
        n_row_problems=len(pass_.row_problems),
        n_warnings=len(pass_.warnings),
        elements=_elements_kind(pass_),
    )


def write_catalog(file: h5py.File, rows: list[PassSummary]) -> None:
    """Replace ``/catalog`` with `rows` (one per stored pass version)."""
    records = [
        (
            row.pass_id,
            row.lineage_id,
            row.natural_id,
            row.version,
            row.supersedes or "",
            row.superseded_by or "",
            row.norad,
            row.name,
            row.band,
            row.site,
            int(row.start_utc.astype("datetime64[ns]").view("int64")),
            int(row.end_utc.astype("datetime64[ns]").view("int64")),
            row.n_points,
            row.exposure_s,
            row.source_name,
            row.source_sha256,
            row.source_format,
            row.ingested_utc,
            row.n_row_problems,
            row.n_warnings,
            row.elements,
        )
        for row in rows
    ]
    _replace_table(file, "catalog", text_table(CATALOG_FIELDS, records, _WIDTH_STEP))


# The PassSummary fields a catalog row stores, in the order of the class (the period columns
# come from the index's results).
_SUMMARY_FIELDS = tuple(
    field.name for field in dataclasses.fields(PassSummary) if field.name not in ("period_s", "period_err_s", "verdict")
)


def read_catalog(file: h5py.File) -> list[PassSummary]:
    """The rows of ``/catalog`` in storage order (files of schema 1 lack the last columns)."""
    table = _read_table(file, "catalog")
    if table is None:
        return []
    n = len(table)
    # Whole columns as Python values at once: indexing a structured array
    # element by element costs microseconds a field.
    columns = {"n_row_problems": [0] * n, "n_warnings": [0] * n, "elements": [""] * n}  # schema 1 lacks them
    for name in table.dtype.names:
        kind = table.dtype[name].kind
        if kind == "S":
            columns[name] = [value.decode("utf-8") for value in table[name].tolist()]
        elif kind == "O":
            columns[name] = [attr_text(value) for value in table[name].tolist()]
        else:
            columns[name] = table[name].tolist()
    columns["start_utc"] = list(table["start_utc"].astype("datetime64[ns]"))
    columns["end_utc"] = list(table["end_utc"].astype("datetime64[ns]"))
    for name in ("supersedes", "superseded_by"):
        columns[name] = [value or None for value in columns[name]]
    rows = [PassSummary(*values) for values in zip(*(columns[name] for name in _SUMMARY_FIELDS))]
    return rows


def _finite(value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return float("nan")
    return value


def result_summary(pass_id: str, kind: str, name: str, group: h5py.Group, attrs=None) -> ResultSummary:
    """What the catalog keeps of a stored result: when, what, and its period and verdict.

    The period is the result's ``best_period_s`` attribute (a period search) and its error
    ``uncertainty_s``; a fit gives its spin period through its ``summary`` row named
    ``spin_period_s`` (median, half the 16-84 % width). Any result may have a ``verdict``.
    `attrs` are the group's attributes when the caller has read them already.
    """
    attrs = group.attrs if attrs is None else attrs
    period = _finite(attrs.get("best_period_s", float("nan")))
    error = _finite(attrs.get("uncertainty_s", float("nan")))
    if not np.isfinite(period) and "summary" in group:
        try:
            summary = group["summary"][()]
            names = [attr_text(value) for value in summary["name"].tolist()]
            for key in ("spin_period_s", "period_s", "P_s"):
                if key in names:
                    row = summary[names.index(key)]
                    period = float(row["median"])
                    error = float(row["p84"] - row["p16"]) / 2.0
                    break
        except (KeyError, ValueError, OSError):
            pass
    return ResultSummary(
        pass_id=pass_id,
        kind=kind,
        name=name,
        stored_utc=attr_text(attrs.get("stored_utc", "")),
        result_type=attr_text(attrs.get("result_type", "")),
        period_s=period if np.isfinite(period) else None,
        period_err_s=error if np.isfinite(error) else None,
        verdict=attr_text(attrs.get("verdict", "")) or None,
    )


def write_results(file: h5py.File, results: list[ResultSummary]) -> None:
    """Replace ``/results`` with `results`."""
    records = [
        (
            item.pass_id,
            item.kind,
            item.name,
            item.stored_utc,
            item.result_type,
            np.nan if item.period_s is None else item.period_s,
            np.nan if item.period_err_s is None else item.period_err_s,
            item.verdict or "",
        )
        for item in results
    ]
    _replace_table(file, "results", text_table(RESULTS_FIELDS, records, _WIDTH_STEP))


def read_results(file: h5py.File) -> list[ResultSummary]:
    """The rows of ``/results``; a file without the table (schema 1) is walked instead."""
    table = _read_table(file, "results")
    if table is None:
        found = []
        passes = file.get("passes", {})
        for pass_id in passes:
            group = passes[pass_id]
            for kind in RESULT_KINDS:
                if kind in group:
                    found.extend(result_summary(pass_id, kind, name, group[kind][name]) for name in group[kind])
        return found
    rows = []
    for record in table.tolist():
        pass_id, kind, name, stored_utc, result_type, period, error, verdict = record
        rows.append(
            ResultSummary(
                pass_id=attr_text(pass_id),
                kind=attr_text(kind),
                name=attr_text(name),
                stored_utc=attr_text(stored_utc),
                result_type=attr_text(result_type),
                period_s=None if not np.isfinite(period) else float(period),
                period_err_s=None if not np.isfinite(error) else float(error),
                verdict=attr_text(verdict) or None,
            )
        )
    return rows


def write_duplicates(file: h5py.File, duplicates: list[DuplicateSource]) -> None:
    """Replace ``/duplicates`` with `duplicates`."""
    records = [(item.sha256, item.source_name, item.pass_id, item.ingested_utc, item.note) for item in duplicates]
    _replace_table(file, "duplicates", text_table(DUPLICATES_FIELDS, records, _WIDTH_STEP))


def read_duplicates(file: h5py.File) -> list[DuplicateSource]:
    """The rows of ``/duplicates`` (none in files of schema 1)."""
    table = _read_table(file, "duplicates")
    if table is None:
        return []
    return [DuplicateSource(*map(attr_text, record)) for record in table.tolist()]


def check_schema(file: h5py.File, path) -> None:
    """Refuse object files written by a newer, incompatible schema."""
    check_schema_version(file.attrs.get("schema_version", -1), path)


def check_schema_version(value, path) -> None:
    """Refuse an object file (at `path`) whose root attribute schema_version is `value`, if newer."""
    version = int(value)
    if version < 1 or version > SCHEMA_VERSION:
        raise ValueError(
            f"{path} has schema_version {version}, but this rsodb reads versions 1..{SCHEMA_VERSION}; "
            "upgrade rsodb or open the archive with the version that wrote it"
        )
