"""Progress bars that say where in a run they are: a run of several trainings, each with stages,
labels each bar (training k of at most K, the stage), and a fit that a stopping rule ends says
that its estimate of the time left runs to the step cap, and how far the rule has come."""

import io

import jax.random as jr
import pytest

import metriplex as mx
from metriplex import _progress
from metriplex.app import _repeats
from helpers import damped_oscillator, make_data, oscillator_x0


def test_labels_prefix_the_bars_opened_inside_them():
    def desc(**kwargs):
        return _progress.progress_bar(total=1, file=io.StringIO(), **kwargs).desc

    assert desc(desc="fit") == "fit"
    with _progress.progress_label("training 2 of at most 4"):
        assert desc(desc="fit") == "training 2 of at most 4, fit"
        with _progress.progress_label("first stage"):
            assert desc(desc="fit") == "training 2 of at most 4, first stage, fit"
            assert desc() == "training 2 of at most 4, first stage"
        assert desc(desc="L-BFGS") == "training 2 of at most 4, L-BFGS"
    assert desc(desc="fit") == "fit"  # left with the block, an exception or not
    with pytest.raises(KeyError), _progress.progress_label("x"):
        raise KeyError
    assert desc(desc="fit") == "fit"


@pytest.mark.parametrize("repeats", [1, 4])
def test_each_training_of_several_is_labelled(tmp_path, repeats):
    from metriplex._train import History

    labels = []

    def one(r, resumed):  # poor every time, so every training runs
        labels.append(_progress._LABELS.get())
        return f"model {r}", History(step=[0, 100], best_step=100, best_rollout=0.9,
                                     best_rollout_failures=0, converged=True)

    _repeats.train_repeats(one, repeats=repeats, out=tmp_path, resume=False, budget=None,
                           began=0.0, keep=lambda m, h: None)
    assert labels == ([()] if repeats == 1 else
                      [(f"training {r} of at most 4",) for r in range(1, 5)])
    assert _progress._LABELS.get() == ()


def test_a_fit_under_a_stopping_rule_says_its_estimate_is_the_caps(capsys, monkeypatch):
    monkeypatch.setattr(_progress, "_terminal", lambda stream=None: True)  # every frame drawn
    data = make_data(damped_oscillator(), oscillator_x0(4), 0.1, 12, names=("q", "p", "s"))
    model = mx.GenericModel(
        energy=mx.MLPPotential(3, width=8, key=jr.key(0)),
        entropy=mx.SumOf((2,)), poisson=mx.CanonicalPoisson(3, pairs=1),
        friction=mx.CholeskyFriction(3, width=8, key=jr.key(1)))
    capsys.readouterr()
    with _progress.progress_label("training 1 of at most 2"):
        mx.fit(model, data, steps=40, eval_every=20, rollout_check=None, progress=True,
               key=jr.key(2))
    err = capsys.readouterr().err
    assert "training 1 of at most 2, fit:" in err, err
    assert "cap in " in err and "lr_cuts=0/" in err, err
    mx.fit(model, data, steps=40, eval_every=20, stopping=None, rollout_check=None,
           progress=True, key=jr.key(2))
    err = capsys.readouterr().err
    assert "fit:" in err and "training 1" not in err and "cap in" not in err, err
    assert "lr_cuts" not in err, err
