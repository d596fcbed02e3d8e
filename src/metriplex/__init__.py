"""metriplex: learn thermodynamically consistent (GENERIC) dynamics from trajectories.

.. math:: \\dot x = L(x)\\nabla E(x) + M(x)\\nabla S(x),\\quad L\\nabla S = 0,\\ M\\nabla E = 0.
"""

from ._version import __version__ as __version__

from . import diagnostics as diagnostics
from . import structure as structure
from . import systems as systems
from ._errors import MetriplexError as MetriplexError
from ._errors import RolloutFailure as RolloutFailure
from ._errors import TrainingDiverged as TrainingDiverged
from ._model import GenericModel as GenericModel
from ._model import Terms as Terms
from .data import Pairs as Pairs
from .data import Trajectories as Trajectories
from ._units import Units as Units
from .diagnostics import evaluate as evaluate
from .integrate import RK4 as RK4
from .integrate import AbstractScheme as AbstractScheme
from .integrate import CrankNicolson as CrankNicolson
from .integrate import DiscreteGradient as DiscreteGradient
from .integrate import ImplicitMidpoint as ImplicitMidpoint
from .integrate import Rollout as Rollout
from .integrate import simulate as simulate
from .integrate import solve as solve
from .io import read_mat_operators as read_mat_operators
from .io import load as load
from .io import read as read
from .io import save as save
from .io import write as write
from .losses import CrankNicolsonResidual as CrankNicolsonResidual
from .losses import DegeneracyPenalty as DegeneracyPenalty
from .losses import DiscreteGradientResidual as DiscreteGradientResidual
from .losses import FrictionDegeneracy as FrictionDegeneracy
from .losses import JacobiPenalty as JacobiPenalty
from .losses import Loss as Loss
from .losses import MidpointResidual as MidpointResidual
from .losses import PoissonDegeneracy as PoissonDegeneracy
from .losses import SchemeResidual as SchemeResidual
from .structure import CanonicalPoisson as CanonicalPoisson
from .structure import CasimirPoisson3 as CasimirPoisson3
from .structure import EntropyCasimirPoisson3 as EntropyCasimirPoisson3
from .structure import CholeskyFriction as CholeskyFriction
from .structure import ConstantFriction as ConstantFriction
from .structure import ConstantPoisson as ConstantPoisson
from .structure import LiePoisson as LiePoisson
from .structure import FeatureMap as FeatureMap
from .structure import Known as Known
from .structure import KnownFriction as KnownFriction
from .structure import KnownPoisson as KnownPoisson
from .structure import MLPPotential as MLPPotential
from .structure import ProjectedCholeskyFriction as ProjectedCholeskyFriction
from .structure import ProjectedSkewMLPPoisson as ProjectedSkewMLPPoisson
from .structure import Scaling as Scaling
from .structure import SkewMLPPoisson as SkewMLPPoisson
from .structure import SumOf as SumOf
from .structure import ZeroFriction as ZeroFriction
from .structure import ZeroPoisson as ZeroPoisson
from .structure import ZeroPotential as ZeroPotential
from .train import History as History
from .train import Plateau as Plateau
from .train import RolloutCheck as RolloutCheck
from .train import fit as fit
