"""GENERIC building blocks: potentials (E, S), Poisson bivectors (L), friction matrices (M)."""

from ._abstract import AbstractFriction as AbstractFriction
from ._abstract import AbstractPoisson as AbstractPoisson
from ._abstract import AbstractPotential as AbstractPotential
from .confinement import Confinement as Confinement
from .constant import ConstantFriction as ConstantFriction
from .constant import ConstantPoisson as ConstantPoisson
from .friction import CholeskyFriction as CholeskyFriction
from .friction import KnownFriction as KnownFriction
from .friction import ProjectedCholeskyFriction as ProjectedCholeskyFriction
from .friction import ZeroFriction as ZeroFriction
from .poisson import CanonicalPoisson as CanonicalPoisson
from .casimir import CasimirPoisson3 as CasimirPoisson3
from .casimir import EntropyCasimirPoisson3 as EntropyCasimirPoisson3
from .lie_poisson import LiePoisson as LiePoisson
from .masked import MaskedFriction as MaskedFriction
from .masked import MaskedPoisson as MaskedPoisson
from .poisson import KnownPoisson as KnownPoisson
from .poisson import ProjectedSkewMLPPoisson as ProjectedSkewMLPPoisson
from .poisson import SkewMLPPoisson as SkewMLPPoisson
from .poisson import ZeroPoisson as ZeroPoisson
from .potential import FeatureMap as FeatureMap
from .potential import Known as Known
from .potential import MLPPotential as MLPPotential
from .potential import SumOf as SumOf
from .potential import ZeroPotential as ZeroPotential
from .scaling import Scaling as Scaling
