"""The controller's model inversion asks the model once per Newton step (milliseconds)."""

from __future__ import annotations

import numpy as np

from omavctl.physics.controller import invert_residual


class _RowModel:
    """A residual that depends on each row's own torque command, body rate and command
    rate, nonlinearly; records the batch size of every call."""

    def __init__(self) -> None:
        self.rows: list[int] = []

    def mean(self, u: np.ndarray, omega: np.ndarray | None = None, du: np.ndarray | None = None):
        assert omega is not None and du is not None
        assert omega.shape == (u.shape[0], 3) and du.shape == u.shape
        self.rows.append(u.shape[0])
        tau = u[:, 3:]
        return 0.3 * np.sin(tau + omega) + 0.2 * omega * tau**2 + 0.05 * du[:, 3:] * tau


def test_each_row_is_solved_at_its_own_rate_and_command_rate() -> None:
    rng = np.random.default_rng(14)
    b = 7
    target, u_force = rng.normal(size=(b, 3)), rng.normal(size=(b, 3))
    omega, du = rng.normal(size=(b, 3)), rng.normal(size=(b, 6))
    model = _RowModel()
    x = invert_residual(target, u_force, model, omega, du=du)
    # every row solves x + mu([u_force, x], omega, du) = target with its own omega, du
    mu = model.mean(np.concatenate([u_force, x], -1), omega, du)
    np.testing.assert_allclose(x + mu, target, atol=1e-9)
    # as a row solved alone
    for i in range(b):
        one = invert_residual(target[i : i + 1], u_force[i : i + 1], _RowModel(), omega[i : i + 1],
                              du=du[i : i + 1])  # fmt: skip
        np.testing.assert_allclose(one, x[i : i + 1], rtol=0, atol=1e-12)


def test_one_model_call_per_newton_step() -> None:
    rng = np.random.default_rng(15)
    b = 5
    model = _RowModel()
    invert_residual(rng.normal(size=(b, 3)), rng.normal(size=(b, 3)), model,
                    rng.normal(size=(b, 3)), du=rng.normal(size=(b, 6)))  # fmt: skip
    # the start, then per step the point and its three forward differences together
    assert model.rows[0] == b and set(model.rows[1:]) == {4 * b}
    assert 2 <= len(model.rows) <= 1 + 6
