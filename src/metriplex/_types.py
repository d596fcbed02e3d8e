"""Shape-annotated array aliases used in public signatures (jaxtyping)."""

from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray, Scalar

State = Float[Array, " n"]
States = Float[Array, "batch n"]
Matrix = Float[Array, "n n"]
Times = Float[Array, " T"]
Trajectory = Float[Array, "T n"]

__all__ = [
    "Array",
    "Bool",
    "Float",
    "Int",
    "Matrix",
    "PRNGKeyArray",
    "Scalar",
    "State",
    "States",
    "Times",
    "Trajectory",
]
