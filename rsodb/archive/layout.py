"""The on-disk layout of an archive: directory names, ids, and how a pass maps to HDF5.

An archive is a directory::

    rsodb-archive.json          marker: {"format": "rsodb archive", "schema_version": 1}
    objects/<NORAD>.h5          everything about one object: passes, periods, fits
    objects/<NORAD>.lock        advisory lock file of that object's writers
    chains/<NORAD>/<pass_id>/<name>.h5   emcee HDFBackend files (written in place by the sampler)

and one object file holds (all names below are literal HDF5 paths)::

    /                      attrs: schema_version, format, norad, name, cospar, updated_utc,
                           sample_units (JSON: the unit of every samples column),
                           catalog_time_units
    /catalog               (m,) compound table, one row per stored pass version
    /passes/<pass_id>      attrs: metadata (JSON: everything that is not a per-sample array)
    /passes/<pass_id>/samples   (n,) compound table: time_utc (int64 ns since 1970-01-01 UTC),
                           mag, mag_err, flux, flux_err, az_deg, el_deg, range_km, saturated,
                           valid[, mag_corrected]
    /passes/<pass_id>/periods/<name>   written by a result's to_hdf5(group)
    /passes/<pass_id>/fits/<name>

docs/archive.md is the reader's guide to this layout.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import h5py
import numpy as np

from ingest.observation import ARRAY_FIELDS, Pass
from ingest.reduction import Reduction
from ingest.site import Site
from rsodb.archive.stored import PassSummary, StoredPass
from rsodb.storage import attr_text, to_json

__all__ = [
    "SCHEMA_VERSION",
    "FORMAT_NAME",
    "MARKER_NAME",
    "OBJECTS_DIR",
    "CHAINS_DIR",
    "RESULT_KINDS",
    "TIME_UNITS",
    "object_file_name",
    "lock_file_name",
    "natural_pass_id",
    "versioned_pass_id",
    "samples_table",
    "content_sha256",
    "pass_metadata",
    "write_pass",
    "write_file_attributes",
    "read_pass",
    "write_catalog",
    "read_catalog",
    "check_schema",
]

SCHEMA_VERSION = 1
FORMAT_NAME = "rsodb archive"
MARKER_NAME = "rsodb-archive.json"
OBJECTS_DIR = "objects"
CHAINS_DIR = "chains"
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

_STR = h5py.string_dtype("utf-8")
CATALOG_DTYPE = np.dtype(
    [
        ("pass_id", _STR),
        ("lineage_id", _STR),
        ("natural_id", _STR),
        ("version", "<i4"),
        ("supersedes", _STR),
        ("superseded_by", _STR),
        ("norad", "<i8"),
        ("name", _STR),
        ("band", _STR),
        ("site", _STR),
        ("start_utc", "<i8"),
        ("end_utc", "<i8"),
        ("n_points", "<i8"),
        ("exposure_s", "<f8"),
        ("source_name", _STR),
        ("source_sha256", _STR),
        ("source_format", _STR),
        ("ingested_utc", _STR),
    ]
)


def object_file_name(norad: int) -> str:
    """File name of an object's HDF5 file inside ``objects/``."""
    return f"{int(norad)}.h5"


def lock_file_name(norad: int) -> str:
    """File name of an object's lock file inside ``objects/``."""
    return f"{int(norad)}.lock"


def natural_pass_id(pass_: Pass) -> str:
    """``NORAD-YYYYmmddTHHMMSS-BAND-site`` from the pass's own data (start truncated to the second)."""
    start = np.datetime_as_string(pass_.start_utc, unit="s").replace("-", "").replace(":", "")
    band = "".join(c for c in pass_.band if c.isalnum()) or "band"
    return f"{pass_.norad}-{start}-{band}-{pass_.site.key}"


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


def content_sha256(pass_: Pass) -> str:
    """SHA-256 of a pass's samples and identity, for passes that did not come from a file."""
    digest = hashlib.sha256(samples_table(pass_).tobytes())
    identity = [pass_.norad, pass_.band, pass_.site.name, float(pass_.exposure_s), pass_.source_name]
    digest.update(json.dumps(identity).encode())
    return digest.hexdigest()


# -- metadata ------------------------------------------------------------------------------
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
        "source_name": pass_.source_name,
        "source_sha256": pass_.source_sha256,
        "source_format": pass_.source_format,
        "reduction": None
        if reduction is None
        else {
            name: (value.item() if isinstance(value, np.generic) else value)
            for name, value in dataclasses.asdict(reduction).items()
        },
        "header": dict(pass_.header),
    }


_TYPE_IDS: dict[np.dtype, h5py.h5t.TypeID] = {}


def _create_table(group: h5py.Group, name: str, table: np.ndarray) -> None:
    """``group[name] = table`` with a cached HDF5 compound type.

    h5py's high-level ``create_dataset`` rebuilds the compound type on every call, which was a
    third of the time to store a pass.
    """
    type_id = _TYPE_IDS.get(table.dtype)
    if type_id is None:
        type_id = _TYPE_IDS[table.dtype] = h5py.h5t.py_create(table.dtype, logical=True)
    dataset = h5py.h5d.create(group.id, name.encode(), type_id, h5py.h5s.create_simple(table.shape))
    dataset.write(h5py.h5s.ALL, h5py.h5s.ALL, table)


def write_pass(passes_group: h5py.Group, pass_: Pass, metadata: dict) -> None:
    """Create ``passes_group[metadata['pass_id']]`` holding the pass's samples and metadata."""
    group = passes_group.create_group(metadata["pass_id"])
    group.attrs["metadata"] = to_json(metadata)
    _create_table(group, "samples", samples_table(pass_))


def write_file_attributes(file: h5py.File, norad: int) -> None:
    """The root attributes of a new object file: format, schema version, units of the tables."""
    file.attrs["format"] = FORMAT_NAME
    file.attrs["schema_version"] = SCHEMA_VERSION
    file.attrs["norad"] = norad
    file.attrs["sample_units"] = json.dumps(SAMPLE_UNITS)
    file.attrs["catalog_time_units"] = TIME_UNITS  # of the catalog's start_utc and end_utc


def read_pass(group: h5py.Group, superseded_by: str | None = None) -> StoredPass:
    """The `StoredPass` stored in `group` (a ``/passes/<pass_id>`` group)."""
    meta = json.loads(group.attrs["metadata"])
    table = group["samples"][()]
    arrays = {name: np.ascontiguousarray(table[name]) for name in ARRAY_FIELDS if name != "time_utc"}
    reduction = meta["reduction"]
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
        pass_id=meta["pass_id"],
        version=meta["version"],
        supersedes=meta["supersedes"],
        superseded_by=superseded_by,
        ingested_utc=meta["ingested_utc"],
    )


# -- catalog -------------------------------------------------------------------------------
def write_catalog(file: h5py.File, rows: list[PassSummary]) -> None:
    """Replace ``/catalog`` with `rows` (one per stored pass version)."""
    table = np.empty(len(rows), dtype=CATALOG_DTYPE)
    for i, row in enumerate(rows):
        table[i] = (
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
            row.start_utc.astype("datetime64[ns]").view("int64"),
            row.end_utc.astype("datetime64[ns]").view("int64"),
            row.n_points,
            row.exposure_s,
            row.source_name,
            row.source_sha256,
            row.source_format,
            row.ingested_utc,
        )
    if "catalog" in file:
        del file["catalog"]
    _create_table(file, "catalog", table)


def read_catalog(file: h5py.File) -> list[PassSummary]:
    """The rows of ``/catalog`` in storage order."""
    if "catalog" not in file:
        return []
    table = file["catalog"][()]

    rows = []
    for record in table:
        rows.append(
            PassSummary(
                pass_id=attr_text(record["pass_id"]),
                lineage_id=attr_text(record["lineage_id"]),
                natural_id=attr_text(record["natural_id"]),
                version=int(record["version"]),
                supersedes=attr_text(record["supersedes"]) or None,
                superseded_by=attr_text(record["superseded_by"]) or None,
                norad=int(record["norad"]),
                name=attr_text(record["name"]),
                band=attr_text(record["band"]),
                site=attr_text(record["site"]),
                start_utc=np.datetime64(int(record["start_utc"]), "ns"),
                end_utc=np.datetime64(int(record["end_utc"]), "ns"),
                n_points=int(record["n_points"]),
                exposure_s=float(record["exposure_s"]),
                source_name=attr_text(record["source_name"]),
                source_sha256=attr_text(record["source_sha256"]),
                source_format=attr_text(record["source_format"]),
                ingested_utc=attr_text(record["ingested_utc"]),
            )
        )
    return rows


def check_schema(file: h5py.File, path) -> None:
    """Refuse object files written by a newer, incompatible schema."""
    version = int(file.attrs.get("schema_version", -1))
    if version < 1 or version > SCHEMA_VERSION:
        raise ValueError(
            f"{path} has schema_version {version}, but this rsodb reads versions 1..{SCHEMA_VERSION}; "
            "upgrade rsodb or open the archive with the version that wrote it"
        )
