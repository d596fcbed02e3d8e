"""The optional L-BFGS finish after the Adam stage: it lowers the loss on its fixed batch, and
fit keeps its model only where the validation score improves."""

import pytest

from metriplex._errors import MetriplexError
from metriplex.config import RunConfig, validate


@pytest.mark.slow
def test_lbfgs_finish_lowers_the_loss_and_keeps_the_better_model(cosine_lbfgs_run):
    # The session's run (tests/conftest.py): 300 cosine-schedule Adam steps, evaluated every
    # 50, then lbfgs_steps=100; its Adam stage is also test_schedule's cosine run.
    config, history = cosine_lbfgs_run
    assert config.lbfgs_steps == 100 and config.eval_every == 50
    adam = history.step.index(config.steps) + 1  # evaluations of the Adam stage
    # L-BFGS adds two evaluations of 50 iterations each.
    assert history.step[adam:] == [350, 400] and history.lbfgs_steps == 100
    # From the best Adam model, on the training pairs, the loss falls well below Adam's.
    assert min(history.train["total"][adam:]) < 0.5 * min(history.train["total"][:adam])
    # The model kept is the best by the validation rollouts over both stages.
    assert history.best_rollout == min(history.rollout)


def test_negative_lbfgs_steps_are_refused():
    with pytest.raises(MetriplexError, match=r"--lbfgs-steps must be an integer >= 0; got -5\. "
                                             r"It counts the iterations of the L-BFGS finish"):
        validate(RunConfig(lbfgs_steps=-5), 3)
