"""Readers for observation files and their photometric reduction (no HDF5 here).

>>> import ingest
>>> passes = ingest.read_file("result_22076_20240730_UT212240.phV")   # doctest: +SKIP
"""
from ingest.errors import FormatError
from ingest.observation import Pass, Reduction
from ingest.readers import READERS, detect_format, read_file

__all__ = ["Pass", "Reduction", "FormatError", "READERS", "detect_format", "read_file"]
