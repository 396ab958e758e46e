"""Draw the attitude conventions of raycast.geometry.attitude into docs/img/attitude_conventions.png.

Every vector drawn is computed by the attitude models themselves, so the figure shows what the
code does: run ``python docs/figures/attitude_conventions.py`` after changing a convention.

Left: `PrecessingSpin` in the local orbital frame (LVLH: x along-track, y = -orbit normal,
z = nadir). Right: `InertialSpin` in GCRS (IAU convention: node = z x pole, W from the node).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from raycast.geometry.attitude import InertialSpin, PrecessingSpin  # noqa: E402

OUTPUT = Path(__file__).resolve().parents[1] / "img" / "attitude_conventions.png"


def arrow(ax, vector, color, label, origin=(0.0, 0.0, 0.0), offset=1.1, **kwargs):
    x, y, z = origin
    ax.quiver(x, y, z, *vector, color=color, arrow_length_ratio=0.08, linewidth=2, **kwargs)
    ax.text(*(np.asarray(origin) + offset * np.asarray(vector)), label, color=color, fontsize=9)


def arc(ax, start, end, radius, color, label, steps=40):
    """Arc from direction `start` to `end` (slerp) at `radius`, labelled at its middle."""
    start, end = start / np.linalg.norm(start), end / np.linalg.norm(end)
    angle = np.arccos(np.clip(start @ end, -1.0, 1.0))
    s = np.linspace(0.0, 1.0, steps)[:, None]
    points = (np.sin((1 - s) * angle) * start + np.sin(s * angle) * end) / np.sin(angle)
    ax.plot(*(radius * points).T, color=color, linewidth=1.2)
    ax.text(*(1.08 * radius * points[steps // 2]), label, color=color, fontsize=10)


def precessing_panel(ax):
    theta_deg, phi_deg = 35.0, 50.0
    model = PrecessingSpin(
        period_s=10.0, phase_deg=0.0, precession_phase_deg=phi_deg, precession_angle_deg=theta_deg, spin_axis="z"
    )
    rotation = model.orientation(np.zeros(1), np.eye(3)[None])[0]  # body axes in LVLH
    spin, reference = rotation[:, 2], rotation[:, 0]
    ex, ey, ez = np.eye(3)
    for vector, name in (
        (ex, "x: along-track\n(direction of motion)"),
        (ey, "y: -orbit normal"),
        (ez, "z: nadir (to Earth centre)"),
    ):
        arrow(ax, vector, "0.35", name)
    # The precession cone around nadir.
    a = np.linspace(0, 2 * np.pi, 90)
    th = np.radians(theta_deg)
    ax.plot(
        np.sin(th) * np.cos(a),
        np.sin(th) * np.sin(a),
        np.full_like(a, np.cos(th)),
        color="tab:blue",
        linewidth=0.8,
        linestyle=":",
    )
    arrow(ax, spin, "tab:blue", "spin axis s3\n(body 'z' here)")
    arrow(ax, reference, "tab:red", "reference axis s1 at psi = 0\n(body 'x' when spin_axis='z')")
    arc(ax, ez, spin, 0.55, "tab:blue", "theta")
    foot = np.array([spin[0], spin[1], 0.0])
    ax.plot(*np.stack([spin, foot]).T, color="tab:blue", linewidth=0.6, linestyle="--")
    arc(ax, ex, foot, 0.45, "tab:green", "phi")
    # The Earth lies along +z (nadir); z is drawn pointing down.
    a = np.linspace(-0.75, 0.75, 60)
    ax.plot(0 * a, 2.0 * np.sin(a), 1.3 + 2.0 * (1 - np.cos(a)), color="tab:brown", linewidth=2)
    ax.text(0.0, 0.15, 1.45, "Earth", color="tab:brown", fontsize=10)
    ax.text2D(
        0.02,
        0.02,
        "theta: cone half-angle (spin axis to nadir)\n"
        "phi: azimuth of the spin axis about nadir, from +x toward +y\n"
        "psi: spin angle; at psi = 0 the reference axis lies in the\n"
        "plane of nadir and spin axis, on the side away from the Earth",
        transform=ax.transAxes,
        fontsize=8.5,
    )
    ax.set_title(
        "PrecessingSpin: R = LVLH Rz(phi) Ry(theta) Rz(psi)\nphi = phi0 + 360 t / P_pr,  psi = psi0 + 360 t / P",
        fontsize=10,
    )


def inertial_panel(ax):
    ra_deg, dec_deg, w_deg = 60.0, 35.0, 50.0
    zero = InertialSpin(pole_ra_deg=ra_deg, pole_dec_deg=dec_deg, period_s=np.inf, phase_deg=0.0).orientation(0.0)
    turned = InertialSpin(pole_ra_deg=ra_deg, pole_dec_deg=dec_deg, period_s=np.inf, phase_deg=w_deg).orientation(0.0)
    pole, node, reference = zero[:, 2], zero[:, 0], turned[:, 0]
    ex, ey, ez = np.eye(3)
    for vector, name in ((ex, "X (equinox)"), (ey, "Y"), (ez, "Z (celestial pole)")):
        arrow(ax, vector, "0.35", name)
    a = np.linspace(0, 2 * np.pi, 120)
    ax.plot(np.cos(a), np.sin(a), 0 * a, color="0.6", linewidth=0.6)  # celestial equator
    second = np.cross(pole, node)
    ax.plot(
        *(0.8 * (np.outer(np.cos(a), node) + np.outer(np.sin(a), second))).T,
        color="tab:blue",
        linewidth=0.6,
        linestyle=":",
    )  # the body's equator
    arrow(ax, pole, "tab:blue", "pole (ra, dec): spin axis")
    arrow(ax, node, "tab:purple", "node = Z x pole (W = 0)")
    arrow(ax, reference, "tab:red", "reference axis at W")
    equator_point = np.array([np.cos(np.radians(ra_deg)), np.sin(np.radians(ra_deg)), 0.0])
    arc(ax, ex, equator_point, 0.5, "tab:green", "ra")
    arc(ax, equator_point, pole, 0.6, "tab:green", "dec")
    arc(ax, node, reference, 0.8, "tab:red", "W")
    ax.text2D(
        0.02,
        0.02,
        "pole at (ra, dec) in GCRS; W = W0 + 360 t / P measured from the node\n"
        "(ascending node of the body's equator on the ICRF equator, RA = ra + 90)\n"
        "counterclockwise about the pole to the reference axis",
        transform=ax.transAxes,
        fontsize=8.5,
    )
    ax.set_title("InertialSpin (IAU): R = Rz(ra + 90) Rx(90 - dec) Rz(W)", fontsize=10)


def main() -> Path:
    figure = plt.figure(figsize=(13, 6.2))
    for index, draw in enumerate((precessing_panel, inertial_panel), start=1):
        ax = figure.add_subplot(1, 2, index, projection="3d")
        draw(ax)
        ax.set_xlim(-1, 1), ax.set_ylim(-1, 1), ax.set_zlim(-1, 1)
        if draw is precessing_panel:
            # Rolled half a turn (a rotation, not a mirror) so that nadir points down.
            ax.set_zlim(-1, 1.5)
            ax.view_init(elev=-18, azim=-160, roll=180)
        else:
            ax.view_init(elev=22, azim=35)
        ax.set_box_aspect((1, 1, 1))
        ax.set_axis_off()
    figure.text(
        0.5,
        0.02,
        "Positive periods turn right-handedly about the +axis; spin_axis 'x' or 'y' relabels body "
        "axes cyclically (s3 = spin axis, s1 = next axis: z->x, x->y, y->z).",
        ha="center",
        fontsize=9,
    )
    figure.tight_layout()
    OUTPUT.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(OUTPUT, dpi=110)
    return OUTPUT


if __name__ == "__main__":
    print(main())
