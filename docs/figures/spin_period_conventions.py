"""Draw the spin-period conventions of rsodb.fit.conventions into docs/img/spin_period_conventions.png.

Every curve is computed by the project's own code (the attitude model, the pass geometry and
rsodb.fit.conventions), so the figure shows what a fit reports: run
``python docs/figures/spin_period_conventions.py`` after changing a convention.

Left: the published COSMOS 2502 state (P = 40.5 s, P_pr = 1620 s, theta = 7 deg, spinning about
body x) along 120 s of a real COSMOS 2502 pass over Derenivka: the body's turn about its spin
axis relative to each reference, minus t / P, so the precessing frame's is flat and the others
drift at the difference of the rates. Right: the closed form of the orbit-frame convention,
P / P_orb - 1 = (P / P_pr) cos(theta), for the two published objects' period ratios.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ingest.site import DERENIVKA  # noqa: E402
from raycast.geometry import PassGeometry  # noqa: E402
from raycast.geometry.orbit import Satellite  # noqa: E402
from rsodb.fit.conventions import angle_steps_about, bisector_azimuth, rates_hz  # noqa: E402
from rsodb.fit.model import ConvexFacets, SpinStateModel  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUTPUT = ROOT / "docs" / "img" / "spin_period_conventions.png"
TLES = ROOT.parent / "shared" / "data" / "tle" / "tles.txt"
STATE = {
    "spin_period_s": 40.5,
    "spin_phase_deg": 0.0,
    "precession_period_s": 1620.0,
    "precession_phase_deg": 60.0,
    "precession_angle_deg": 7.0,
}


def main() -> Path:
    satellite = Satellite.from_catalogue(TLES, 40358)
    start = np.datetime64("2024-01-11T17:08:00", "ns")
    times = start + (np.arange(0, 120.0, 0.25) * 1e9).astype("int64").astype("timedelta64[ns]")
    geometry = PassGeometry.compute(satellite, DERENIVKA, times, 0.0, n_sub=1)
    model = SpinStateModel(geometry, ConvexFacets.box(), "precessing", {"spin_axis": "x"}, (), "V", 1000.0)
    rotations = model.attitude_model(STATE).orientation(geometry.t_s, geometry.lvlh_gcrs[:, 0])
    lvlh = geometry.lvlh_gcrs[:, 0]
    t = geometry.t_s
    turns = {
        "inertial (sidereal)": np.concatenate([[0], np.cumsum(angle_steps_about(rotations, 0))]),
        "orbit frame (not precessing)": np.concatenate(
            [[0], np.cumsum(angle_steps_about(np.einsum("nji,njk->nik", lvlh, rotations), 0))]
        ),
        "light curve (synodic: about the\nSun-observer bisector)": -(
            bisector_azimuth(rotations, geometry, 0) - bisector_azimuth(rotations, geometry, 0)[0]
        ),
    }
    rates = rates_hz(model, STATE, geometry, "x")
    periods = {
        "parameter": STATE["spin_period_s"],
        "orbit frame": 1 / rates["orbit_frame"],
        "inertial": 1 / rates["inertial"],
        "light curve": 1 / rates["light_curve"],
    }

    figure, (left, right) = plt.subplots(1, 2, figsize=(12.5, 4.8), gridspec_kw={"width_ratios": [1.4, 1]})
    left.axhline(0.0, color="C0", lw=2, label=f"precessing frame: the parameter P = {periods['parameter']:.2f} s")
    for (name, angle), colour, key in zip(
        turns.items(), ("C3", "C1", "C2"), ("inertial", "orbit frame", "light curve")
    ):
        left.plot(
            t,
            angle / (2 * np.pi) - t / STATE["spin_period_s"],
            color=colour,
            lw=1.5,
            label=f"{name}: {periods[key]:.2f} s",
        )
    left.set_xlabel("seconds along the pass (COSMOS 2502, 2024-01-11 17:08 UTC, Derenivka)")
    left.set_ylabel("turns about the spin axis minus t / P")
    left.set_title("One spin state, four periods (P 40.5 s, P_pr 1620 s, theta 7 deg, axis x)", fontsize=10)
    left.legend(fontsize=8, loc="upper left")

    theta = np.linspace(0, 90, 91)
    for ratio, label in (
        (40.5 / 1620.0, "COSMOS 2502: P/P_pr = 40.5/1620"),
        (9.86 / 689.0, "TOPEX: P/P_pr = 9.86/689"),
    ):
        right.plot(theta, 100 * ratio * np.cos(np.radians(theta)), lw=1.5, label=label)
    right.axhline(1.0, color="0.5", lw=0.8, ls="--")
    right.text(2, 1.05, "default spin-period prior: +-1%", fontsize=8, color="0.4")
    right.set_xlabel("precession cone half-angle theta [deg]")
    right.set_ylabel("P / P_orb - 1  [%]")
    right.set_title("1 / P_orb = 1 / P + cos(theta) / P_pr", fontsize=10)
    right.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(OUTPUT, dpi=110)
    return OUTPUT


if __name__ == "__main__":
    print(main())
