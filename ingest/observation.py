"""The observed pass: one light curve of one object, in one band, from one site.

`Pass` is the unit that flows through the project: readers return it, the archive stores it,
period search and fitting read it. It is immutable; operations return new objects.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from ingest.elements import MAX_NORAD
from ingest.problems import FileWarning, RowProblem
from ingest.reduction import Reduction
from ingest.site import Site

__all__ = ["Pass", "ARRAY_FIELDS", "MAX_EXPOSURE_S"]

# The longest exposure a light-curve sample can have: one hour.
MAX_EXPOSURE_S = 3600.0

# Per-sample arrays of a pass, in storage order, with their dtypes.
ARRAY_FIELDS = {
    "time_utc": "datetime64[ns]",
    "mag": "float64",
    "mag_err": "float64",
    "flux": "float64",
    "flux_err": "float64",
    "az_deg": "float64",
    "el_deg": "float64",
    "range_km": "float64",
    "saturated": "bool",
    "valid": "bool",
}


@dataclass(frozen=True, eq=False)
class Pass:
    """One light curve of one object through one band at one site.

    All per-sample arrays have shape (n,) and share the time axis.

    Attributes
    ----------
    norad : int
        NORAD catalogue number.
    name : str
        Object name as written in the file.
    band : str
        Photometric band letter (``"V"``, ``"B"``, ``"R"``, ...).
    site : Site
        Where the pass was observed.
    exposure_s : float
        Exposure (integration) time of one sample, seconds.
    time_utc : (n,) datetime64[ns]
        UTC at mid-exposure, strictly increasing.
    mag : (n,) float
        Magnitude as written by the file (for ccd_phot: standard magnitude reduced to 1000 km).
    mag_err : (n,) float
        1-sigma magnitude error.
    flux, flux_err : (n,) float
        Background-subtracted counts per exposure and their error; NaN where the format has none.
    az_deg, el_deg, range_km : (n,) float
        Topocentric azimuth, elevation (as written, refraction included) and range from the file.
    saturated : (n,) bool
        Frames flagged as saturated by the photometry (kept, not dropped).
    valid : (n,) bool
        False where the file marks the magnitude as bad (sentinel values) or it is not finite.
    cospar : str
        International designator.
    tle : tuple of str or None
        The TLE lines from the header (two lines, or three with the name line).
    omm : mapping or None
        The OMM record from the header when the file carries one instead of a TLE.
    time_convention : str
        What `time_utc` means; always mid-exposure after ingest.
    time_shift_s : float
        Seconds added to the file's time stamps to reach mid-exposure.
    mag_convention : str
        What `mag` means (reduction to 1000 km range or not).
    source_name, source_sha256, source_format : str
        File name, SHA-256 of its bytes, and reader that parsed it.
    reduction : Reduction or None
        Zero point and extinction term recovered from the file.
    mag_corrected : (n,) float or None
        Magnitudes with the extinction sign error undone; None when the file had no error.
    header : mapping
        Every header key and value as read, for provenance.
    row_problems : tuple of RowProblem
        Rows of the file that the reader set aside (with line, reason and the row as written);
        their values are not in the arrays above.
    warnings : tuple of FileWarning
        Where the file's header disagrees with its data (an end time long after the last row, a
        filter letter that contradicts the magnitude column, ...).
    elements_source : mapping or None
        Where `tle` / `omm` came from when not from the file's own header: catalogue file,
        its SHA-256, the set's epoch and its age at the pass (see `ingest.elements`).
    """

    norad: int
    name: str
    band: str
    site: Site
    exposure_s: float
    time_utc: np.ndarray
    mag: np.ndarray
    mag_err: np.ndarray
    flux: np.ndarray
    flux_err: np.ndarray
    az_deg: np.ndarray
    el_deg: np.ndarray
    range_km: np.ndarray
    saturated: np.ndarray
    valid: np.ndarray
    cospar: str = ""
    tle: tuple[str, ...] | None = None
    omm: Mapping | None = None
    time_convention: str = "UTC, mid-exposure"
    time_shift_s: float = 0.0
    mag_convention: str = ""
    source_name: str = ""
    source_sha256: str = ""
    source_format: str = ""
    reduction: Reduction | None = None
    mag_corrected: np.ndarray | None = None
    header: Mapping = field(default_factory=dict)
    row_problems: tuple[RowProblem, ...] = ()
    warnings: tuple[FileWarning, ...] = ()
    elements_source: Mapping | None = None

    def __post_init__(self):
        if isinstance(self.norad, bool) or not isinstance(self.norad, (int, np.integer)):
            raise TypeError(f"pass {self.source_name!r}: norad={self.norad!r} must be an integer catalogue number")
        if not 0 < int(self.norad) <= MAX_NORAD:
            raise ValueError(
                f"pass {self.source_name!r}: norad={self.norad} is not a catalogue number (1..{MAX_NORAD})"
            )
        object.__setattr__(self, "norad", int(self.norad))
        object.__setattr__(self, "row_problems", tuple(self.row_problems))
        object.__setattr__(self, "warnings", tuple(self.warnings))
        n = None
        for name, dtype in ARRAY_FIELDS.items():
            value = np.asarray(getattr(self, name), dtype=dtype)
            if value.ndim != 1:
                raise ValueError(f"pass {self.source_name!r}: {name} must be 1-D, got shape {value.shape}")
            if n is None:
                n = value.shape[0]
            elif value.shape[0] != n:
                raise ValueError(f"pass {self.source_name!r}: {name} has {value.shape[0]} samples but time_utc has {n}")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.mag_corrected is not None:
            corrected = np.asarray(self.mag_corrected, dtype="float64")
            if corrected.shape != (n,):
                raise ValueError(
                    f"pass {self.source_name!r}: mag_corrected has shape {corrected.shape}, expected ({n},)"
                )
            corrected.setflags(write=False)
            object.__setattr__(self, "mag_corrected", corrected)
        if n == 0:
            raise ValueError(f"pass {self.source_name!r} has no samples")
        if not (np.isfinite(self.exposure_s) and 0 < self.exposure_s <= MAX_EXPOSURE_S):
            raise ValueError(
                f"pass {self.source_name!r}: exposure_s={self.exposure_s!r} must be positive and at most {MAX_EXPOSURE_S:g} s"
            )
        if np.any(np.diff(self.time_utc.view("int64")) <= 0):
            raise ValueError(f"pass {self.source_name!r}: time_utc must be strictly increasing")

    # Headers and OMM records are read-only mappings (MappingProxyType), which pickle cannot
    # send to another process; they travel as plain dicts and are frozen again on arrival.
    def __getstate__(self):
        state = dict(self.__dict__)
        for name in ("header", "omm", "elements_source"):
            if isinstance(state.get(name), MappingProxyType):
                state[name] = dict(state[name])
        return state

    def __setstate__(self, state):
        for name in ("header", "omm", "elements_source"):
            if isinstance(state.get(name), dict):
                state[name] = MappingProxyType(state[name])
        self.__dict__.update(state)

    # -- derived views -------------------------------------------------------------------
    def __len__(self) -> int:
        return self.time_utc.shape[0]

    @property
    def start_utc(self) -> np.datetime64:
        """First mid-exposure time."""
        return self.time_utc[0]

    @property
    def end_utc(self) -> np.datetime64:
        """Last mid-exposure time."""
        return self.time_utc[-1]

    @property
    def time(self):
        """The mid-exposure times as an astropy ``Time`` (UTC)."""
        # astropy.time loads in about half a second; readers and the archive do not need it.
        from astropy.time import Time

        return Time(self.time_utc, scale="utc")

    @property
    def duration_s(self) -> float:
        """Seconds between the first and last sample."""
        return float((self.time_utc[-1] - self.time_utc[0]) / np.timedelta64(1, "s"))

    @property
    def t_s(self) -> np.ndarray:
        """(n,) float seconds since the first sample."""
        return (self.time_utc - self.time_utc[0]) / np.timedelta64(1, "s")

    @property
    def best_mag(self) -> np.ndarray:
        """(n,) the corrected magnitude where the file needed a correction, else `mag`."""
        return self.mag if self.mag_corrected is None else self.mag_corrected

    def replace(self, **changes) -> Pass:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def to_pandas(self):
        """The per-sample arrays as a DataFrame indexed by UTC time."""
        # pandas costs about half a second to import; only this conversion needs it.
        import pandas as pd

        columns = {name: getattr(self, name) for name in ARRAY_FIELDS if name != "time_utc"}
        if self.mag_corrected is not None:
            columns["mag_corrected"] = self.mag_corrected
        frame = pd.DataFrame(columns, index=pd.DatetimeIndex(self.time_utc, name="time_utc"))
        frame.attrs.update(
            norad=self.norad,
            name=self.name,
            band=self.band,
            site=self.site.name,
            exposure_s=self.exposure_s,
            source_name=self.source_name,
        )
        return frame

    def __repr__(self) -> str:
        return (
            f"Pass(norad={self.norad}, name={self.name!r}, band={self.band!r}, site={self.site.name!r}, "
            f"start={str(self.start_utc)[:23]}, n={len(self)}, exposure_s={self.exposure_s})"
        )
