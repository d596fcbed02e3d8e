"""The optional L-BFGS finish after the Adam stage: it lowers the loss on its fixed batch, and
fit keeps its model only where the validation score improves."""

import pytest

from metriplex._errors import MetriplexError
from metriplex.config import RunConfig, validate
from metriplex.runs import train_run
from helpers import damped_oscillator, make_data, oscillator_x0

CONFIG = RunConfig(entropy="sum:2", poisson="canonical:1", width=8, steps=300, eval_every=50,
                   schedule="cosine", float64=True)


@pytest.fixture(scope="module")
def data():
    return make_data(damped_oscillator(), oscillator_x0(6), 0.1, 20, names=("q", "p", "s"))


def test_lbfgs_finish_lowers_the_loss_and_keeps_the_better_model(tmp_path, data):
    config = RunConfig(**{**CONFIG.to_json(), "lbfgs_steps": 100})
    _, history, *_ = train_run(data, config, tmp_path / "run", progress=False)
    adam = history.step.index(CONFIG.steps) + 1  # evaluations of the Adam stage
    # L-BFGS adds two evaluations of 50 iterations each.
    assert history.step[adam:] == [350, 400] and history.lbfgs_steps == 100
    # From the best Adam model, on the training pairs, the loss falls well below Adam's.
    assert min(history.train["total"][adam:]) < 0.5 * min(history.train["total"][:adam])
    # The model kept is the best by the validation rollouts over both stages.
    assert history.best_rollout == min(history.rollout)


def test_negative_lbfgs_steps_are_refused():
    with pytest.raises(MetriplexError, match=r"--lbfgs-steps must be >= 0 .* got -5"):
        validate(RunConfig(lbfgs_steps=-5), 3)
