"""Surface materials and texture images, as glTF's PBR metallic-roughness model holds them.

The same values map onto USD's ``UsdPreviewSurface`` (see docs/format-usd.md): base
colour and opacity, metallic and roughness, normal map, occlusion and emission, each a
factor and optionally a texture.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Image", "TextureRef", "Material", "TEXTURE_SLOTS", "ALPHA_MODES"]

#: The texture slots of a material: glTF's names.
TEXTURE_SLOTS = ("baseColor", "metallicRoughness", "normal", "occlusion", "emissive")
#: glTF alpha modes.
ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")


@dataclass(frozen=True, eq=False)
class Image:
    """A texture image: its bytes, or a file on disk.

    Parameters
    ----------
    name : str
        A file name for it (``"albedo.png"``), unique in the asset.
    mime_type : str
        ``"image/png"``, ``"image/jpeg"``, ...
    data : bytes, optional
        The file's content (embedded images); None when ``path`` is given.
    path : str, optional
        Absolute path of the image file (external images, USD asset paths).
    """

    name: str
    mime_type: str
    data: bytes | None = None
    path: str | None = None

    def content(self) -> bytes:
        """The image file's bytes."""
        if self.data is not None:
            return self.data
        if self.path is None:
            raise ValueError(f"image {self.name!r} has neither data nor a path")
        with open(self.path, "rb") as f:
            return f.read()


@dataclass(frozen=True)
class TextureRef:
    """A material's use of an image.

    Parameters
    ----------
    image : int
        Index into ``Asset.images``.
    texcoord : int
        Texture coordinate set (glTF ``TEXCOORD_n``; USD ``st``, ``st1``...).
    wrap_s, wrap_t : str
        ``"repeat"``, ``"mirror"`` or ``"clamp"``.
    scale : float
        Normal map scale or occlusion strength (1 for the other slots).
    """

    image: int
    texcoord: int = 0
    wrap_s: str = "repeat"
    wrap_t: str = "repeat"
    scale: float = 1.0


@dataclass(frozen=True, eq=False)
class Material:
    """A PBR metallic-roughness material (glTF 2.0 core).

    Colours are linear RGB(A); textures multiply their factors as in glTF.
    """

    name: str
    base_color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    metallic: float = 1.0
    roughness: float = 1.0
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    alpha_mode: str = "OPAQUE"
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    textures: dict[str, TextureRef] = field(default_factory=dict)
