"""File formats: one module per format, found by extension (see :mod:`.registry`)."""

from usdhands.formats.io import read_asset, read_clip, write_asset, write_clip

__all__ = ["read_asset", "read_clip", "write_asset", "write_clip"]
