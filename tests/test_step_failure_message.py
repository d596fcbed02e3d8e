"""A failed step's message suggests only what the user has not tried already."""

import metriplex as mx
from metriplex._solve.rollout import step_failure


def test_failed_implicit_step_suggests_newton_only_when_it_was_not_used():
    auto = step_failure(mx.CrankNicolson(), 1.0, 1.5)
    newton = step_failure(mx.CrankNicolson(solver="newton"), 1.0, 1.5)
    assert "--solver newton" in auto
    assert "did not converge (solver 'newton')" in newton
    assert "--solver newton" not in newton
    assert "smaller time step" in newton and "--scheme rk4" in newton


def test_failed_explicit_step_speaks_of_a_non_finite_state_not_a_solve():
    message = step_failure(mx.RK4(), 0.0, 0.1)
    assert "non-finite" in message and "converge" not in message
