"""usdhands: finger animation for skeletal characters in USD, glTF and BVH files."""

__version__ = "0.1.0"

from usdhands.errors import UsdHandsError  # noqa: E402

__all__ = ["__version__", "UsdHandsError"]
