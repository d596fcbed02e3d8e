"""Exact structure by construction: projected L and M, Jacobi-exact 3-D bivectors, and the
stochastic Jacobi estimator against the exact one."""

import json
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.losses import Batch, ExactJacobi, JacobiPenalty, StochasticJacobi, stochastic_jacobi
from metriplex.structure import (
    CasimirPoisson3,
    CholeskyFriction,
    EntropyCasimirPoisson3,
    Known,
    MLPPotential,
    ProjectedCholeskyFriction,
    ProjectedSkewMLPPoisson,
    Scaling,
    SkewMLPPoisson,
    ZeroFriction,
    ZeroPotential,
)
from metriplex.structure._registry import REGISTRY

N = 5
# Deliberately uneven units: the projectors must work in physical coordinates.
SCALING = Scaling((0.3, -1.0, 5.0, 0.0, 2.0), (0.5, 2.0, 10.0, 0.1, 1.0))


def _states(n, count, seed, spread=None):
    z = jr.normal(jr.key(seed), (count, n))
    if spread is not None:
        z = jnp.asarray(spread.shift)[None, :] + jnp.asarray(spread.scale)[None, :] * z
    return z


def _model(n=N, scaling=SCALING, seed=0, entropy=None, energy=None):
    k = jr.split(jr.key(seed), 4)
    return mx.GenericModel(
        energy=MLPPotential(n, width=16, depth=2, key=k[0]) if energy is None else energy,
        entropy=MLPPotential(n, width=16, depth=2, key=k[1]) if entropy is None else entropy,
        poisson=ProjectedSkewMLPPoisson(n, width=16, depth=2, scaling=scaling, key=k[2]),
        friction=ProjectedCholeskyFriction(n, width=16, depth=2, scaling=scaling, key=k[3]),
    )


@eqx.filter_jit
def _terms(model, xs):
    return jax.vmap(model.terms)(xs)


@eqx.filter_jit
def _fields(model, xs):
    return jax.vmap(model.vector_field)(xs)


@eqx.filter_jit
def _vmap_call(fn, xs):
    return jax.vmap(fn)(xs)


@eqx.filter_jit
def _jacobi(model, xs):
    return jax.vmap(model.jacobi_tensor)(xs)


def _flat_states(scaling):
    return _states(N, 300, 1, scaling)


@pytest.mark.parametrize("scaling", [None, SCALING], ids=["identity", "scaled"])
def test_projected_blocks_are_exactly_degenerate(scaling):
    model = _model(scaling=scaling)
    t = _terms(model, _flat_states(scaling))
    L, M, gE, gS = t.poisson, t.friction, t.grad_energy, t.grad_entropy
    assert bool(jnp.all(jnp.isfinite(L))) and bool(jnp.all(jnp.isfinite(M)))
    # L and M are not trivially small: the projection leaves an (n-1)-dim block.
    assert float(jnp.min(jnp.max(jnp.abs(L), axis=(1, 2)))) > 1e-3
    assert float(jnp.min(jnp.max(jnp.abs(M), axis=(1, 2)))) > 1e-6
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", L, gS)))) < 1e-12
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", M, gE)))) < 1e-12
    assert bool(jnp.all(L == -jnp.swapaxes(L, 1, 2)))
    assert float(jnp.max(jnp.abs(M - jnp.swapaxes(M, 1, 2)))) <= 1e-15 * float(jnp.max(jnp.abs(M)))
    eig = jnp.linalg.eigvalsh(M)
    assert float(jnp.min(eig)) > -1e-13 * float(jnp.max(eig))
    # GENERIC: dE/dt = grad E . f = 0 and dS/dt = grad S . f >= 0.
    f = jnp.einsum("bij,bj->bi", L, gE) + jnp.einsum("bij,bj->bi", M, gS)
    dE = jnp.sum(gE * f, axis=-1)
    dS = jnp.sum(gS * f, axis=-1)
    assert float(jnp.max(jnp.abs(dE))) < 1e-12
    assert float(jnp.min(dS)) > -1e-12
    assert float(jnp.max(dS)) > 1e-6  # the friction is really there


def test_projection_is_the_standardised_orthogonal_projector():
    """L = D P A~ P D with P = I - h h^T/|h|^2, h = D grad S (unit-invariant family)."""
    P = ProjectedSkewMLPPoisson(N, width=16, scaling=SCALING, key=jr.key(3))
    F = ProjectedCholeskyFriction(N, width=16, scaling=SCALING, key=jr.key(4))
    d = jnp.asarray(SCALING.scale)
    x = _states(N, 1, 5, SCALING)[0]
    g = jr.normal(jr.key(6), (N,))
    h = d * g
    Pt = jnp.eye(N) - jnp.outer(h, h) / jnp.sum(h * h)
    A_t = P.base(x) / jnp.outer(d, d)
    np.testing.assert_allclose(P(x, g), d[:, None] * (Pt @ A_t @ Pt) * d[None, :], atol=1e-13)
    B_t = F.base.factor(x) / d[:, None]
    Mt = Pt @ B_t @ B_t.T @ Pt
    np.testing.assert_allclose(F(x, g), d[:, None] * Mt * d[None, :], atol=1e-13)


def test_no_nan_where_gradients_vanish():
    # A critical point of both E and S (x = a), and states approaching it (down to underflow).
    a = jnp.asarray(SCALING.shift)
    dirs = jr.normal(jr.key(7), (4, N))
    near = jnp.concatenate([a[None, :]] + [a[None, :] + r * dirs for r in (1e-300, 1e-17, 1e-9)])
    crit = _model(
        energy=Known(lambda x: 0.5 * jnp.sum((x - a) ** 2)),
        entropy=Known(lambda x: jnp.sum(jnp.cos(x - a))),
    )
    # Zero entropy: nothing to project, L is the unprojected network, exactly.
    zero = _model(entropy=ZeroPotential())
    for m in (zero, crit):
        t = _terms(m, near)
        for arr in (t.poisson, t.friction, _jacobi(m, near)):
            assert bool(jnp.all(jnp.isfinite(arr)))
    # (Separately compiled programs may round differently: compare to rounding, not bits.)
    np.testing.assert_allclose(
        _terms(zero, near).poisson, _vmap_call(zero.poisson.base, near), rtol=1e-13, atol=1e-15
    )
    t = _terms(crit, near)  # g = 0 exactly at x = a: L = A, M = B B^T
    np.testing.assert_allclose(t.poisson[0], crit.poisson.base(a), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(t.friction[0], crit.friction.base(a), rtol=1e-13, atol=1e-15)
    # Training gradients through the projectors, Jacobi term included, stay finite at g = 0.
    loss = mx.DegeneracyPenalty() + JacobiPenalty(ExactJacobi())
    batch = Batch(near, near + 0.01, jnp.full((near.shape[0],), 0.1), jnp.ones((N,)))
    grads = eqx.filter_jit(eqx.filter_grad(lambda m: loss(m, batch)[0]))(crit)
    leaves = jax.tree_util.tree_leaves(eqx.filter(grads, eqx.is_inexact_array))
    assert leaves and all(bool(jnp.all(jnp.isfinite(g))) for g in leaves)


def test_degeneracy_leak_is_bounded_by_eps():
    """|D^-1 L grad S| <= eps |A~| / 2 at every |grad S|, with a deliberately large eps."""
    eps = 1e-3
    P = ProjectedSkewMLPPoisson(N, width=16, scaling=SCALING, eps=eps, key=jr.key(8))
    d = jnp.asarray(SCALING.scale)
    x = _states(N, 1, 9, SCALING)[0]
    A_t = P.base(x) / jnp.outer(d, d)
    bound = 0.5 * eps * float(jnp.linalg.norm(A_t, 2))
    g0 = jr.normal(jr.key(10), (N,))
    for r in 10.0 ** np.arange(-8.0, 2.0, 0.5):
        leak = jnp.linalg.norm(P(x, r * g0) @ (r * g0) / d)
        assert float(leak) <= bound * (1.0 + 1e-9)
    # An eps whose square underflows still gives L = A at g = 0, not 0 * inf.
    tiny = ProjectedSkewMLPPoisson(N, width=16, scaling=SCALING, eps=1e-200, key=jr.key(8))
    assert bool(jnp.all(tiny(x, jnp.zeros((N,))) == tiny.base(x)))


def _jacobi_rms(model, xs):
    J = _jacobi(model, xs)
    return float(jnp.sqrt(jnp.mean(jnp.sum(J**2, axis=(1, 2, 3)))))


def _model3(poisson, entropy=None):
    return mx.GenericModel(
        energy=MLPPotential(3, width=16, key=jr.key(11)),
        entropy=MLPPotential(3, width=16, key=jr.key(12)) if entropy is None else entropy,
        poisson=poisson,
        friction=ZeroFriction(3),
    )


SCALING3 = Scaling((0.5, -0.2, 1.0), (2.0, 0.5, 3.0))


def test_casimir3_satisfies_jacobi_and_generic_does_not():
    xs = _states(3, 64, 13, SCALING3)
    cas = _model3(CasimirPoisson3(width=16, scaling=SCALING3, key=jr.key(14)))
    ent = _model3(EntropyCasimirPoisson3(width=16, scaling=SCALING3, key=jr.key(15)))
    skew = _model3(SkewMLPPoisson(3, width=16, scaling=SCALING3, key=jr.key(16)))
    for m in (cas, ent):
        L = _vmap_call(m.poisson_matrix, xs)
        assert bool(jnp.all(L == -jnp.swapaxes(L, 1, 2)))
        assert float(jnp.min(jnp.max(jnp.abs(L), axis=(1, 2)))) > 1e-4
        assert _jacobi_rms(m, xs) < 1e-10
    assert _jacobi_rms(skew, xs) > 1e-3
    # The learned Casimir C is conserved by L (L grad C = 0); the entropy variant is degenerate.
    p = cas.poisson

    @eqx.filter_jit
    def casimir_leak(p, x):
        gC = jax.grad(p.casimir)(p._z(x)) / jnp.asarray(SCALING3.scale)
        return p(x) @ gC

    assert float(jnp.max(jnp.abs(jax.vmap(casimir_leak, (None, 0))(p, xs)))) < 1e-12
    t = _terms(ent, xs)
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", t.poisson, t.grad_entropy)))) < 1e-12
    # epsilon_ijk convention: L v = v x w, so the rigid body L = -eps m is w = -m.
    from metriplex.structure.casimir import _cross_matrix

    w, v = jr.normal(jr.key(17), (2, 3))
    np.testing.assert_allclose(_cross_matrix(w) @ v, jnp.cross(v, w), atol=1e-15)


def test_casimir3_rejects_other_sizes():
    with pytest.raises(mx.MetriplexError, match="needs n = 3; got n=4"):
        CasimirPoisson3(4, key=jr.key(0))
    with pytest.raises(mx.MetriplexError, match="must be finite and > 0"):
        ProjectedSkewMLPPoisson(3, eps=0.0, key=jr.key(0))


def test_stochastic_jacobi_matches_exact():
    n = 4
    scale = jnp.asarray([0.5, 2.0, 1.0, 3.0])
    model = mx.GenericModel(
        energy=ZeroPotential(),
        entropy=ZeroPotential(),
        poisson=SkewMLPPoisson(n, width=16, key=jr.key(20)),
        friction=ZeroFriction(n),
    )
    xs = _states(n, 4, 21)
    # The trilinear form on basis vectors is the tensor, entry by entry.
    J = _jacobi(model, xs[:1])[0]
    E = jnp.eye(n)
    Jb = jax.jit(lambda: jax.vmap(
        lambda i: jax.vmap(
            lambda j: jax.vmap(lambda l: stochastic_jacobi(model, xs[0], E[i], E[j], E[l]))(
                jnp.arange(n)
            )
        )(jnp.arange(n))
    )(jnp.arange(n)))()
    np.testing.assert_allclose(Jb, J, atol=1e-12)
    batch = Batch(xs, xs, jnp.ones((4,)), scale)
    exact = float(eqx.filter_jit(JacobiPenalty(ExactJacobi()))(model, batch, None, jr.key(0)))
    stoch = eqx.filter_jit(
        lambda k: JacobiPenalty(StochasticJacobi(probes=64))(model, batch, None, k))
    est = np.array([float(stoch(k)) for k in jr.split(jr.key(22), 60)])
    se = est.std(ddof=1) / np.sqrt(len(est))
    assert exact > 0.0
    assert abs(est.mean() - exact) < 4.0 * se, (est.mean(), exact, se)
    assert se < 0.2 * exact  # the test has power


def test_jacobi_penalty_on_a_subset_of_the_batch():
    n = 4
    model = mx.GenericModel(ZeroPotential(), ZeroPotential(),
                            SkewMLPPoisson(n, width=16, key=jr.key(23)), ZeroFriction(n))
    xs = _states(n, 8, 24)
    scale = jnp.ones((n,))

    def penalty(samples=None):  # compiled once per setting and shape, not op by op
        kw = {} if samples is None else {"samples": samples}
        return eqx.filter_jit(lambda m, b: JacobiPenalty(ExactJacobi(), **kw)(m, b, None, None))

    one = penalty()
    per_state = [float(one(model, Batch(xs[i:i + 1], xs[i:i + 1], jnp.ones((1,)), scale)))
                 for i in range(8)]
    batch = Batch(xs, xs, jnp.ones((8,)), scale)
    # samples=2 of 8: every 4th pair, i.e. pairs 0 and 4.
    sub = float(penalty(2)(model, batch))
    np.testing.assert_allclose(sub, 0.5 * (per_state[0] + per_state[4]), rtol=1e-12)
    full = float(penalty(100)(model, batch))
    np.testing.assert_allclose(full, np.mean(per_state), rtol=1e-12)
    with pytest.raises(mx.MetriplexError, match="samples must be >= 1"):
        JacobiPenalty(ExactJacobi(), samples=0)


def _all_models():
    k = jr.split(jr.key(30), 6)
    return {
        "projected": _model(scaling=SCALING, seed=31),
        "projected-eps": mx.GenericModel(
            energy=MLPPotential(N, width=16, key=k[0]),
            entropy=MLPPotential(N, width=16, key=k[1]),
            poisson=ProjectedSkewMLPPoisson(
                N, width=16, depth=1, activation="tanh", eps=1e-9, key=k[2]
            ),
            friction=ProjectedCholeskyFriction(N, width=16, depth=3, eps=1e-7, key=k[3]),
        ),
        "casimir3": _model3(CasimirPoisson3(width=16, scaling=SCALING3, key=k[4])),
        "casimir3-entropy": _model3(EntropyCasimirPoisson3(width=16, depth=1, key=k[5])),
        "friction-features": _pendulum_model(exact=False),
        "projected-friction-features": _pendulum_model(exact=True),
        "projected-lie-poisson": mx.GenericModel(
            energy=MLPPotential(N, width=16, key=k[0]), entropy=mx.SumOf((N - 1,)),
            poisson=mx.ProjectedLiePoisson(N, scaling=SCALING, eps=1e-9, key=k[2]),
            friction=ProjectedCholeskyFriction(N, width=16, key=k[3])),
    }


def _pendulum_model(exact: bool):
    from metriplex.config import FEATURES

    feats = FEATURES["pendulum"]
    data = np.asarray(jr.normal(jr.key(35), (64, 10)))
    cls = ProjectedCholeskyFriction if exact else mx.CholeskyFriction
    k = jr.split(jr.key(36), 2)
    return mx.GenericModel(
        energy=MLPPotential(10, width=16, features=feats, data=data, key=k[0]),
        entropy=mx.SumOf((8, 9)),
        poisson=mx.CanonicalPoisson(10, 4),
        friction=cls(10, width=16, features=feats, data=data, key=k[1]),
    )


def _predict(model, n):
    return np.asarray(_fields(model, _states(n, 32, 40)))


def test_model_files_that_call_the_networks_mlp_still_load(tmp_path):
    # Files written before the network blocks took the command line's name ("neural") say
    # "mlp" and "projected-mlp"; they load as the same blocks, with the same predictions.
    model = mx.GenericModel(
        energy=MLPPotential(N, width=8, key=jr.key(1)),
        entropy=MLPPotential(N, width=8, key=jr.key(2)),
        poisson=mx.MaskedPoisson(ProjectedSkewMLPPoisson(N, width=8, key=jr.key(3)), (1,)),
        friction=CholeskyFriction(N, width=8, key=jr.key(4)),
    )
    path = tmp_path / "new.mpx"
    mx.save(path, model, n=N)
    raw = path.read_bytes()
    head, rest = raw.split(b"\n", 1)[0], raw.split(b"\n", 1)[1]
    header, leaves = rest.split(b"\n", 1)
    assert b'"neural"' in header and b'"projected-neural"' in header
    old = header.replace(b'"projected-neural"', b'"projected-mlp"').replace(b'"neural"', b'"mlp"')
    (tmp_path / "old.mpx").write_bytes(head + b"\n" + old + b"\n" + leaves)
    back = mx.load(tmp_path / "old.mpx")
    assert back.spec() == model.spec()
    assert np.array_equal(_predict(back, N), _predict(model, N))


def test_save_load_round_trip(tmp_path):
    assert REGISTRY["poisson"]["projected-neural"] is ProjectedSkewMLPPoisson
    assert REGISTRY["poisson"]["casimir3"] is CasimirPoisson3
    assert REGISTRY["poisson"]["casimir3-entropy"] is EntropyCasimirPoisson3
    assert REGISTRY["friction"]["projected-neural"] is ProjectedCholeskyFriction
    assert REGISTRY["poisson"]["projected-lie-poisson"] is mx.ProjectedLiePoisson
    expected = {}
    for name, model in _all_models().items():
        n = model.poisson.n
        path = tmp_path / f"{name}.mpx"
        mx.save(path, model, n=n)
        back = mx.load(path)
        assert back.spec() == model.spec()
        assert type(back.poisson) is type(model.poisson)
        a = jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_array))
        b = jax.tree_util.tree_leaves(eqx.filter(back, eqx.is_array))
        # Compared in NumPy: jnp's == would compile for every shape of weight.
        assert len(a) == len(b) and all(np.array_equal(np.asarray(u), np.asarray(v))
                                        for u, v in zip(a, b))
        pred = _predict(model, n)
        assert np.array_equal(pred, _predict(back, n))
        expected[name] = (str(path), n, pred)
    # A fresh process rebuilds every model from the file alone, bit for bit. (Its `_fields` is
    # the one above, so with the suite's compilation cache it reuses what this process
    # compiled: the weights are arguments of that program, read from the files.)
    script = (
        "import sys, json, numpy as np, jax\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "import equinox as eqx, jax.random as jr, metriplex as mx\n"
        "@eqx.filter_jit\n"
        "def _fields(model, xs):\n"
        "    return jax.vmap(model.vector_field)(xs)\n"
        "out = {}\n"
        "for name, (path, n) in json.loads(sys.argv[1]).items():\n"
        "    m = mx.load(path)\n"
        "    x = jr.normal(jr.key(40), (32, n))\n"
        "    out[name] = np.asarray(_fields(m, x))\n"
        "np.savez(sys.argv[2], **out)\n"
    )
    arg = json.dumps({k: [v[0], v[1]] for k, v in expected.items()})
    res = tmp_path / "fresh.npz"
    subprocess.run([sys.executable, "-c", script, arg, str(res)], check=True, timeout=120)
    with np.load(res) as fresh:
        for name, (_, _, pred) in expected.items():
            assert np.array_equal(fresh[name], pred), name


def test_degeneracy_exact_builds_what_it_records_for_every_learned_L():
    # --degeneracy exact made run folders record L grad S = 0 exact for casimir3 and
    # lie-poisson while building neither exactly and dropping the penalty (new-user audit).
    from metriplex.app._build import build_loss, build_model
    from metriplex.app.config import RunConfig, exact_blocks
    from metriplex.systems import generate

    data = generate("oscillator-bath", trajectories=2, steps=5, seed=0)
    x = jnp.asarray(data.x[:4])
    exact = RunConfig(poisson="casimir3", entropy="sum:2", degeneracy="exact")
    assert exact_blocks(exact)[0]
    model = build_model(exact, data, key=jr.key(0))
    assert isinstance(model.poisson, EntropyCasimirPoisson3)
    gS = jax.vmap(jax.grad(model.entropy))(x)
    L = jax.vmap(model.poisson)(x, gS)
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", L, gS)))) < 1e-12
    assert float(jnp.max(jnp.abs(L))) > 1e-3  # not L = 0
    # With S = 0 there is nothing to be degenerate to: the plain casimir3, no penalty to drop.
    assert not exact_blocks(RunConfig(poisson="casimir3", entropy="zero", degeneracy="exact"))[0]
    with pytest.raises(mx.MetriplexError, match="--degeneracy exact .* got --poisson "
                                                "lie-poisson with --entropy neural. Give S"):
        build_model(RunConfig(poisson="lie-poisson", degeneracy="exact"), data, key=jr.key(0))
    # Beside a sum of entropy variables exact projects a Lie-Poisson L: the sum's gradient is
    # constant, so L stays linear in the state, and L grad S = 0 exactly.
    for degeneracy in ("exact",):
        config = RunConfig(poisson="lie-poisson", entropy="sum:2", degeneracy=degeneracy)
        assert exact_blocks(config)[0]
        assert "PoissonDegeneracy" not in repr(build_loss(config, None, data))
        model = build_model(config, data, key=jr.key(0))
        assert isinstance(model.poisson, mx.ProjectedLiePoisson)
        gS = jax.vmap(jax.grad(model.entropy))(x)
        L = jax.vmap(model.poisson)(x, gS)
        assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", L, gS)))) < 1e-12
        assert float(jnp.max(jnp.abs(L))) > 1e-3
        np.testing.assert_allclose(model.poisson(2.5 * x[0], gS[0]), 2.5 * L[0], rtol=1e-12,
                                   atol=1e-12)  # linear
        assert float(jnp.max(jnp.abs(L[:, 2]))) < 1e-12  # s brackets with nothing
    # auto and soft keep the penalty (exact measured less accurate: docs/zoo.md).
    for degeneracy in ("auto", "soft"):
        auto = RunConfig(poisson="lie-poisson", entropy="sum:2", degeneracy=degeneracy)
        assert not exact_blocks(auto)[0]
        assert "PoissonDegeneracy" in repr(build_loss(auto, None, data))


@pytest.mark.parametrize("degeneracy", ["auto", "exact"])
def test_a_lie_poisson_l_is_not_linear_in_the_given_entropy_variables(tmp_path, degeneracy):
    # An entropy's zero is arbitrary: a new-user check recorded a bath's entropy at 1000, and
    # the term c^s s of a Lie-Poisson L made it one constant matrix (the model worse than
    # predicting no motion). Built beside --entropy sum:..., L is linear in the others only,
    # so an offset on the entropy variable changes nothing; it survives the model file.
    from metriplex.app._build import build_model
    from metriplex.app.config import RunConfig

    data = mx.systems.generate("oscillator-bath", trajectories=2, steps=5, seed=0)
    config = RunConfig(poisson="lie-poisson", entropy="sum:2", degeneracy=degeneracy)
    model = build_model(config, data, key=jr.key(0))
    block = model.poisson if degeneracy == "auto" else model.poisson.base
    assert block.linear_in == (0, 1)
    x = jnp.asarray(data.x[3])
    gS = jax.grad(model.entropy)(x)
    shifted = x.at[2].add(1000.0)
    np.testing.assert_array_equal(model.poisson(x, gS), model.poisson(shifted, gS))
    assert float(jnp.max(jnp.abs(model.poisson(x, gS)))) > 1e-3
    mx.save(tmp_path / "m.mpx", model, n=3)
    loaded = mx.load(tmp_path / "m.mpx")
    np.testing.assert_array_equal(loaded.poisson(shifted, gS), model.poisson(x, gS))
    # Without a given entropy (the rigid body) it stays linear in every variable.
    free = build_model(RunConfig(poisson="lie-poisson"), data, key=jr.key(0)).poisson
    assert free.linear_in is None
    with pytest.raises(mx.MetriplexError, match="linear in some of its 3 variables"):
        mx.LiePoisson(3, linear_in=(3,), key=jr.key(0))
