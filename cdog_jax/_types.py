"""Shape aliases shared by all modules (dimension letters: B scenes, M views, P slots per
view, N = M*P nodes, G groups)."""

from jaxtyping import Array, Bool, Float, Int

Scalar = Float[Array, ""]
Mat3 = Float[Array, "M 3 3"]
Vec3 = Float[Array, "M 3"]
Pixels = Float[Array, "M P 2"]
Mask = Bool[Array, "M P"]
Labels = Int[Array, "M P"]

__all__ = ["Array", "Bool", "Float", "Int", "Scalar", "Mat3", "Vec3", "Pixels", "Mask", "Labels"]
