"""A failed step's message suggests only what the user has not tried already."""

import pytest

import metriplex as mx
from metriplex._solve.rollout import step_failure


def test_failed_implicit_step_suggests_newton_only_when_it_was_not_used():
    auto = step_failure(mx.CrankNicolson(), 1.0, 1.5)
    newton = step_failure(mx.CrankNicolson(root_finder=mx.Newton()), 1.0, 1.5)
    assert "--solver newton" in auto
    assert "did not converge (solver 'newton')" in newton
    assert "--solver newton" not in newton
    assert "smaller time step" in newton and "--scheme rk4" in newton


def test_failed_explicit_step_speaks_of_a_non_finite_state_not_a_solve():
    message = step_failure(mx.RK4(), 0.0, 0.1)
    assert "non-finite" in message and "converge" not in message


def test_a_root_finder_outside_the_registry_is_named_by_its_class():
    class Bisection(mx.AbstractRootFinder):
        def solve_batch(self, update, x0, guess, args):
            return guess, True, 0

    message = step_failure(mx.CrankNicolson(root_finder=Bisection()), 1.0, 1.5)
    assert "did not converge (solver 'Bisection')" in message
    assert "--solver newton" in message
    with pytest.raises(TypeError):
        mx.AbstractRootFinder()


def test_python_callers_are_told_python_arguments_not_command_line_options():
    message = step_failure(mx.CrankNicolson(), 1.0, 1.5, python=True)
    assert "scheme=CrankNicolson(root_finder=Newton())" in message
    assert "scheme=RK4()" in message
    assert "--" not in message


def test_simulate_names_python_arguments_when_a_rollout_fails():
    import jax.numpy as jnp

    from metriplex.structure import CanonicalPoisson, Known, ZeroFriction, ZeroPotential

    # dq/dt = p, dp/dt = q^3: blows up in finite time (at t = sqrt(2) / q0 = 0.47 from q0 = 3).
    model = mx.GenericModel(Known(lambda x: x[1] ** 2 / 2 - x[0] ** 4 / 4), ZeroPotential(),
                            CanonicalPoisson(2, 1), ZeroFriction(2))
    with pytest.raises(mx.RolloutFailure) as info:
        mx.simulate(model, jnp.array([3.0, 3.0 ** 2 / 2 ** 0.5]), jnp.linspace(0.0, 2.0, 21),
                    retry=0)
    assert "--solver" not in str(info.value) and "--scheme" not in str(info.value)
