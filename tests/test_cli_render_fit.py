"""``rsodb render`` reproduces a fitted state: every attitude parameter on the command line,
phases at the fit's reference epoch, and ``--from-fit`` replaying a stored fit with its frames.

Authority: a convex mesh casts no shadows, so the fit's shape cache and the renderer of
``rsodb render`` are both exact on it (tests/test_fit_shapes.py); the same state at the same
epoch must give the same light curve through either path, up to the magnitude offset.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rsodb.archive import Archive
from rsodb.cli import main
from rsodb.cli.render import ATTITUDE_FAMILIES, PARAMETER_OPTIONS
from tests.conftest import TLES, TOPEX_PHV


def write_ellipsoid(directory, n_lat: int = 8, n_lon: int = 16):
    """A 2 x 1 x 0.7 m Lambertian ellipsoid (albedo 0.2) as OBJ + materials JSON: convex, and
    never dark while lit (a box is dark at this pass's 124 deg phase angle in some attitudes)."""
    lat = np.linspace(0.0, np.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0.0, 2 * np.pi, n_lon, endpoint=False)
    points = [(0.0, 0.0, 0.35)] + [
        (np.sin(a) * np.cos(b), 0.5 * np.sin(a) * np.sin(b), 0.35 * np.cos(a)) for a in lat for b in lon
    ]
    points.append((0.0, 0.0, -0.35))
    ring = lambda i, j: 2 + i * n_lon + j % n_lon  # noqa: E731  (1-based OBJ index)
    faces = [(1, ring(0, j), ring(0, j + 1)) for j in range(n_lon)]
    for i in range(n_lat - 2):
        faces += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)) for j in range(n_lon)]
    last = len(points)
    faces += [(last, ring(n_lat - 2, j + 1), ring(n_lat - 2, j)) for j in range(n_lon)]
    lines = ["o body", "usemtl paint"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in points]
    lines += ["f " + " ".join(map(str, face)) for face in faces]
    obj = directory / "ellipsoid.obj"
    obj.write_text("\n".join(lines) + "\n")
    materials = directory / "ellipsoid.materials.json"
    materials.write_text(json.dumps({"materials": {"paint": {"blender_node": "Diffuse BSDF", "color": [0.2] * 3}}}))
    return obj, materials


def test_render_options_cover_every_attitude_family_and_parameter():
    from rsodb.fit.model import ATTITUDES

    assert ATTITUDE_FAMILIES == tuple(ATTITUDES)
    for family in ATTITUDES.values():
        assert set(family.parameters) <= set(PARAMETER_OPTIONS), family


def test_from_fit_refuses_a_model_and_an_epoch(tmp_path, capsys):
    assert main(["render", "--from-fit", "22076", "--archive", str(tmp_path), "--model", "topex"]) == 2
    assert "leave out --model, --materials, --epoch" in capsys.readouterr().err
    base = ["render", "--model", "topex", "--tle", str(TLES), "--norad", "22076", "--start", "2024-07-30T21:24:00"]
    base += ["--duration", "10"]
    assert main(base + ["--epoch", "yesterday"]) == 2
    assert "--epoch 'yesterday' is not an ISO UTC time" in capsys.readouterr().err


@pytest.mark.slow
def test_a_stored_fit_replays_and_renders_by_hand_at_its_epoch(tmp_path, capsys):
    from rsodb.fit import make_attitude, predict_fit
    from rsodb.fit.coverage import window
    from rsodb.rendering import load_scene, render_pass

    archive_dir = tmp_path / "archive"
    archive = Archive(archive_dir, create=True)
    archive.ingest([TOPEX_PHV], progress=False)
    pass_id = archive.passes(norad=22076)[0].pass_id
    obj, materials = write_ellipsoid(tmp_path)
    # A tiny fit of the first 20 s (its epoch, the window's mid-time, is not the pass's).
    config = tmp_path / "tiny.toml"
    config.write_text(
        f"""name = "tiny"
band_draws = 5
[model]
mesh = "{obj}"
materials = "{materials}"
n_sub = 1
[data]
duration_s = 20.0
[parameters]
spin_period_s = {{ kind = "uniform", low = 9.5, high = 10.2 }}
precession_period_s = 700.0
precession_phase_deg = 50.0
precession_angle_deg = 30.0
jitter_mag = 0.0
[sampler]
n_walkers = 6
n_steps = 6
init = "prior"
"""
    )
    assert main(["fit", pass_id, "--archive", str(archive_dir), "--config", str(config), "--quiet"]) == 0
    capsys.readouterr()
    frames, gif, plot = tmp_path / "frames", tmp_path / "pass.gif", tmp_path / "replay.png"
    glints = tmp_path / "glints.png"
    status = main(
        ["render", "--from-fit", f"{pass_id}:tiny", "--archive", str(archive_dir), "--json", "--draws", "5"]
        + ["--plot", str(plot), "--frames-png", str(frames), "--frames", "2", "--gif", str(gif), "--gif-frames", "3"]
        + ["--glint-map", str(glints)]
    )
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    observed = archive.get(pass_id)
    assert summary["n_samples"] == len(observed) and summary["n_window"] == np.sum(observed.t_s <= 20.0)
    assert set(summary["spin_periods"]["conventions"]) == {
        "parameter",
        "orbit_frame",
        "inertial",
        "light_curve",
        "periodogram",
    }
    assert plot.stat().st_size > 10_000 and len(list(frames.glob("*.png"))) == 2
    assert summary["glint_map"] == str(glints) and glints.stat().st_size > 10_000
    from PIL import Image

    assert Image.open(gif).n_frames == 3

    # The same state rendered by hand, phases at the fit's epoch (what 'rsodb render --epoch' does).
    prediction = predict_fit(archive, pass_id, "tiny", draws=0)
    # The glint map's bisector: half the phase angle from the Sun at every sample, and the
    # spin axis of the precessing family is its body z.
    bisector, spin = prediction.bisector_body()
    geometry, body = prediction.body_geometry()
    half_phase = np.degrees(np.arccos(np.clip(np.sum(bisector * body.sun_body[:, 0], axis=1), -1.0, 1.0)))
    np.testing.assert_allclose(half_phase, geometry.phase_angle_deg / 2.0, atol=1e-6)
    np.testing.assert_allclose(spin, [0.0, 0.0, 1.0], atol=1e-12)
    epoch_s = float((np.datetime64(prediction.result.epoch_utc, "ns") - observed.time_utc[0]) / np.timedelta64(1, "s"))
    attitude = make_attitude("precessing", prediction.values, {"spin_axis": "z"}, epoch_s)
    # The first 40 s (the fitted 20 s and as many after) keep the direct renderer cheap.
    first = window(observed, 0.0, 40.0)
    scene = load_scene(str(obj), str(materials))
    by_hand, _ = render_pass(first, scene, attitude, "direct", n_sub=1)
    replay = prediction.samples.mag_model[np.isin(prediction.samples.time_utc, first.time_utc)]
    assert replay.size == len(first)
    difference = replay - by_hand.mag_1000km
    # Both are exact on a convex mesh up to their accuracies (the cache's 0.01 mag asked, the
    # direct renderer's 0.005): after the offset the light curves agree to that, while the
    # curve itself swings by more than half a magnitude.
    assert np.ptp(by_hand.mag_1000km) > 0.5
    residual = difference - np.median(difference)
    assert np.sqrt(np.mean(residual**2)) < 0.01 and np.max(np.abs(residual)) < 0.03
    # At the pass's mid-time instead (the old convention), the phases are off and so is the curve.
    shifted = make_attitude("precessing", prediction.values, {"spin_axis": "z"}, 0.5 * observed.duration_s)
    off, _ = render_pass(first, scene, shifted, "direct", n_sub=1)
    wrong = replay - off.mag_1000km
    assert np.max(np.abs(wrong - np.median(wrong))) > 0.1
