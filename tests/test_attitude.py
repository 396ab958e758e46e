"""Attitude models: conventions, rotation properties, torque-free dynamics against exact answers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from raycast.geometry.attitude import ATTITUDE_MODELS, InertialSpin, PrecessingSpin, TorqueFree, build

RNG = np.random.default_rng(20240730)


def random_lvlh(shape) -> np.ndarray:
    """Random rotation matrices standing in for local orbital frames."""
    q = RNG.normal(size=shape + (4,))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def angular_velocity(model, t, lvlh=None, h=1e-4):
    """Angular velocity in GCRS from R(t+h) R(t-h)^T (skew part), rad/s."""
    ahead, behind = model.orientation(t + h, lvlh), model.orientation(t - h, lvlh)
    skew = (ahead @ np.swapaxes(behind, -1, -2) - behind @ np.swapaxes(ahead, -1, -2)) / (4 * h)
    return np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], axis=-1)


AXIS_COLUMN = {"x": 0, "y": 1, "z": 2}
REFERENCE_COLUMN = {"z": 0, "x": 1, "y": 2}  # next axis in cyclic order


# -- rotation properties for every model and axis ---------------------------------------------
def models():
    yield PrecessingSpin(
        period_s=9.86,
        phase_deg=40.0,
        precession_period_s=689.0,
        precession_phase_deg=10.0,
        precession_angle_deg=35.0,
        spin_axis="z",
    )
    yield PrecessingSpin(period_s=-40.5, precession_period_s=1620.0, precession_angle_deg=7.0, spin_axis="x")
    yield InertialSpin(pole_ra_deg=123.0, pole_dec_deg=-41.0, period_s=10.73, phase_deg=200.0, spin_axis="y")
    yield TorqueFree.from_angular_momentum((1.0, 2.0, 2.5), (0.05, 0.3, 0.4), 80.0, 20.0, 5.0)


@pytest.mark.parametrize("model", list(models()), ids=lambda m: type(m).__name__ + getattr(m, "spin_axis", ""))
def test_orientations_are_rotations_of_the_requested_shape(model):
    t = np.linspace(-0.1, 300.0, 24).reshape(6, 4)
    rotation = model.orientation(t, random_lvlh((6, 4)))
    assert rotation.shape == (6, 4, 3, 3)
    np.testing.assert_allclose(
        np.swapaxes(rotation, -1, -2) @ rotation, np.broadcast_to(np.eye(3), rotation.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0, atol=1e-12)


def test_models_are_immutable_and_built_from_the_table():
    model = build("precessing", period_s=9.86)
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.period_s = 1.0
    assert set(ATTITUDE_MODELS) == {"precessing", "inertial", "torque_free"}
    assert build("inertial", pole_ra_deg=1.0, pole_dec_deg=2.0, period_s=3.0) == InertialSpin(1.0, 2.0, 3.0)
    with pytest.raises(
        ValueError, match="unknown attitude model 'spinning'; choose one of precessing, inertial, torque_free"
    ):
        build("spinning")


# -- the seed paper's precessing spin ---------------------------------------------------------
@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_precessing_spin_axis_lies_on_the_cone_around_nadir(axis):
    theta, phi0, period_pr = 35.0, 10.0, 689.0
    model = PrecessingSpin(
        period_s=9.86,
        phase_deg=40.0,
        precession_period_s=period_pr,
        precession_phase_deg=phi0,
        precession_angle_deg=theta,
        spin_axis=axis,
    )
    t = np.linspace(0.0, 1000.0, 57)
    lvlh = random_lvlh(t.shape)
    rotation = model.orientation(t, lvlh)
    spin_lvlh = np.einsum("nji,nj->ni", lvlh, rotation[..., AXIS_COLUMN[axis]])
    phi = np.radians(phi0 + 360.0 * t / period_pr)
    th = math.radians(theta)
    expected = np.stack([math.sin(th) * np.cos(phi), math.sin(th) * np.sin(phi), np.full_like(phi, math.cos(th))], -1)
    np.testing.assert_allclose(spin_lvlh, expected, atol=1e-12)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_precessing_spin_zero_phase_and_sense(axis):
    theta, phi = math.radians(35.0), math.radians(10.0)
    model = PrecessingSpin(
        period_s=9.86, phase_deg=0.0, precession_phase_deg=10.0, precession_angle_deg=35.0, spin_axis=axis
    )
    lvlh = np.eye(3)[None]
    rotation = model.orientation(np.zeros(1), lvlh)[0]
    # psi = 0: the reference axis is Rz(phi) Ry(theta) x = (cos th cos phi, cos th sin phi, -sin th),
    # in the plane of nadir and the spin axis, on the side away from the Earth.
    reference = rotation[:, REFERENCE_COLUMN[axis]]
    np.testing.assert_allclose(
        reference, [math.cos(theta) * math.cos(phi), math.cos(theta) * math.sin(phi), -math.sin(theta)], atol=1e-15
    )
    # Positive period: right-handed spin about the spin axis at 2 pi / P (no precession here).
    omega = angular_velocity(model, np.zeros(1), lvlh)[0]
    np.testing.assert_allclose(omega, 2 * math.pi / 9.86 * rotation[:, AXIS_COLUMN[axis]], atol=1e-9)


def test_precessing_spin_periods_and_precession_sense():
    model = PrecessingSpin(period_s=9.86, phase_deg=33.0, precession_period_s=np.inf, precession_angle_deg=20.0)
    lvlh = random_lvlh((5,))
    t = np.linspace(0.0, 30.0, 5)
    np.testing.assert_allclose(model.orientation(t + 9.86, lvlh), model.orientation(t, lvlh), atol=1e-12)
    precessing = PrecessingSpin(period_s=np.inf, precession_period_s=600.0, precession_angle_deg=30.0)
    # With no spin the body turns about nadir (LVLH z) at 2 pi / P_pr, right-handed.
    omega = angular_velocity(precessing, np.array([17.0]), np.eye(3)[None])[0]
    np.testing.assert_allclose(omega, [0.0, 0.0, 2 * math.pi / 600.0], atol=1e-10)
    retrograde = dataclasses.replace(precessing, precession_period_s=-600.0)
    np.testing.assert_allclose(
        angular_velocity(retrograde, np.array([17.0]), np.eye(3)[None])[0], [0.0, 0.0, -2 * math.pi / 600.0], atol=1e-10
    )


def test_precessing_spin_needs_the_local_orbital_frames():
    model = PrecessingSpin(period_s=9.86)
    with pytest.raises(ValueError, match="PrecessingSpin needs lvlh_gcrs"):
        model.orientation(np.zeros(3))
    with pytest.raises(ValueError, match=r"lvlh_gcrs has shape \(2, 3, 3\) but t_s has shape \(3,\)"):
        model.orientation(np.zeros(3), random_lvlh((2,)))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(period_s=0.0), "PrecessingSpin: period_s=0.0 must be a non-zero number of seconds"),
        (dict(period_s=9.0, precession_period_s=float("nan")), "precession_period_s=nan must be a non-zero number"),
        (dict(period_s=9.0, precession_angle_deg=190.0), "precession_angle_deg=190.0 must lie in \\[0, 180\\]"),
        (dict(period_s=9.0, phase_deg=float("inf")), "phase_deg=inf must be a finite angle in degrees"),
        (dict(period_s=9.0, spin_axis="w"), "spin_axis='w' must be one of 'x', 'y', 'z'"),
    ],
)
def test_precessing_spin_refuses_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PrecessingSpin(**kwargs)


# -- inertially fixed spin axis ------------------------------------------------------------------
@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_inertial_spin_follows_the_iau_convention(axis):
    ra, dec = math.radians(123.0), math.radians(-41.0)
    model = InertialSpin(pole_ra_deg=123.0, pole_dec_deg=-41.0, period_s=10.73, phase_deg=0.0, spin_axis=axis)
    pole = np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])
    node = np.array([-math.sin(ra), math.cos(ra), 0.0])  # ascending node, RA = ra + 90
    t = np.array([0.0, 10.73 / 4.0, 5.0])
    rotation = model.orientation(t)
    np.testing.assert_allclose(rotation[:, :, AXIS_COLUMN[axis]], np.broadcast_to(pole, (3, 3)), atol=1e-15)
    np.testing.assert_allclose(rotation[0, :, REFERENCE_COLUMN[axis]], node, atol=1e-15)  # W = 0
    np.testing.assert_allclose(rotation[1, :, REFERENCE_COLUMN[axis]], np.cross(pole, node), atol=1e-14)  # W = 90
    np.testing.assert_allclose(angular_velocity(model, t[2:]), [2 * math.pi / 10.73 * pole], atol=1e-9)
    backwards = dataclasses.replace(model, period_s=-10.73)
    np.testing.assert_allclose(angular_velocity(backwards, t[2:]), [-2 * math.pi / 10.73 * pole], atol=1e-9)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_tilted_inertial_spin_turns_the_tilted_body_direction_about_the_pole(axis):
    ra, dec, tilt, azimuth = math.radians(123.0), math.radians(-41.0), math.radians(17.0), math.radians(250.0)
    model = InertialSpin(123.0, -41.0, 10.73, 30.0, axis, axis_tilt_deg=17.0, axis_tilt_azimuth_deg=250.0)
    pole = np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])
    k = "xyz".index(axis)
    direction = np.zeros(3)  # the tilted spin axis in the body: from `axis` toward the next axes in cyclic order
    direction[k] = math.cos(tilt)
    direction[(k + 1) % 3] = math.sin(tilt) * math.cos(azimuth)
    direction[(k + 2) % 3] = math.sin(tilt) * math.sin(azimuth)
    t = np.linspace(0.0, 25.0, 11)
    rotation = model.orientation(t)
    np.testing.assert_allclose(rotation @ direction, np.broadcast_to(pole, (11, 3)), atol=1e-14)
    np.testing.assert_allclose(model.spin_direction_body, direction, atol=1e-15)
    np.testing.assert_allclose(angular_velocity(model, t[5:6]), [2 * math.pi / 10.73 * pole], atol=1e-9)
    # The body axis itself circles the pole 17 deg away, once a period.
    np.testing.assert_allclose(np.degrees(np.arccos(rotation[:, :, k] @ pole)), 17.0, atol=1e-9)
    assert np.ptp(rotation[:, :, k] @ np.cross(pole, [0.0, 0.0, 1.0])) > 0.2
    untilted = InertialSpin(123.0, -41.0, 10.73, 30.0, axis)
    np.testing.assert_array_equal(dataclasses.replace(model, axis_tilt_deg=0.0).orientation(t), untilted.orientation(t))


def test_tilted_inertial_spin_refuses_a_tilt_beyond_a_half_turn():
    with pytest.raises(ValueError, match=r"axis_tilt_deg=190.0 must lie in \[0, 180\]"):
        InertialSpin(0.0, 90.0, 10.0, axis_tilt_deg=190.0)


# -- torque-free rigid body --------------------------------------------------------------------
TRIAXIAL = (1200.0, 2000.0, 2600.0)  # kg m^2, a TOPEX-like bus scaled down
SPIN = (0.30, 0.02, 0.40)  # rad/s: a ~13 s tumble near the maximum axis


def test_torque_free_conserves_energy_and_angular_momentum_over_ten_thousand_seconds():
    model = TorqueFree.from_angular_momentum(TRIAXIAL, SPIN, 40.0, 30.0, 10.0)
    t = np.linspace(-100.0, 1e4, 4001)
    rotation = model.orientation(t)
    omega = model.angular_velocity_body(t)
    inertia = np.asarray(TRIAXIAL)
    energy = 0.5 * np.sum(inertia * omega**2, axis=1)
    momentum = np.einsum("nij,nj->ni", rotation, inertia * omega)
    # The required conservation: 1e-9 relative over 1e4 s (measured ~1e-10).
    assert np.abs(energy / energy[0] - 1.0).max() < 1e-9
    assert np.linalg.norm(momentum - momentum[0], axis=1).max() / np.linalg.norm(momentum[0]) < 1e-9
    # from_angular_momentum put the momentum at RA 40, Dec 30.
    ra, dec = math.radians(40.0), math.radians(30.0)
    np.testing.assert_allclose(
        momentum[0] / np.linalg.norm(momentum[0]),
        [math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)],
        atol=1e-12,
    )
    # The triaxial body really tumbles: omega wanders in the body frame.
    assert np.ptp(omega[:, 1]) > 0.1


def test_axisymmetric_body_matches_analytic_regular_precession():
    # I1 = I2 = It: omega_3 is constant, the body turns about the angular momentum h at
    # |H| / It while spinning about its z axis at -lambda = -(I3 - It) / It * omega_3 relative to
    # that: R(t) = Rot(h, |H| t / It) R0 Rz(-lambda t) exactly.
    it, i3 = 1500.0, 600.0
    omega0 = np.array([0.12, -0.05, 0.9])
    rotation0 = InertialSpin(pole_ra_deg=70.0, pole_dec_deg=15.0, period_s=np.inf, phase_deg=25.0).orientation(0.0)
    model = TorqueFree((it, it, i3), omega0, rotation0)
    t = np.linspace(-50.0, 2000.0, 301)
    momentum = rotation0 @ (np.array([it, it, i3]) * omega0)
    h = momentum / np.linalg.norm(momentum)
    precession = np.linalg.norm(momentum) / it
    lam = (i3 - it) / it * omega0[2]

    def rot(axis, angle):
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        return np.eye(3) + np.sin(angle)[:, None, None] * k + (1 - np.cos(angle))[:, None, None] * (k @ k)

    expected = rot(h, precession * t) @ rotation0 @ rot(np.array([0.0, 0.0, 1.0]), -lam * t)
    # 1e-8: the integrator's rtol of 1e-13 accumulated over ~300 turns.
    np.testing.assert_allclose(model.orientation(t), expected, atol=1e-8)
    # The body z axis keeps the nutation angle cos(theta) = I3 omega3 / |H| to the momentum.
    z_axis = model.orientation(t)[:, :, 2]
    np.testing.assert_allclose(z_axis @ h, i3 * omega0[2] / np.linalg.norm(momentum), atol=1e-10)


def test_spin_about_a_principal_axis_is_a_uniform_spin():
    rotation0 = InertialSpin(pole_ra_deg=10.0, pole_dec_deg=50.0, period_s=np.inf).orientation(0.0)
    model = TorqueFree(TRIAXIAL, (0.0, 0.0, 2 * math.pi / 12.0), rotation0)
    uniform = InertialSpin(pole_ra_deg=10.0, pole_dec_deg=50.0, period_s=12.0)
    t = np.linspace(-30.0, 300.0, 67)
    np.testing.assert_allclose(model.orientation(t), uniform.orientation(t), atol=1e-10)


def test_torque_free_results_are_cached_and_times_may_come_in_any_order():
    model = TorqueFree.from_angular_momentum(TRIAXIAL, SPIN, 0.0, 0.0)
    t = np.array([[50.0, -3.0], [0.0, 20.0]])
    first = model.orientation(t)
    again = TorqueFree.from_angular_momentum(TRIAXIAL, SPIN, 0.0, 0.0).orientation(t)
    np.testing.assert_array_equal(first, again)
    np.testing.assert_allclose(model.orientation(t.ravel()[::-1]), first.reshape(4, 3, 3)[::-1], atol=1e-15)


@pytest.mark.parametrize(
    "inertia, omega, message",
    [
        ((1.0, 1.0, 3.0), (0, 0, 1), "breaks the triangle inequality"),
        ((1.0, -1.0, 1.0), (0, 0, 1), "must be three positive moments"),
        ((1.0, 1.0, 1.0), (0, float("nan"), 1), "must be three finite rates in rad/s"),
    ],
)
def test_torque_free_refuses_impossible_bodies(inertia, omega, message):
    with pytest.raises(ValueError, match=message):
        TorqueFree(inertia, omega)
    with pytest.raises(ValueError, match="rotation0 must be a 3x3 rotation matrix"):
        TorqueFree(TRIAXIAL, SPIN, np.diag([1.0, 1.0, -1.0]))
