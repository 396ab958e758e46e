"""The observation archive: a directory of crash-safe HDF5 files, one per object.

>>> from rsodb.archive import Archive                                  # doctest: +SKIP
>>> archive = Archive("archive")                                       # doctest: +SKIP
>>> print(archive.ingest(["observations/"]).summary())                 # doctest: +SKIP
>>> [p.pass_id for p in archive.passes(norad=22076, band="V")]         # doctest: +SKIP

The layout (readable with plain h5py and pandas) is described in `rsodb.archive.layout` and
docs/archive.md.
"""

from rsodb.archive.ingest_report import CommitEvent, IngestedFile, IngestReport, PendingFile
from rsodb.archive.store import Archive, UnknownPassError
from rsodb.archive.stored import ArchivedObject, PassSummary, StoredPass

__all__ = [
    "Archive",
    "StoredPass",
    "PassSummary",
    "ArchivedObject",
    "IngestReport",
    "IngestedFile",
    "CommitEvent",
    "PendingFile",
    "UnknownPassError",
]
