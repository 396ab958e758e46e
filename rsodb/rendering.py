"""Synthetic light curves of a model along a stored pass or over a time span seen from a site.

The library side of ``rsodb render``: choose a scene (a model built by code or a mesh file),
compute the pass geometry from the pass's own orbital elements, render, and draw the result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from raycast.geometry import PassGeometry
from raycast.models import MODELS
from raycast.renderer import DirectRenderer, Scene, render
from raycast.renderer.rays import orthonormal_basis
from rsodb.plotting import file_pyplot

__all__ = [
    "PAPER_MODEL",
    "load_scene",
    "render_pass",
    "render_span",
    "plot_against_pass",
    "plot_span",
    "save_frames",
    "save_animation",
]

# The reference paper's own COSMOS 2502 mesh, read where the project's data sits beside it.
PAPER_MODEL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "models" / "cosmos2502_lotos.obj"


def load_scene(model: str, materials=None, panel_pitch_deg: float | None = None) -> Scene:
    """The scene of a model name (topex, topex_louvered, cosmos2502, cosmos2502-paper) or of a mesh file.

    Parameters
    ----------
    model : str
        A name of `raycast.models.MODELS`, ``"cosmos2502-paper"`` or the path of an OBJ, PLY or
        glTF file.
    materials : path, optional
        Materials JSON of a mesh file.
    panel_pitch_deg : float, optional
        TOPEX solar-array pitch.
    """
    name = model.lower()
    if name in MODELS:
        scene = MODELS[name]()
    elif name == "cosmos2502-paper":
        scene = Scene.from_file(PAPER_MODEL, materials=PAPER_MODEL.with_suffix("").with_suffix(".materials.json"))
    elif Path(model).is_file():
        scene = Scene.from_file(model, materials=materials)
    else:
        raise ValueError(
            f"model {model!r} is neither a known model ({', '.join(MODELS)}, cosmos2502-paper) "
            "nor a mesh file; check the name or path"
        )
    if panel_pitch_deg is not None:
        scene = scene.with_parameters(panel_pitch_deg=panel_pitch_deg)
    return scene


def render_pass(stored, scene, attitude, method="auto", accuracy_mag=0.005, n_sub=None, spin_period_s=None):
    """(LightCurveModel, BodyGeometry) of ``scene`` along a stored pass with ``attitude``.

    The geometry comes from the pass's own TLE or OMM, or else from a track fitted to its file's
    Az/El/range columns (`PassGeometry.from_pass`); each exposure
    is integrated over `n_sub` sub-samples (default: 2 deg of rotation each at `spin_period_s`).
    """
    geometry = PassGeometry.from_pass(stored, n_sub=n_sub, spin_period_s=spin_period_s)
    body = geometry.body_frame(attitude)
    return render(scene, body, method=method, band=stored.band, accuracy_mag=accuracy_mag), body


def render_span(
    satellite,
    site,
    start_utc,
    duration_s,
    cadence_s,
    scene,
    attitude,
    method="auto",
    accuracy_mag=0.005,
    exposure_s=0.0,
    band="V",
    n_sub=None,
    spin_period_s=None,
):
    """(LightCurveModel, BodyGeometry, PassGeometry) of ``scene`` over a time span seen from ``site``.

    Each exposure is integrated over `n_sub` sub-samples (default: 2 deg of rotation each at
    `spin_period_s`).
    """
    for name, value in (("duration", duration_s), ("cadence", cadence_s)):
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"--{name} {value!r} must be a positive number of seconds")
    n = int(np.floor(duration_s / cadence_s + 1e-9)) + 1
    if n > 200_000:
        raise ValueError(
            f"--duration {duration_s} at --cadence {cadence_s} makes {n} frames (more than 200000); "
            "raise the cadence or shorten the span"
        )
    times = start_utc + (np.arange(n) * cadence_s * 1e6).astype("timedelta64[us]")
    geometry = PassGeometry.compute(
        satellite,
        site,
        times,
        exposure_s=exposure_s,
        n_sub=n_sub,
        spin_period_s=spin_period_s,
    )
    body = geometry.body_frame(attitude)
    return render(scene, body, method=method, band=band, accuracy_mag=accuracy_mag), body, geometry


def plot_span(geometry, model, title, path):
    plt = file_pyplot()

    t = (geometry.time_utc - geometry.time_utc[0]) / np.timedelta64(1, "s")
    fig, (ax, ax_el) = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(t, model.mag, "-", lw=0.8, color="C3", label=f"model at the true range ({model.band})")
    ax.plot(t, model.mag_1000km, "-", lw=0.8, color="C0", alpha=0.6, label="model at 1000 km")
    ax.invert_yaxis()
    ax.set_ylabel("magnitude")
    ax.set_title(title)
    ax.legend()
    ax_el.plot(t, geometry.el_deg, color="0.3", lw=0.8)
    ax_el.axhline(0.0, color="0.6", lw=0.6)
    ax_el.set_ylabel("elevation [deg]")
    ax_el.set_xlabel(f"seconds since {np.datetime_as_string(geometry.time_utc[0], unit='s')} UTC")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_against_pass(stored, model_mag, path):
    plt = file_pyplot()

    t = (stored.time_utc - stored.time_utc[0]) / np.timedelta64(1, "s")
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(t, stored.best_mag, ".", ms=2, color="0.4", label=f"observed ({stored.band})")
    ax.plot(t, model_mag, "-", lw=0.8, color="C3", label="model + median offset")
    ax.invert_yaxis()
    ax.set_xlabel(f"seconds since {np.datetime_as_string(stored.time_utc[0], unit='s')} UTC")
    ax.set_ylabel("magnitude at 1000 km")
    ax.set_title(f"{stored.name} ({stored.norad}), pass {stored.pass_id}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _frame_images(scene, body, indices):
    """Images of the frames at `indices`: [(image, u, v, sun, extent)], image axes u (right) and
    v (up) seen from the observer, extent in metres from the mesh's centre."""
    mesh = scene.posed()
    pixel = mesh.radius_m / 150.0
    renderer = DirectRenderer(scene, pixel)
    relative = mesh.vertices_m - mesh.center_m
    frames = []
    for index in indices:
        sun, obs = body.sun_body[index, 0], body.obs_body[index, 0]
        image = renderer.image(sun, obs)
        u, v = (axis[0] for axis in orthonormal_basis(obs[None, :]))
        # The renderer's pixel grid starts a pixel before the projected mesh (DirectRenderer.image).
        left, bottom = (relative @ u).min() - pixel, (relative @ v).min() - pixel
        extent = (left, left + image.shape[1] * pixel, bottom, bottom + image.shape[0] * pixel)
        frames.append((image, u, v, sun, extent))
    return frames


def _draw_frame(ax, frame, radius_m, vmax, label, scale_m):
    """One annotated frame: the image in metres, Sun direction, body axes, scale bar."""
    image, u, v, sun, extent = frame
    ax.imshow(
        np.sqrt(np.clip(image / vmax, 0.0, 1.0)),
        cmap="gray",
        origin="lower",
        extent=extent,
        vmin=0.0,
        vmax=1.0,
    )
    limit = 1.15 * radius_m
    ax.set_xlim(-limit, limit)
    ax.set_ylim(-limit, limit)
    ax.set_facecolor("black")
    ax.set_xticks([])
    ax.set_yticks([])
    # The Sun: its direction projected on the image plane (the arrow's length is sin of its angle
    # from the line of sight, i.e. of the phase angle).
    su, sv = float(sun @ u), float(sun @ v)
    ax.annotate(
        "",
        xy=(0.85 * limit * su, 0.85 * limit * sv),
        xytext=(0, 0),
        arrowprops={"arrowstyle": "->", "color": "gold", "lw": 1.5},
    )
    ax.text(0.9 * limit * su, 0.9 * limit * sv, "Sun", color="gold", fontsize=7, ha="center", va="center")
    # Body axes projected (x red, y green, z blue) from the lower left corner.
    corner = np.array([-0.78 * limit, -0.78 * limit])
    for k, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
        tip = corner + 0.18 * limit * np.array([u[k], v[k]])
        ax.annotate("", xy=tip, xytext=corner, arrowprops={"arrowstyle": "->", "color": colour, "lw": 1.0})
        ax.text(*(corner + 0.24 * limit * np.array([u[k], v[k]])), "xyz"[k], color=colour, fontsize=6)
    ax.text(-0.95 * limit, 0.95 * limit, "observer: out of the page", color="0.8", fontsize=6, va="top")
    # Scale bar.
    x0, y0 = 0.35 * limit, -0.9 * limit
    ax.plot([x0, x0 + scale_m], [y0, y0], color="white", lw=2)
    ax.text(x0 + scale_m / 2, y0 + 0.05 * limit, f"{scale_m:g} m", color="white", fontsize=6, ha="center")
    ax.set_title(label, fontsize=7)


def _scale_bar_m(radius_m: float) -> float:
    """A round length near a third of the radius (1, 2 or 5 times a power of ten), metres."""
    target = radius_m / 3.0
    power = 10.0 ** np.floor(np.log10(target))
    return float(max(m * power for m in (1, 2, 5) if m * power <= target))


def _frame_labels(geometry_time_utc, phase_angle_deg, indices, start_utc):
    return [
        f"{np.datetime_as_string(geometry_time_utc[i], unit='ms')} UTC "
        f"(t = {(geometry_time_utc[i] - start_utc) / np.timedelta64(1, 's'):.1f} s)\nphase angle {phase_angle_deg[i]:.1f} deg"
        for i in indices
    ]


def save_frames(scene, body, directory, count, time_utc=None):
    """PNG images of `count` frames spread over the pass, each annotated and on one brightness scale.

    Each frame shows the object as the observer sees it (the image plane in metres, the same
    extent in every frame), the time and phase angle, the Sun's direction projected on the image,
    the body axes, and a scale bar; brightness is the square root of radiance over the brightest
    pixel of all the frames, so frames compare.

    Parameters
    ----------
    scene : Scene
    body : BodyGeometry
    directory : path
    count : int
    time_utc : (n,) datetime64, optional
        Times of the frames, for the labels.

    Returns
    -------
    list of str
        The files written.
    """
    plt = file_pyplot()

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    n = len(body.range_km)
    indices = np.unique(np.linspace(0, n - 1, max(count, 1)).round().astype(int))
    frames = _frame_images(scene, body, indices)
    vmax = max(max(float(f[0].max()) for f in frames), 1e-12)
    radius = scene.posed().radius_m
    times = time_utc if time_utc is not None else np.full(n, np.datetime64("NaT", "ns"))
    labels = _frame_labels(times, body.phase_angle_deg, indices, times[0])
    written = []
    for index, frame, label in zip(indices, frames, labels):
        fig, ax = plt.subplots(figsize=(4, 4))
        _draw_frame(ax, frame, radius, vmax, label, _scale_bar_m(radius))
        fig.tight_layout()
        path = out / f"frame_{index:05d}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        written.append(str(path))
    return written


def save_animation(scene, body, time_utc, model_mag, observed, path, count=60):
    """An animated GIF of the pass: the object's frames beside the light curve with a moving marker.

    Parameters
    ----------
    scene : Scene
    body : BodyGeometry
        The frames' geometry at `time_utc`.
    time_utc : (n,) datetime64
    model_mag : (n,) float
        The model's magnitude at `time_utc`.
    observed : (time_utc (m,), mag (m,)) or None
        Observed samples to draw behind the model.
    path : path
        The .gif file.
    count : int
        Frames in the animation.
    """
    plt = file_pyplot()
    # matplotlib's animation writer loads Pillow; only this function needs it.
    from matplotlib.animation import FuncAnimation, PillowWriter

    n = len(time_utc)
    indices = np.unique(np.linspace(0, n - 1, max(count, 2)).round().astype(int))
    frames = _frame_images(scene, body, indices)
    vmax = max(max(float(f[0].max()) for f in frames), 1e-12)
    radius = scene.posed().radius_m
    start = time_utc[0]
    t = (time_utc - start) / np.timedelta64(1, "s")
    labels = _frame_labels(time_utc, body.phase_angle_deg, indices, start)
    fig, (ax_image, ax_curve) = plt.subplots(1, 2, figsize=(10, 4), gridspec_kw={"width_ratios": [1, 1.6]})
    if observed is not None:
        ax_curve.plot(
            (observed[0] - start) / np.timedelta64(1, "s"), observed[1], ".", ms=2, color="0.6", label="observed"
        )
    ax_curve.plot(t, model_mag, "-", lw=0.8, color="C3", label="model")
    ax_curve.invert_yaxis()
    ax_curve.set_xlabel(f"seconds since {np.datetime_as_string(start, unit='s')} UTC")
    ax_curve.set_ylabel("magnitude")
    ax_curve.legend(fontsize=7, loc="upper right")
    (marker,) = ax_curve.plot([], [], "o", color="C0", ms=6)

    def draw(k):
        ax_image.clear()
        _draw_frame(ax_image, frames[k], radius, vmax, labels[k], _scale_bar_m(radius))
        marker.set_data([t[indices[k]]], [model_mag[indices[k]]])
        return (marker,)

    fig.tight_layout()
    animation = FuncAnimation(fig, draw, frames=len(indices), blit=False)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    animation.save(path, writer=PillowWriter(fps=8), dpi=80)
    plt.close(fig)
    return str(path)
