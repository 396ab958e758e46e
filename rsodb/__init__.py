"""The observation archive (HDF5), spin periods, fitting, campaigns, reports and the CLI."""
__version__ = "0.1.0"
