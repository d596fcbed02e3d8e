"""The learning-rate schedule is chosen by name on the command line and reaches fit as an object."""

import jax.numpy as jnp
import pytest

from metriplex._errors import MetriplexError
from metriplex.app._build import stopping_for
from metriplex.config import SCHEDULES, RunConfig, validate
from metriplex.runs import train_run
from metriplex.train import Plateau
from helpers import damped_oscillator, make_data, oscillator_x0


def test_schedule_names_become_stopping_objects():
    assert stopping_for(RunConfig()) == Plateau(cuts=RunConfig().lr_cuts)
    assert stopping_for(RunConfig(patience=4)) == Plateau(patience=4, cuts=RunConfig().lr_cuts)
    assert stopping_for(RunConfig(schedule="cosine", patience=4)) is None
    assert set(SCHEDULES) == {"plateau", "cosine"}


def test_an_unknown_schedule_is_refused_with_the_choices():
    with pytest.raises(MetriplexError, match=r"--schedule must be one of plateau, cosine; got 'step'"):
        validate(RunConfig(schedule="step"), 3)


@pytest.mark.slow
def test_cosine_runs_the_whole_budget(cosine_lbfgs_run):
    # The session's cosine-schedule run (tests/conftest.py; it has test_lbfgs's L-BFGS finish
    # after the Adam stage, which is what is checked here). The cosine schedule never stops
    # early: its Adam stage runs the whole budget, and the rate decays to 1% of the peak.
    config, history = cosine_lbfgs_run
    assert config.schedule == "cosine" and stopping_for(config) is None
    adam = history.step.index(config.steps) + 1  # evaluations of the Adam stage
    assert history.step[:adam] == list(range(0, config.steps + 1, config.eval_every))
    assert history.stopped.startswith("step budget")
    assert history.learning_rate[adam - 1] < 0.02 * config.lr
    assert history.learning_rate[0] > 0 and jnp.isfinite(history.train["total"][adam - 1])


def test_plateau_stops_on_its_own(tmp_path):
    data = make_data(damped_oscillator(), oscillator_x0(6), 0.1, 20, names=("q", "p", "s"))
    # patience 1 and no cuts: the plateau schedule stops at the first evaluation that does not
    # improve, long before its 3 000-step budget.
    budget = 3000
    config = RunConfig(entropy="sum:2", poisson="canonical:1", width=8, steps=budget,
                       eval_every=50, patience=1, lr_cuts=0, schedule="plateau", float64=True,
                       repeats=1)  # one training: its schedule is the subject
    _, history, *_ = train_run(data, config, tmp_path / "plateau", progress=False)
    assert history.step[-1] < budget and history.converged
    assert history.learning_rate[0] > 0 and jnp.isfinite(history.train["total"][-1])


def test_the_default_optimiser_state_lets_the_plateau_cut_the_rate():
    # The plateau schedule cuts the learning rate through the injected hyperparameter; an
    # optimiser state it cannot read stops training at the first plateau, uncut (a change to
    # how the state was recognised once did that silently: "after 0 learning-rate cuts").
    from metriplex._optimizers import adjustable_optimizer, is_adjustable, learning_rate_of
    from metriplex._optimizers import with_learning_rate

    state = adjustable_optimizer(1e-2).init({"w": jnp.zeros(3)})
    assert is_adjustable(state)
    assert learning_rate_of(with_learning_rate(state, 3e-3), 0.0) == pytest.approx(3e-3)


def test_plateau_cuts_the_rate_before_it_stops(tmp_path):
    data = make_data(damped_oscillator(), oscillator_x0(6), 0.1, 20, names=("q", "p", "s"))
    config = RunConfig(entropy="sum:2", poisson="canonical:1", width=8, steps=3000,
                       eval_every=50, patience=1, lr_cuts=2, schedule="plateau", float64=True,
                       repeats=1)  # one training: its schedule is the subject
    _, history, *_ = train_run(data, config, tmp_path / "plateau", progress=False)
    assert history.converged and "after 2 learning-rate cuts" in history.stopped
    rates = sorted(set(history.learning_rate), reverse=True)
    assert rates[:3] == pytest.approx([1e-2, 3e-3, 9e-4])
