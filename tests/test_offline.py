"""Geometry never touches the network: the ephemeris and time tables ship with the packages."""

from __future__ import annotations

import socket
import subprocess
import sys
import textwrap
import urllib.request

import numpy as np
import pytest

from tests.conftest import PROJECT_ROOT

BLOCK_NETWORK = textwrap.dedent(
    """
    import socket

    def refuse(*args, **kwargs):
        raise OSError("network access attempted while the test forbids it")

    socket.socket.connect = refuse
    socket.socket.connect_ex = refuse
    socket.create_connection = refuse
    socket.getaddrinfo = refuse
    """
)

GEOMETRY = textwrap.dedent(
    """
    import urllib.request
    try:
        urllib.request.urlopen("https://ssd.jpl.nasa.gov/", timeout=5)
        print("NETWORK REACHABLE")
    except OSError:
        print("network blocked")

    import numpy as np
    from raycast.geometry.attitude import PrecessingSpin
    from raycast.geometry.pass_geometry import PassGeometry
    from raycast.geometry.orbit import Satellite
    from ingest.site import DERENIVKA

    satellite = Satellite.from_tle([
        "1 22076U 92052A   24212.51246405 -.00000054  00000-0  29042-4 0  9994",
        "2 22076  66.0414 118.8147 0008045 267.5347 265.0431 12.81066660495523"])
    times = np.datetime64("2024-07-30T21:22:40.008849") + np.arange(100) * np.timedelta64(200, "ms")
    geometry = PassGeometry.compute(satellite, DERENIVKA, times, exposure_s=0.2)
    body = geometry.body_frame(PrecessingSpin(period_s=9.86, precession_period_s=689.0, precession_angle_deg=35.0))
    print(geometry.el_refracted_deg[0], geometry.sunlit_fraction.min(), body.sun_body.shape)
    """
)


def test_a_fresh_process_computes_geometry_with_the_network_unreachable():
    result = subprocess.run(
        [sys.executable, "-c", BLOCK_NETWORK + GEOMETRY],
        cwd=PROJECT_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    assert lines[0] == "network blocked"
    # The file's first row says El 16.839 (refracted; 0.02 deg as in tests/test_geometry.py);
    # the pass is sunlit; 100 times x 4 exposure sub-samples.
    elevation, sunlit, shape = lines[1].split(" ", 2)
    assert float(elevation) == pytest.approx(16.839, abs=0.02)
    assert (float(sunlit), shape) == (1.0, "(100, 4, 3)")


def test_loading_the_ephemeris_again_needs_no_network(monkeypatch):
    from ingest.site import UZHHOROD
    from raycast.geometry import ephemeris
    from raycast.geometry.orbit import Satellite
    from raycast.geometry.pass_geometry import PassGeometry

    def refuse(*args, **kwargs):
        raise OSError("network access attempted while the test forbids it")

    for name in ("connect", "connect_ex"):
        monkeypatch.setattr(socket.socket, name, refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)
    monkeypatch.setattr(socket, "getaddrinfo", refuse)
    with pytest.raises(OSError):
        urllib.request.urlopen("https://celestrak.org/", timeout=5)
    for cached in (ephemeris.loader, ephemeris.timescale, ephemeris.planets):
        cached.cache_clear()
    assert ephemeris.planets()["sun"] is not None
    satellite = Satellite.from_tle(
        [
            "1 40358U 14086A   24009.55814244  .00000043  00000-0  83941-4 0  9993",
            "2 40358  67.1523  12.8839 0007020 252.7955 107.2362 13.97588796459621",
        ]
    )
    geometry = PassGeometry.compute(
        satellite, UZHHOROD, np.datetime64("2024-01-09T18:00") + np.arange(3) * np.timedelta64(1, "s")
    )
    assert np.all(np.isfinite(geometry.range_km))
