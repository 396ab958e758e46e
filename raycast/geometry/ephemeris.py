"""The offline ephemeris and timescale every geometry computation uses.

Nothing here touches the network. The JPL DE421 planetary ephemeris comes from the
``skyfield-data`` package (``de421.bsp``, valid 1899-07-29 to 2053-10-09), and the timescale
uses the leap-second, Delta T and UT1 tables that skyfield carries inside itself
(``load.timescale(builtin=True)``; their predictions reach 2027). The timescale has no
polar-motion table, so the ITRS used by `raycast.geometry` ignores polar motion (at most
~0.5 arcsec, ~15 m on the ground).

Both objects are loaded once per process and shared; they are read-only.

Examples
--------
>>> from raycast.geometry import ephemeris
>>> ts = ephemeris.timescale()
>>> sun = ephemeris.planets()["sun"]
"""

from __future__ import annotations

import functools
from pathlib import Path
import warnings

from skyfield.api import Loader
import skyfield_data

__all__ = ["EPHEMERIS_FILE", "data_path", "loader", "timescale", "planets"]

EPHEMERIS_FILE = "de421.bsp"


def data_path() -> Path:
    """Directory of the ``skyfield-data`` package's files.

    Returns
    -------
    pathlib.Path
        The directory holding ``de421.bsp``.
    """
    # skyfield-data warns about its own copy of finals2000A.all expiring; the project never
    # reads that file (the timescale is skyfield's built-in one), so the warning is noise.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The file .* has expired", category=RuntimeWarning)
        return Path(skyfield_data.get_skyfield_data_path())


@functools.cache
def loader():
    """A skyfield ``Loader`` rooted in the ``skyfield-data`` directory (never downloads).

    Returns
    -------
    skyfield.iokit.Loader
    """
    return Loader(str(data_path()), verbose=False)


@functools.cache
def timescale():
    """The shared skyfield timescale, built from skyfield's internal tables.

    Returns
    -------
    skyfield.timelib.Timescale
    """
    return loader().timescale(builtin=True)


@functools.cache
def planets():
    """The DE421 ephemeris from the ``skyfield-data`` package.

    Returns
    -------
    skyfield.jpllib.SpiceKernel

    Raises
    ------
    FileNotFoundError
        When the package's ``de421.bsp`` is missing (skyfield would otherwise download it).
    """
    path = data_path() / EPHEMERIS_FILE
    if not path.is_file():
        raise FileNotFoundError(
            f"{EPHEMERIS_FILE} is missing from {path.parent}; reinstall the skyfield-data package "
            "(pip install --force-reinstall skyfield-data)"
        )
    return loader()(EPHEMERIS_FILE)
