"""Readers for observation files and their photometric reduction (no HDF5 here).

The front door: everything a notebook needs, loaded on first use.

>>> import ingest
>>> passes = ingest.read_file("result_22076_20240730_UT212240.phV")   # doctest: +SKIP
>>> passes[0].to_pandas()                                             # doctest: +SKIP
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "errors": ["FormatError"],
        "observation": ["Pass", "ARRAY_FIELDS"],
        "reduction": ["Reduction", "fit_reduction", "standard_mag"],
        "readers": ["READERS", "detect_format", "read_file", "read_pass"],
        "site": ["Site", "DERENIVKA", "UZHHOROD"],
        "elements": ["parse_tle", "parse_omm", "ElementCatalogue", "DEFAULT_MAX_AGE_DAYS"],
        "problems": ["RowProblem", "FileWarning"],
        "writers": ["write_ccd_phot", "write_phc", "write_csv"],
    },
)
