"""The learning-rate schedule is chosen by name on the command line and reaches fit as an object."""

import jax.numpy as jnp
import pytest

from metriplex._errors import MetriplexError
from metriplex._build import stopping_for
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
                       eval_every=50, patience=1, lr_cuts=0, schedule="plateau", float64=True)
    _, history, *_ = train_run(data, config, tmp_path / "plateau", progress=False)
    assert history.step[-1] < budget and history.converged
    assert history.learning_rate[0] > 0 and jnp.isfinite(history.train["total"][-1])
