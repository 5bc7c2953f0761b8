"""Rigid body, allocation, controller inversion, effects regressors."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.physics.allocation import Allocation
from omavctl.physics.controller import Controller, ControllerState, invert_residual
from omavctl.physics.effects import EFFECTS, EffectContext
from omavctl.physics.rigid_body import (
    angular_acceleration,
    euler_rates,
    euler_rates_to_body,
    rotation_matrix,
    rotation_to_euler,
    state_derivative,
)
from omavctl.sim.scalar import ScalarBody


def test_rotation_euler_round_trip():
    rng = np.random.default_rng(0)
    eta = rng.uniform([-3, -1.4, -3], [3, 1.4, 3], size=(200, 3))
    np.testing.assert_allclose(rotation_to_euler(rotation_matrix(eta)), eta, atol=1e-12)
    r = rotation_matrix(eta)
    np.testing.assert_allclose(
        r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12
    )


def test_euler_rate_maps_are_inverse():
    rng = np.random.default_rng(1)
    eta = rng.uniform(-1.2, 1.2, size=(100, 3))
    omega = rng.normal(size=(100, 3))
    back, _ = euler_rates_to_body(eta, euler_rates(eta, omega))
    np.testing.assert_allclose(back, omega, atol=1e-12)


def test_body_acceleration_from_euler_derivatives_matches_finite_difference():
    t = np.linspace(0, 2, 2001)
    eta = np.column_stack([0.5 * np.sin(2 * t), 0.4 * np.cos(3 * t), 0.3 * t**2])
    deta = np.column_stack([np.cos(2 * t), -1.2 * np.sin(3 * t), 0.6 * t])
    ddeta = np.column_stack([-2 * np.sin(2 * t), -3.6 * np.cos(3 * t), np.full_like(t, 0.6)])
    omega, domega = euler_rates_to_body(eta, deta, ddeta)
    fd = np.gradient(omega, t, axis=0)
    np.testing.assert_allclose(domega[5:-5], fd[5:-5], atol=1e-5)


def test_scalar_plant_derivative_matches_library(vehicle):
    rng = np.random.default_rng(2)
    inertia = np.array([[0.09, 0.001, 0.0], [0.001, 0.1, 0.002], [0.0, 0.002, 0.17]])
    body = ScalarBody(vehicle.mass, inertia, vehicle.gravity)
    for _ in range(20):
        x = rng.normal(size=12)
        x[4] = np.clip(x[4], -1.2, 1.2)
        f, tau = rng.normal(size=3) * 10, rng.normal(size=3)
        ref = state_derivative(
            x, f, tau, vehicle.mass, inertia, np.linalg.inv(inertia), vehicle.gravity
        )
        np.testing.assert_allclose(
            body.derivative(x.tolist(), f.tolist(), tau.tolist()), ref, atol=1e-12
        )


def _feasible_wrenches(vehicle, n, rng):
    hover = np.array([0, 0, vehicle.mass * vehicle.gravity, 0, 0, 0])
    scale = np.array([15, 15, 15, 2, 2, 1])
    return hover + rng.uniform(-1, 1, size=(n, 6)) * scale


def test_allocation_round_trip_is_exact_for_feasible_wrenches(vehicle):
    alloc = Allocation(vehicle)
    w = _feasible_wrenches(vehicle, 500, np.random.default_rng(3))
    res = alloc.allocate(w)
    assert res.feasible.all()
    assert res.rotor_thrust.shape == (500, 12) and res.tilt.shape == (500, 6)
    np.testing.assert_allclose(alloc.forward(res.tilt, res.rotor_thrust), w, atol=1e-9, rtol=0)


def test_allocation_reports_thrust_saturation_without_clipping(vehicle):
    alloc = Allocation(vehicle)
    w = np.array([[0, 0, 300.0, 0, 0, 0], [0, 0, 40.0, 0, 0, 0]])
    res = alloc.allocate(w)
    assert res.feasible.tolist() == [False, True]
    assert res.thrust_high[0].all() and not res.thrust_low.any()
    assert res.rotor_thrust[0].max() == pytest.approx(300.0 / 12)  # reported, not clipped
    np.testing.assert_allclose(alloc.forward(res.tilt, res.rotor_thrust), w, atol=1e-9)


def test_allocation_reports_tilt_rate(vehicle):
    alloc = Allocation(vehicle)
    hover = np.array([0, 0, vehicle.mass * vehicle.gravity, 0, 0, 0.0])
    side = hover + np.array([20.0, 0, 0, 0, 0, 0])
    prev = alloc.allocate(hover).tilt
    slow = alloc.allocate(side, previous_tilt=prev, dt=1.0)
    fast = alloc.allocate(side, previous_tilt=prev, dt=0.001)
    assert slow.feasible and not fast.feasible
    assert fast.tilt_rate_exceeded.any() and not fast.thrust_high.any()


def test_allocation_jacobians_match_finite_differences(vehicle):
    alloc = Allocation(vehicle)
    rng = np.random.default_rng(4)
    tilt, thrust = rng.uniform(-1, 1, 6), rng.uniform(2, 10, 6)

    def wrench(a, f):
        return alloc.forward(a, np.repeat(f / 2, 2))

    h = 1e-6
    jt = np.column_stack(
        [(wrench(tilt + h * e, thrust) - wrench(tilt - h * e, thrust)) / (2 * h) for e in np.eye(6)]
    )
    jf = np.column_stack(
        [(wrench(tilt, thrust + h * e) - wrench(tilt, thrust - h * e)) / (2 * h) for e in np.eye(6)]
    )
    np.testing.assert_allclose(alloc.tilt_jacobian(tilt, thrust), jt, atol=1e-7)
    np.testing.assert_allclose(alloc.thrust_jacobian(tilt), jf, atol=1e-7)


class _Affine:
    """A residual model mu(u) = A u_tau + B u_force + c + 0.05 sin(u_tau)."""

    def __init__(self):
        rng = np.random.default_rng(5)
        self.a = 0.3 * rng.normal(size=(3, 3))
        self.b = 0.1 * rng.normal(size=(3, 3))
        self.c = np.array([0.2, -0.1, 0.05])

    def mean(self, u, omega=None):
        return u[..., 3:] @ self.a.T + u[..., :3] @ self.b.T + self.c + 0.05 * np.sin(u[..., 3:])


def test_inversion_solves_u_plus_mu_equals_target():
    model = _Affine()
    rng = np.random.default_rng(6)
    target, u_f = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    x = invert_residual(target, u_f, model)
    np.testing.assert_allclose(x + model.mean(np.concatenate([u_f, x], -1)), target, atol=1e-9)


def test_controller_with_zero_model_commands_nominal_torque(vehicle):
    ctrl = Controller(vehicle)
    x = np.zeros((1, 12))
    x[0, 3:6] = [0.1, -0.05, 0.2]
    x[0, 9:12] = [0.3, -0.2, 0.5]
    ref = np.zeros((1, 19))
    ref[0, 16:19] = [1.0, 2.0, -0.5]
    out = ctrl.step(ControllerState.zeros(1), x, ref, 0.01)
    # the commanded torque produces exactly a* through the nominal model
    acc = angular_acceleration(x[:, 9:12], out.torque, vehicle.inertia, vehicle.inertia_inv)
    np.testing.assert_allclose(acc, out.desired_angular, atol=1e-12)
    # hover force in body frame balances gravity along world z
    np.testing.assert_allclose(
        (rotation_matrix(x[0, 3:6]) @ out.force[0])[2],
        vehicle.mass * vehicle.gravity * 1.0,
        rtol=1e-12,
    )


def test_controller_with_model_cancels_the_residual(vehicle):
    model = _Affine()
    ctrl = Controller(vehicle, model)
    x = np.zeros((1, 12))
    ref = np.zeros((1, 19))
    ref[0, 16:19] = [1.0, -1.0, 0.5]
    out = ctrl.step(ControllerState.zeros(1), x, ref, 0.01)
    achieved = out.u[:, 3:] + model.mean(out.u)
    np.testing.assert_allclose(achieved, out.desired_angular, atol=1e-9)


def _context(vehicle, n=400, seed=7):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    omega = np.column_stack([np.sin(t), 0.8 * np.cos(1.3 * t), 0.5 * np.sin(0.7 * t)]) * 2
    force = np.column_stack([3 * np.sin(0.5 * t), 2 * np.cos(0.9 * t), 39 + np.sin(t)])
    torque = rng.normal(size=(n, 3)) * 0.1
    nominal = angular_acceleration(omega, torque, vehicle.inertia, vehicle.inertia_inv)
    return EffectContext(
        omega=omega,
        force=force,
        torque=torque,
        omega_dot_nominal=nominal,
        inertia=vehicle.inertia,
        dt=0.01,
        allocation=Allocation(vehicle),
        derivative=lambda y: np.gradient(y, 0.01, axis=0),
    )


@pytest.mark.parametrize("name", ["rotational_drag", "com_offset"])
def test_torque_effect_regressor_matches_simulation_form(vehicle, name):
    ctx = _context(vehicle)
    effect = EFFECTS[name]
    params = {p.name: np.array([0.02, -0.03, 0.01][: p.size]) for p in effect.parameters}
    x = effect.regressor(ctx)
    assert x.shape == (ctx.omega.shape[0], 3, effect.n_theta)
    torque = effect.body_torque(params, ctx.omega, ctx.force)
    np.testing.assert_allclose(
        x @ effect.to_theta(params), torque @ vehicle.inertia_inv.T, atol=1e-12
    )


def test_inertia_error_regressor_and_parameter_map(vehicle):
    ctx = _context(vehicle)
    effect = EFFECTS["inertia_error"]
    scale = np.array([1.2, 0.9, 1.1])
    theta = effect.to_theta({"scale": scale})
    # first-order residual: (1/s - 1) * nominal acceleration
    np.testing.assert_allclose(
        effect.regressor(ctx) @ theta, (1 / scale - 1) * ctx.omega_dot_nominal
    )
    params = effect.to_parameters(theta, np.eye(3) * 1e-4)
    np.testing.assert_allclose(params["scale"][0], scale)
    np.testing.assert_allclose(params["scale"][1], 1e-2 * scale**2)


def test_every_effect_has_formula_units_and_regressor(vehicle):
    ctx = _context(vehicle)
    for name, effect in EFFECTS.items():
        assert effect.name == name
        assert effect.__doc__ and len(effect.__doc__) > 80
        assert all(p.unit for p in effect.parameters)
        x = effect.regressor(ctx)
        assert x.shape == (400, 3, effect.n_theta) and np.all(np.isfinite(x))
        lo, hi = effect.theta_range
        assert effect.prior_std > 0 and lo < hi
    assert {
        "rotational_drag",
        "com_offset",
        "inertia_error",
        "servo_lag",
        "motor_lag",
        "gyro_bias",
    } <= set(EFFECTS)
