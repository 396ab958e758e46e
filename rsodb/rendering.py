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
from rsodb.plotting import file_pyplot

__all__ = ["PAPER_MODEL", "load_scene", "render_pass", "render_span", "plot_against_pass", "plot_span", "save_frames"]

# The reference paper's own COSMOS 2502 mesh, read where the project's data sits beside it.
PAPER_MODEL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "models" / "cosmos2502_lotos.obj"


def load_scene(model: str, materials=None, panel_pitch_deg: float | None = None) -> Scene:
    """The scene of a model name (topex, cosmos2502, cosmos2502-paper) or of a mesh file.

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
            f"model {model!r} is neither a known model (topex, cosmos2502, cosmos2502-paper) "
            "nor a mesh file; check the name or path"
        )
    if panel_pitch_deg is not None:
        scene = scene.with_parameters(panel_pitch_deg=panel_pitch_deg)
    return scene


def render_pass(stored, scene, attitude, method="auto", accuracy_mag=0.005, n_sub=None):
    """(LightCurveModel, BodyGeometry) of ``scene`` along a stored pass with ``attitude``.

    The geometry comes from the pass's own TLE or OMM (`PassGeometry.from_pass`).
    """
    geometry = PassGeometry.from_pass(stored, n_sub=n_sub)
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
):
    """(LightCurveModel, BodyGeometry, PassGeometry) of ``scene`` over a time span seen from ``site``."""
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
        spin_period_s=attitude.period_s if hasattr(attitude, "period_s") else None,
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


def save_frames(scene, body, directory, count):
    plt = file_pyplot()

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    renderer = DirectRenderer(scene, scene.posed().radius_m / 150.0)
    written = []
    for index in np.linspace(0, len(body.range_km) - 1, max(count, 1)).astype(int):
        image = renderer.image(body.sun_body[index, 0], body.obs_body[index, 0])
        path = out / f"frame_{index:05d}.png"
        plt.imsave(path, np.sqrt(image / max(image.max(), 1e-12)), cmap="gray", origin="lower")
        written.append(str(path))
    return written
