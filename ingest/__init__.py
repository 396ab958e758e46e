"""Readers for observation files and their photometric reduction (no HDF5 here)."""
from ingest.observation import Pass, Reduction

__all__ = ["Pass", "Reduction"]
