"""glTF materials, textures and images to and from the model's :class:`~usdhands.model.material.Material`.

Reading keeps the core PBR metallic-roughness values (factors, the five textures with
their texture coordinate set, wrap modes, normal scale and occlusion strength, alpha
mode and cutoff, double-sidedness); images come as bytes (buffer views, data URIs) or
as the path of an external file. Writing puts every image in a buffer view of the
output (a ``.glb``'s binary chunk, a ``.gltf``'s embedded buffer).
"""

from __future__ import annotations

import base64
import os
import urllib.parse

import pygltflib

from usdhands.errors import AssetReadError
from usdhands.formats.gltf_container import BinaryAppender, GltfFile, contained_file
from usdhands.model.material import ALPHA_MODES, Image, Material, TextureRef

__all__ = ["read_materials", "write_materials"]

_WRAP = {10497: "repeat", 33648: "mirror", 33071: "clamp"}
_WRAP_CODE = {v: k for k, v in _WRAP.items()}
_EXT = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp", "image/ktx2": ".ktx2"}
_MIME = {v: k for k, v in _EXT.items()} | {".jpeg": "image/jpeg"}


def _image(doc: GltfFile, i: int) -> Image:
    im = doc.gltf.images[i]
    where = f"images[{i}]"
    mime = im.mimeType or ""
    base = im.name or f"image{i}"
    if im.bufferView is not None:
        view = doc.gltf.bufferViews[im.bufferView]
        data = doc.buffers[view.buffer][(view.byteOffset or 0):(view.byteOffset or 0) + view.byteLength]
        if len(data) != view.byteLength:
            raise doc.error(f"bufferView {im.bufferView} runs past its buffer", where)
        return Image(name=_file_name(base, mime or "image/png"), mime_type=mime or "image/png", data=bytes(data))
    uri = im.uri or ""
    if uri.startswith("data:"):
        head, _, payload = uri.partition(",")
        mime = mime or head[5:].split(";")[0] or "image/png"
        try:
            data = base64.b64decode(payload) if ";base64" in head else urllib.parse.unquote_to_bytes(payload)
        except ValueError:
            raise doc.error("image data URI is not valid base64", where) from None
        return Image(name=_file_name(base, mime), mime_type=mime, data=data)
    file = contained_file(doc.path, uri, "image", where)
    if not file.is_file():
        raise doc.error(f"image file {uri!r} cannot be read (not a regular file, or missing)", where)
    mime = mime or _MIME.get(file.suffix.lower(), "image/png")
    return Image(name=im.name and _file_name(im.name, mime) or file.name, mime_type=mime, path=str(file))


def _file_name(name: str, mime: str) -> str:
    stem, ext = os.path.splitext(os.path.basename(name))
    return f"{stem or 'image'}{ext if ext.lower() in _MIME else _EXT.get(mime, '.png')}"


def read_materials(doc: GltfFile) -> tuple[tuple[Material, ...], tuple[Image, ...], tuple[str, ...]]:
    """Every material of the file, the images they use, and what could not be kept (one phrase each)."""
    g = doc.gltf
    images: list[Image] = []
    image_of: dict[int, int] = {}
    notes: list[str] = []

    def ref(info, slot: str, scale_name: str | None = None) -> TextureRef | None:
        if info is None or info.index is None or not 0 <= info.index < len(g.textures):
            return None
        tex = g.textures[info.index]
        src = tex.source
        if src is None or not 0 <= src < len(g.images):
            notes.append(f"a {slot} texture without a core image source")
            return None
        if src not in image_of:
            try:
                image = _image(doc, src)
            except (AssetReadError, IndexError, TypeError) as e:  # a missing file: the rest of the file still reads
                notes.append(f"image {src} ({e.message if isinstance(e, AssetReadError) else 'malformed'})")
                return None
            image_of[src] = len(images)
            images.append(image)
        wrap_s = wrap_t = "repeat"
        if tex.sampler is not None and 0 <= tex.sampler < len(g.samplers):
            smp = g.samplers[tex.sampler]
            wrap_s = _WRAP.get(smp.wrapS or 10497, "repeat")
            wrap_t = _WRAP.get(smp.wrapT or 10497, "repeat")
        if info.extensions and "KHR_texture_transform" in info.extensions:
            notes.append(f"KHR_texture_transform on a {slot} texture")
        scale = getattr(info, scale_name) if scale_name else None
        return TextureRef(image=image_of[src], texcoord=int(info.texCoord or 0), wrap_s=wrap_s, wrap_t=wrap_t,
                          scale=1.0 if scale is None else float(scale))

    out = []
    for i, m in enumerate(g.materials):
        pbr = m.pbrMetallicRoughness or pygltflib.PbrMetallicRoughness()
        textures = {}
        for slot, info, scale_name in (("baseColor", pbr.baseColorTexture, None),
                                       ("metallicRoughness", pbr.metallicRoughnessTexture, None),
                                       ("normal", m.normalTexture, "scale"),
                                       ("occlusion", m.occlusionTexture, "strength"),
                                       ("emissive", m.emissiveTexture, None)):
            r = ref(info, slot, scale_name)
            if r is not None:
                textures[slot] = r
        for ext in (m.extensions or {}):
            notes.append(f"material extension {ext}")
        base = pbr.baseColorFactor if pbr.baseColorFactor is not None else [1.0, 1.0, 1.0, 1.0]
        out.append(Material(
            name=m.name or f"material{i}", base_color=tuple(float(x) for x in base),
            metallic=float(1.0 if pbr.metallicFactor is None else pbr.metallicFactor),
            roughness=float(1.0 if pbr.roughnessFactor is None else pbr.roughnessFactor),
            emissive=tuple(float(x) for x in (m.emissiveFactor or [0.0, 0.0, 0.0])),
            alpha_mode=m.alphaMode if m.alphaMode in ALPHA_MODES else "OPAQUE",
            alpha_cutoff=float(0.5 if m.alphaCutoff is None else m.alphaCutoff),
            double_sided=bool(m.doubleSided), textures=textures))
    return tuple(out), tuple(images), tuple(dict.fromkeys(notes))


def write_materials(gltf: pygltflib.GLTF2, app: BinaryAppender, materials, images) -> list[int]:
    """Append ``materials`` (and the images they use, in buffer views); returns their indices."""
    if not materials:
        return []
    image_index: dict[int, int] = {}
    sampler_index: dict[tuple[str, str], int] = {}

    def texture(r: TextureRef) -> int:
        if r.image not in image_index:
            im = images[r.image]
            view = app.add_view(im.content())
            gltf.images.append(pygltflib.Image(name=os.path.splitext(im.name)[0], bufferView=view,
                                               mimeType=im.mime_type))
            image_index[r.image] = len(gltf.images) - 1
        key = (r.wrap_s, r.wrap_t)
        if key not in sampler_index:
            gltf.samplers.append(pygltflib.Sampler(wrapS=_WRAP_CODE.get(r.wrap_s, 10497),
                                                   wrapT=_WRAP_CODE.get(r.wrap_t, 10497)))
            sampler_index[key] = len(gltf.samplers) - 1
        gltf.textures.append(pygltflib.Texture(source=image_index[r.image], sampler=sampler_index[key]))
        return len(gltf.textures) - 1

    out = []
    for m in materials:
        t = m.textures
        pbr = pygltflib.PbrMetallicRoughness(baseColorFactor=[float(x) for x in m.base_color],
                                             metallicFactor=float(m.metallic), roughnessFactor=float(m.roughness))
        if "baseColor" in t:
            pbr.baseColorTexture = pygltflib.TextureInfo(index=texture(t["baseColor"]), texCoord=t["baseColor"].texcoord)
        if "metallicRoughness" in t:
            r = t["metallicRoughness"]
            pbr.metallicRoughnessTexture = pygltflib.TextureInfo(index=texture(r), texCoord=r.texcoord)
        mat = pygltflib.Material(name=m.name, pbrMetallicRoughness=pbr, alphaMode=m.alpha_mode,
                                 alphaCutoff=float(m.alpha_cutoff) if m.alpha_mode == "MASK" else None,
                                 doubleSided=bool(m.double_sided), emissiveFactor=[float(x) for x in m.emissive])
        if "normal" in t:
            r = t["normal"]
            mat.normalTexture = pygltflib.NormalMaterialTexture(index=texture(r), texCoord=r.texcoord, scale=r.scale)
        if "occlusion" in t:
            r = t["occlusion"]
            mat.occlusionTexture = pygltflib.OcclusionTextureInfo(index=texture(r), texCoord=r.texcoord,
                                                                  strength=r.scale)
        if "emissive" in t:
            r = t["emissive"]
            mat.emissiveTexture = pygltflib.TextureInfo(index=texture(r), texCoord=r.texcoord)
        gltf.materials.append(mat)
        out.append(len(gltf.materials) - 1)
    return out
