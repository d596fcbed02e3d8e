r"""metriplex: learn thermodynamically consistent (GENERIC) dynamics from trajectories.

.. math:: \dot x = L(x)\nabla E(x) + M(x)\nabla S(x),\quad L\nabla S = 0,\ M\nabla E = 0.

An energy E and an entropy S (scalar potentials), a Poisson bivector L (antisymmetric) and a
friction matrix M (symmetric positive semi-definite), each learned or given, make a
:class:`GenericModel`. Training minimises the Crank-Nicolson residual of observed pairs
``(x_n, x_{n+1}, dt_n)`` plus penalties for the degeneracy conditions and the Jacobi identity.

The data flow, one function each:

- :func:`read` a data file (``.npz``, ``.csv``, ``.h5``/``.hdf5`` or ``.mat``) into
  :class:`Trajectories` (or build them: ``Trajectories.from_list([(t, x), ...])``);
- build the blocks: potentials (:class:`MLPPotential`, :class:`SumOf`, :class:`ZeroPotential`),
  bivectors (:class:`SkewMLPPoisson`, :class:`CanonicalPoisson`, :class:`ConstantPoisson`, ...),
  frictions (:class:`CholeskyFriction`, :class:`ProjectedCholeskyFriction`, ...); put every
  network in the data's units with :class:`Units`;
- :func:`fit` the model (a :class:`Loss` of :class:`SchemeResidual` and penalties; it keeps the
  model whose held-out rollouts are best and returns it with its :class:`History`);
- :func:`simulate` or :func:`solve` it from initial states (schemes :class:`CrankNicolson`,
  :class:`ImplicitMidpoint`, :class:`DiscreteGradient`, :class:`RK4`, :class:`Hermite`);
- :func:`evaluate` it on data (rollout errors, energy drift, entropy production, structure
  residuals), and :func:`save` / :func:`load` it (JSON header + Equinox leaves).

Ground-truth systems are models too (:mod:`metriplex.systems`). The command line,
``metriplex train DATA --out RUN`` with the structure you know (``--poisson canonical:K``,
``--entropy sum:I,J``), builds all of this with defaults chosen across many systems; see
``metriplex --help`` and the README.
"""

from ._version import __version__ as __version__

from . import diagnostics as diagnostics
from . import structure as structure
from . import systems as systems
from ._errors import MetriplexError as MetriplexError
from ._errors import RolloutFailure as RolloutFailure
from ._errors import TrainingDiverged as TrainingDiverged
from ._model import AbstractModel as AbstractModel
from ._model import GenericModel as GenericModel
from ._model import Terms as Terms
from .data import Pairs as Pairs
from .data import Trajectories as Trajectories
from ._units import Units as Units
from .diagnostics import evaluate as evaluate
from .integrate import RK4 as RK4
from .integrate import AbstractRootFinder as AbstractRootFinder
from .integrate import AbstractScheme as AbstractScheme
from .integrate import CrankNicolson as CrankNicolson
from .integrate import DiscreteGradient as DiscreteGradient
from .integrate import FixedPoint as FixedPoint
from .integrate import FixedPointThenNewton as FixedPointThenNewton
from .integrate import Hermite as Hermite
from .integrate import ImplicitMidpoint as ImplicitMidpoint
from .integrate import Newton as Newton
from .integrate import Rollout as Rollout
from .integrate import simulate as simulate
from .integrate import solve as solve
from .io import read_mat_operators as read_mat_operators
from .io import load as load
from .io import read as read
from .io import save as save
from .io import write as write
from .losses import AbstractJacobiEstimator as AbstractJacobiEstimator
from .losses import CrankNicolsonResidual as CrankNicolsonResidual
from .losses import DegeneracyPenalty as DegeneracyPenalty
from .losses import DiscreteGradientResidual as DiscreteGradientResidual
from .losses import ExactJacobi as ExactJacobi
from .losses import FrictionDegeneracy as FrictionDegeneracy
from .losses import NegativeTemperature as NegativeTemperature
from .losses import JacobiPenalty as JacobiPenalty
from .losses import Loss as Loss
from .losses import MidpointResidual as MidpointResidual
from .losses import PoissonDegeneracy as PoissonDegeneracy
from ._rollout_loss import RolloutWindow as RolloutWindow
from .losses import SchemeResidual as SchemeResidual
from .losses import StochasticJacobi as StochasticJacobi
from .structure import CanonicalPoisson as CanonicalPoisson
from .structure import CasimirPoisson3 as CasimirPoisson3
from .structure import EntropyCasimirPoisson3 as EntropyCasimirPoisson3
from .structure import CholeskyFriction as CholeskyFriction
from .structure import ConstantFriction as ConstantFriction
from .structure import ExchangeFriction as ExchangeFriction
from .structure import ConstantPoisson as ConstantPoisson
from .structure import Confinement as Confinement
from .structure import LiePoisson as LiePoisson
from .structure import ProjectedLiePoisson as ProjectedLiePoisson
from .structure import Lattice as Lattice
from .structure import LocalFriction as LocalFriction
from .structure import LocalPotential as LocalPotential
from .structure import MaskedFriction as MaskedFriction
from .structure import MaskedPoisson as MaskedPoisson
from .structure import FeatureMap as FeatureMap
from .structure import Known as Known
from .structure import KnownFriction as KnownFriction
from .structure import KnownPoisson as KnownPoisson
from .structure import MLPPotential as MLPPotential
from .structure import ProjectedCholeskyFriction as ProjectedCholeskyFriction
from .structure import PlanarPoisson as PlanarPoisson
from .structure import ProjectedSkewMLPPoisson as ProjectedSkewMLPPoisson
from .structure import Scaling as Scaling
from .structure import SkewMLPPoisson as SkewMLPPoisson
from .structure import SumOf as SumOf
from .structure import ZeroFriction as ZeroFriction
from .structure import ZeroPoisson as ZeroPoisson
from .structure import ZeroPotential as ZeroPotential
from .train import Average as Average
from .train import Checkpoint as Checkpoint
from .train import History as History
from .train import LBFGSFinish as LBFGSFinish
from .train import Plateau as Plateau
from .train import RolloutCheck as RolloutCheck
from .train import fit as fit
