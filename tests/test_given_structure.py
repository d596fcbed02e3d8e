"""Structure the user knows, given as data: constant L and M from files, a Lie–Poisson prior."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
import scipy.io

import metriplex as mx
from metriplex.app._build import build_model
from metriplex.config import RunConfig, validate
from helpers import damped_oscillator, make_data, oscillator_x0

CANONICAL = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def test_constant_blocks_check_their_matrices():
    L = mx.ConstantPoisson(CANONICAL)
    x = jnp.ones(3)
    np.testing.assert_array_equal(np.asarray(L(x, x)), CANONICAL)
    with pytest.raises(mx.MetriplexError, match=r"must be antisymmetric .* max \|L \+ L\^T\| = 2"):
        mx.ConstantPoisson(np.eye(3))
    with pytest.raises(mx.MetriplexError, match="must be symmetric"):
        mx.ConstantFriction(CANONICAL)
    with pytest.raises(mx.MetriplexError, match="positive semi-definite .* eigenvalue -1"):
        mx.ConstantFriction(-np.eye(3))
    with pytest.raises(mx.MetriplexError, match="square n x n matrix"):
        mx.ConstantFriction(np.ones((2, 3)))
    M = mx.ConstantFriction(np.diag([0.0, 1.0, 2.0]))
    assert np.asarray(M(x, x)).shape == (3, 3)


def test_a_friction_matrix_rounded_to_six_digits_or_float32_is_taken(tmp_path):
    # M grad E = 0 needs a null space: a rank-one M = w w^T typed to six digits, or stored in
    # float32, has eigenvalues of -1e-8 relative, and was refused as "not PSD (M, not -M)".
    rng = np.random.default_rng(0)
    for k in range(5):
        w = rng.normal(size=4)
        exact = np.outer(w, w)
        for given in (np.array([[float(f"{v:.6g}") for v in row] for row in exact]),
                      exact.astype(np.float32)):
            M = np.asarray(mx.ConstantFriction(given)(jnp.ones(4), jnp.ones(4)), np.float64)
            # Negative rounding set to zero (what is left is float64's, not the input's 1e-8).
            assert np.linalg.eigvalsh(M).min() >= -1e-14 * np.abs(exact).max()
            assert np.abs(M - exact).max() < 1e-5 * np.abs(exact).max()
    # An indefinite M is still refused, naming the file it came from.
    np.save(tmp_path / "M.npy", np.diag([1.0, -1e-3, 0.0]))
    with pytest.raises(mx.MetriplexError, match=r"--friction file:.*M\.npy: a friction matrix "
                                                r"must be positive semi-definite .* -0\.001"):
        validate(RunConfig(poisson="canonical:1", entropy="sum:2",
                           friction=f"file:{tmp_path / 'M.npy'}"), 3)


def test_lie_poisson_is_linear_and_antisymmetric():
    L = mx.LiePoisson(3, key=jr.key(0))
    a, b = jnp.array([1.0, -2.0, 0.5]), jnp.array([0.3, 0.1, -1.0])
    La, Lb = L(a), L(b)
    np.testing.assert_allclose(np.asarray(L(2.0 * a - 3.0 * b)), np.asarray(2.0 * La - 3.0 * Lb),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(La), -np.asarray(La).T)


@pytest.mark.parametrize("suffix", [".npy", ".npz", ".mat"])
def test_cli_config_reads_constant_operators(tmp_path, suffix):
    data = make_data(damped_oscillator(), oscillator_x0(4), 0.1, 10, names=("q", "p", "s"))
    path = tmp_path / f"ops{suffix}"
    if suffix == ".npy":
        np.save(path, CANONICAL)
    elif suffix == ".npz":
        np.savez(path, L=CANONICAL)
    else:
        scipy.io.savemat(path, {"L": CANONICAL})
    config = RunConfig(poisson=f"file:{path}", entropy="sum:2", width=8)
    model = build_model(config, data, key=jr.key(0))
    assert isinstance(model.poisson, mx.ConstantPoisson)
    saved = tmp_path / "m.mpx"
    mx.save(saved, model, n=3)
    np.testing.assert_array_equal(np.asarray(mx.load(saved).poisson(jnp.ones(3), jnp.ones(3))),
                                  CANONICAL)


def test_cli_config_rejects_a_wrong_operator_file(tmp_path):
    np.save(tmp_path / "L.npy", np.zeros((4, 4)))
    with pytest.raises(mx.MetriplexError, match=r"has shape \(4, 4\); the data have 3 variables"):
        validate(RunConfig(poisson=f"file:{tmp_path / 'L.npy'}"), 3)
    with pytest.raises(mx.MetriplexError, match="does not exist"):
        validate(RunConfig(friction=f"file:{tmp_path / 'missing.npy'}"), 3)
    (tmp_path / "L.txt").write_text("0 1\n-1 0\n")
    with pytest.raises(mx.MetriplexError, match="reads .npy, .npz or .mat"):
        validate(RunConfig(poisson=f"file:{tmp_path / 'L.txt'}"), 2)


def test_operator_mat_files_are_read_as_the_data_reader_reads_them(tmp_path):
    # A sparse L (as scipy.io.savemat stores a scipy.sparse matrix, and MATLAB a sparse one)
    # and an L inside the file's only struct are read; a complex L is refused by name.
    import scipy.sparse

    from metriplex.io._operators import read_matrix

    scipy.io.savemat(tmp_path / "sparse.mat", {"L": scipy.sparse.csc_matrix(CANONICAL)})
    np.testing.assert_array_equal(read_matrix(str(tmp_path / "sparse.mat"), "L", 3), CANONICAL)
    scipy.io.savemat(tmp_path / "struct.mat",
                     {"data": {"Z": np.zeros((2, 3, 4)), "L": CANONICAL}})
    np.testing.assert_array_equal(read_matrix(str(tmp_path / "struct.mat"), "L", 3), CANONICAL)
    with pytest.raises(mx.MetriplexError, match=r"struct `data` .* has no variable 'M'"):
        read_matrix(str(tmp_path / "struct.mat"), "M", 3)
    scipy.io.savemat(tmp_path / "complex.mat", {"L": CANONICAL * (1 + 1j)})
    with pytest.raises(mx.MetriplexError, match="holds complex numbers; --poisson needs a real"):
        read_matrix(str(tmp_path / "complex.mat"), "L", 3)


def test_zoo_cases_are_registered_and_distinct_from_the_reference_systems():
    from metriplex.systems import SYSTEMS
    from metriplex.systems.zoo import ZOO

    assert len(ZOO) >= 8
    ns = sorted(c.system.n for c in ZOO.values())
    assert ns[0] <= 2 and ns[-1] >= 30
    assert any(c.held_out for c in ZOO.values()) and not all(c.held_out for c in ZOO.values())
    for name, case in ZOO.items():
        assert SYSTEMS[name] is case.system
        assert name not in ("rigid-body", "pendulum-energetic", "pendulum-temperature",
                            "gas-containers")
        validate(RunConfig(**dict(case.flags)), case.system.n)


def test_a_learned_s_beside_a_given_l_is_one_of_its_casimirs(tmp_path):
    # With L given (canonical on (q, p), or the same L from a file) and S learned, S is made a
    # function of s alone, the variable L leaves free: L grad S = 0 holds exactly, so the
    # model's entropy cannot fall along its own flow. --degeneracy soft learns it of all.
    from helpers import oscillator_data

    data = oscillator_data()
    np.save(tmp_path / "L.npy", CANONICAL)
    x = jnp.asarray(data.x[::7])
    for poisson in ("canonical:1", f"file:{tmp_path / 'L.npy'}"):
        config = RunConfig(poisson=poisson, width=8)
        model = build_model(config, data, key=jr.key(0))
        terms = [model.terms(xi) for xi in x]
        gS = np.array([np.asarray(t.grad_entropy) for t in terms])
        assert np.all(gS[:, :2] == 0) and np.all(gS[:, 2] != 0), poisson
        LgS = np.array([np.asarray(t.poisson @ t.grad_entropy) for t in terms])
        assert np.all(LgS == 0), poisson
    soft = build_model(RunConfig(poisson="canonical:1", width=8, degeneracy="soft"), data,
                       key=jr.key(0))
    assert np.any(np.asarray(soft.terms(x[0]).grad_entropy)[:2] != 0)
    # Where L's free variables are not coordinates (here none: L is nondegenerate on all),
    # nothing changes.
    from metriplex.app._build import casimir_variables
    assert casimir_variables(RunConfig(poisson="canonical:2"), mx.CanonicalPoisson(4, 2)) is None
    assert casimir_variables(RunConfig(poisson="canonical:1", entropy="sum:2"),
                             mx.CanonicalPoisson(3, 1)) is None
    assert casimir_variables(RunConfig(poisson="zero"), mx.ZeroPoisson(3)) is None


def test_activation_reaches_every_learned_network(tmp_path):
    """``--activation`` (RunConfig.activation) builds every learned block with it, and the
    model file keeps it."""
    data = make_data(damped_oscillator(), oscillator_x0(4), 0.1, 10, names=("q", "p", "s"))
    model = build_model(RunConfig(activation="tanh", width=8, reversible_first=False), data,
                        key=jr.key(0))
    saved = tmp_path / "m.mpx"
    mx.save(saved, model, n=3)
    spec = mx.load(saved).spec()
    learned = [name for name in ("energy", "entropy", "poisson", "friction")
               if "activation" in spec[name]]
    assert learned == ["energy", "entropy", "poisson", "friction"], spec
    assert all(spec[name]["activation"] == "tanh" for name in learned), spec


def test_an_unknown_activation_is_refused_by_name():
    """A configuration from Python or a config.json (not argparse's choices) names the rule."""
    from metriplex.app.config import validate

    with pytest.raises(mx.MetriplexError, match=r"--activation must be one of gelu, silu, "
                       r"softplus, tanh .*; got 'relu'\. Example: --activation softplus\."):
        validate(RunConfig(activation="relu"), 3)


def test_a_given_l_that_moves_the_given_entropy_is_refused_before_any_work(tmp_path):
    # S = q with L canonical on (q, p): L grad S != 0 by construction, so the model could
    # never be GENERIC; the same for a constant L from a file. A variable named twice in S
    # would double it.
    with pytest.raises(mx.MetriplexError, match=r"canonical:1 with --entropy sum:0: the given L "
                       r"moves the given entropy .* variables ones that L leaves still \(here "
                       r"\[2\]\)"):
        validate(RunConfig(poisson="canonical:1", entropy="sum:0"), 3)
    np.save(tmp_path / "L.npy", CANONICAL)
    with pytest.raises(mx.MetriplexError, match="the given L moves the given entropy"):
        validate(RunConfig(poisson=f"file:{tmp_path / 'L.npy'}", entropy="sum:1,2"), 3)
    validate(RunConfig(poisson=f"file:{tmp_path / 'L.npy'}", entropy="sum:2"), 3)
    validate(RunConfig(poisson="canonical:1", entropy="sum:2"), 3)
    with pytest.raises(mx.MetriplexError, match=r"indices must be distinct; got \[2, 2\]"):
        validate(RunConfig(poisson="canonical:1", entropy="sum:2,2"), 3)
