"""The observation archive: a directory of crash-safe HDF5 files, one per object, and its index.

>>> from rsodb.archive import Archive                                  # doctest: +SKIP
>>> archive = Archive("archive")                                       # doctest: +SKIP
>>> print(archive.ingest(["observations/"]).summary())                 # doctest: +SKIP
>>> [p.pass_id for p in archive.passes(norad=22076, band="V")]         # doctest: +SKIP
>>> archive.catalog(period_min=5, verdict="confident")                 # doctest: +SKIP

The layout (readable with plain h5py and pandas) is described in `rsodb.archive.layout` and
docs/archive.md.
"""

from rsodb.archive.check import CheckReport, check_archive
from rsodb.archive.ingest_report import (
    CommitEvent,
    DuplicateFile,
    IngestedFile,
    IngestReport,
    IngestWarning,
    PendingFile,
)
from rsodb.archive.integrity import DamagedObjectError
from rsodb.archive.store import Archive, ElementsReport, UnknownPassError
from rsodb.archive.stored import (
    ArchivedObject,
    DamagedObject,
    DuplicateSource,
    PassSummary,
    ResultSummary,
    StoredPass,
    utc_text,
)

__all__ = [
    "Archive",
    "StoredPass",
    "PassSummary",
    "ResultSummary",
    "DuplicateSource",
    "ArchivedObject",
    "DamagedObject",
    "DamagedObjectError",
    "IngestReport",
    "IngestedFile",
    "DuplicateFile",
    "IngestWarning",
    "CommitEvent",
    "PendingFile",
    "UnknownPassError",
    "ElementsReport",
    "CheckReport",
    "check_archive",
    "utc_text",
]
