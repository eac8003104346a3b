"""Materials between the model (glTF's PBR metallic-roughness) and USD's ``UsdPreviewSurface``.

Each :class:`~usdhands.model.material.Material` is a ``Material`` prim with a
``UsdPreviewSurface`` shader; a texture is a ``UsdUVTexture`` reading the ``st`` primvar
(``st1``... for other sets) whose ``scale``/``bias`` carry glTF's factors:

============================  =====================================================================
glTF                          UsdPreviewSurface
============================  =====================================================================
baseColorFactor (+ texture)   ``diffuseColor`` (texture ``rgb``, scale = factor), ``opacity`` (``a``)
metallic/roughness factors    ``metallic`` / ``roughness`` (texture ``b`` / ``g``, scale (1, r, m, 1))
normalTexture (scale s)       ``normal`` (texture ``rgb``, scale (2s, 2s, 2, 1), bias (-s, -s, -1, 0))
occlusionTexture (strength)   ``occlusion`` (texture ``r``, scale strength, bias 1 - strength)
emissiveFactor (+ texture)    ``emissiveColor`` (texture ``rgb``, scale = factor)
alphaMode MASK / BLEND        ``opacityThreshold`` = alphaCutoff / 0, ``opacity`` from alpha
doubleSided                   the bound meshes' ``doubleSided``
============================  =====================================================================

Images the model holds as bytes (a ``.glb``'s) are written as files in a folder beside
the output (``<output stem>_textures/``); images that are files already are referenced
by a path relative to the output. Reading resolves texture paths through Ar, so images
inside a ``.usdz`` are read too.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np
from pxr import Ar, Gf, Sdf, Usd, UsdGeom, UsdShade

from usdhands.formats.registry import atomic_write_bytes
from usdhands.model.material import ALPHA_MODES, Image, Material, TextureRef

__all__ = ["write_materials", "bind_material", "MaterialReader", "texture_folder"]

#: customData of a Material prim: the glTF alpha mode and double-sidedness, for an exact round trip
ALPHA_MODE_KEY = "usdhands:alphaMode"
DOUBLE_SIDED_KEY = "usdhands:doubleSided"

_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
         ".ktx2": "image/ktx2"}
_EXT = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp", "image/ktx2": ".ktx2"}
_WRAPS = ("repeat", "mirror", "clamp")


def texture_folder(final_path: str | os.PathLike) -> Path:
    """Where the images of a USD output go: ``<folder>/<stem>_textures``."""
    final_path = Path(final_path)
    return final_path.parent / f"{final_path.stem}_textures"


def _image_file_name(image: Image, used: set[str]) -> str:
    stem, ext = os.path.splitext(os.path.basename(image.name) or "image")
    ext = ext.lower() if ext.lower() in _MIME else _EXT.get(image.mime_type, ".png")
    name, k = f"{stem}{ext}", 1
    while name in used:
        k += 1
        name = f"{stem}_{k}{ext}"
    used.add(name)
    return name


def _file_ids(paths: Sequence[str | os.PathLike]) -> set[tuple[int, int]] | None:
    """The ``(device, inode)`` of every path, or None when one cannot be looked up. Two files with
    different identities are different files, so their resolved paths differ: a texture's target that is
    none of the inputs' files needs no resolving of paths (two ``realpath`` walks, ~40 us a write)."""
    ids = set()
    for p in paths:
        try:
            st = os.stat(p)
        except (OSError, ValueError):
            return None
        ids.add((st.st_dev, st.st_ino))
    return ids


def _write_images(images: Sequence[Image], final_path: Path, inputs: Sequence[Path]) -> list[str]:
    """Asset paths (relative to the output's folder) of every image; bytes are written to files."""
    folder = texture_folder(final_path)
    out_dir = keep = None  # each made once, when first needed
    input_ids: set[tuple[int, int]] | None = None
    inputs_looked_up = False
    used: set[str] = set()
    paths = []
    for image in images:
        if image.path is not None and os.path.isfile(image.path) and "[" not in image.path:
            out_dir = final_path.parent.resolve() if out_dir is None else out_dir
            rel = os.path.relpath(os.path.abspath(image.path), out_dir)
            paths.append(Path(rel).as_posix() if rel.startswith("..") else f"./{Path(rel).as_posix()}")
            continue
        name = _image_file_name(image, used)
        target = folder / name
        if os.path.lexists(target):  # a path that is not there overwrites nothing
            if not inputs_looked_up:
                input_ids, inputs_looked_up = _file_ids(inputs), True
            here = _file_ids([target])
            if input_ids is None or here is None or here & input_ids:  # not shown to be another file than every input
                keep = {Path(p).resolve() for p in inputs} if keep is None else keep
                if target.resolve() in keep:
                    raise ValueError(f"texture {target} would overwrite an input")
        folder.mkdir(exist_ok=True)
        data = image.content() if image.data is None else image.data
        atomic_write_bytes(target, data)  # a fresh temporary name: threads of one process write side by side
        paths.append(f"./{folder.name}/{name}")
    return paths


def _value_input(shader: UsdShade.Shader, name: str, type_, value) -> None:
    shader.CreateInput(name, type_).Set(value)


class _TextureWriter:
    def __init__(self, stage: Usd.Stage, material_path: Sdf.Path, image_paths: list[str]):
        self.stage = stage
        self.path = material_path
        self.image_paths = image_paths
        self.readers: dict[int, UsdShade.Shader] = {}

    def reader(self, texcoord: int) -> UsdShade.Shader:
        if texcoord not in self.readers:
            name = "st" if texcoord == 0 else f"st{texcoord}"
            r = UsdShade.Shader.Define(self.stage, self.path.AppendChild(f"uvReader_{name}"))
            r.CreateIdAttr("UsdPrimvarReader_float2")
            r.CreateInput("varname", Sdf.ValueTypeNames.String).Set(name)
            r.CreateOutput("result", Sdf.ValueTypeNames.Float2)
            self.readers[texcoord] = r
        return self.readers[texcoord]

    def texture(self, slot: str, ref: TextureRef, scale, bias, color_space: str) -> UsdShade.Shader:
        tex = UsdShade.Shader.Define(self.stage, self.path.AppendChild(f"{slot}_texture"))
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(self.image_paths[ref.image]))
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(self.reader(ref.texcoord).ConnectableAPI(),
                                                                         "result")
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(ref.wrap_s)
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(ref.wrap_t)
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
        tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, scale)))
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, bias)))
        return tex


def _connect(shader: UsdShade.Shader, name: str, type_, tex: UsdShade.Shader, output: str, out_type) -> None:
    tex.CreateOutput(output, out_type)
    shader.CreateInput(name, type_).ConnectToSource(tex.ConnectableAPI(), output)


def write_materials(stage: Usd.Stage, scope: Sdf.Path, materials: Sequence[Material], images: Sequence[Image],
                    final_path: str | os.PathLike, inputs: Sequence[str | os.PathLike] = ()) -> list[Sdf.Path]:
    """Define one ``Material`` prim per material under ``scope``; returns their paths in order.

    Image bytes are written to :func:`texture_folder` of ``final_path`` (never onto a
    path in ``inputs``); image files are referenced relative to ``final_path``'s folder.
    """
    from usdhands.formats.usd_common import SOURCE_NAME_KEY, unique_name, valid_identifier

    if not materials:
        return []
    T = Sdf.ValueTypeNames
    image_paths = _write_images(images, Path(final_path), [Path(p) for p in inputs])
    UsdGeom.Scope.Define(stage, scope)
    used: set[str] = set()
    out = []
    for m in materials:
        name = unique_name(valid_identifier(m.name or "Material"), used)
        path = scope.AppendChild(name)
        mat = UsdShade.Material.Define(stage, path)
        if m.name and name != m.name:
            mat.GetPrim().SetCustomDataByKey(SOURCE_NAME_KEY, m.name)
        mat.GetPrim().SetCustomDataByKey(ALPHA_MODE_KEY, m.alpha_mode)
        if m.double_sided:
            mat.GetPrim().SetCustomDataByKey(DOUBLE_SIDED_KEY, True)
        shader = UsdShade.Shader.Define(stage, path.AppendChild("PreviewSurface"))
        shader.CreateIdAttr("UsdPreviewSurface")
        mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        shader.CreateOutput("surface", T.Token)
        textures = _TextureWriter(stage, path, image_paths)
        _value_input(shader, "useSpecularWorkflow", T.Int, 0)
        base = m.base_color
        blended = m.alpha_mode != "OPAQUE"
        if "baseColor" in m.textures:
            tex = textures.texture("baseColor", m.textures["baseColor"], base, (0, 0, 0, 0), "sRGB")
            _connect(shader, "diffuseColor", T.Color3f, tex, "rgb", T.Float3)
            if blended:
                _connect(shader, "opacity", T.Float, tex, "a", T.Float)
        else:
            _value_input(shader, "diffuseColor", T.Color3f, Gf.Vec3f(*map(float, base[:3])))
        if blended and "baseColor" not in m.textures:
            _value_input(shader, "opacity", T.Float, float(base[3]))
        if m.alpha_mode == "MASK":
            _value_input(shader, "opacityThreshold", T.Float, float(m.alpha_cutoff))
        if "metallicRoughness" in m.textures:
            tex = textures.texture("metallicRoughness", m.textures["metallicRoughness"],
                                   (1.0, m.roughness, m.metallic, 1.0), (0, 0, 0, 0), "raw")
            _connect(shader, "roughness", T.Float, tex, "g", T.Float)
            _connect(shader, "metallic", T.Float, tex, "b", T.Float)
        else:
            _value_input(shader, "metallic", T.Float, float(m.metallic))
            _value_input(shader, "roughness", T.Float, float(m.roughness))
        if "normal" in m.textures:
            s = float(m.textures["normal"].scale)
            tex = textures.texture("normal", m.textures["normal"], (2 * s, 2 * s, 2, 1), (-s, -s, -1, 0), "raw")
            _connect(shader, "normal", T.Normal3f, tex, "rgb", T.Float3)
        if "occlusion" in m.textures:
            s = float(m.textures["occlusion"].scale)
            tex = textures.texture("occlusion", m.textures["occlusion"], (s, s, s, 1), (1 - s, 1 - s, 1 - s, 0), "raw")
            _connect(shader, "occlusion", T.Float, tex, "r", T.Float)
        if "emissive" in m.textures:
            e = m.emissive
            tex = textures.texture("emissive", m.textures["emissive"], (*e, 1.0), (0, 0, 0, 0), "sRGB")
            _connect(shader, "emissiveColor", T.Color3f, tex, "rgb", T.Float3)
        elif any(m.emissive):
            _value_input(shader, "emissiveColor", T.Color3f, Gf.Vec3f(*map(float, m.emissive)))
        out.append(path)
    return out


def bind_material(prim: Usd.Prim, material_path: Sdf.Path) -> None:
    """Bind the material at ``material_path`` to ``prim`` (``material:binding``)."""
    api = UsdShade.MaterialBindingAPI.Apply(prim)
    api.Bind(UsdShade.Material(prim.GetStage().GetPrimAtPath(material_path)))


def _input_value(shader: UsdShade.Shader, name: str):
    """``(value, texture shader, output name)`` of a UsdPreviewSurface input."""
    inp = shader.GetInput(name)
    if not inp:
        return None, None, None
    if inp.HasConnectedSource():
        source, output, _ = inp.GetConnectedSource()
        tex = UsdShade.Shader(source.GetPrim())
        if tex and tex.GetIdAttr().Get() == "UsdUVTexture":
            return None, tex, str(output)
        return None, None, None
    return inp.Get(), None, None


def _tex_input(tex: UsdShade.Shader, name: str, default):
    inp = tex.GetInput(name)
    v = inp.Get() if inp else None
    return default if v is None else v


class MaterialReader:
    """Reads the ``UsdPreviewSurface`` materials bound to meshes, each material and image once."""

    def __init__(self, source_path: str | os.PathLike):
        self.source = str(source_path)
        self.materials: list[Material] = []
        self.images: list[Image] = []
        self._material_index: dict[str, int] = {}
        self._image_index: dict[str, int] = {}
        self.skipped: set[str] = set()
        self.missing_images: set[str] = set()

    def material_of(self, mesh_prim: Usd.Prim) -> int | None:
        """Index (into :attr:`materials`) of the material bound to ``mesh_prim``; None when it has
        none or it is not a ``UsdPreviewSurface`` network (named in :attr:`skipped`)."""
        material, _ = UsdShade.MaterialBindingAPI(mesh_prim).ComputeBoundMaterial()
        if not material:
            return None
        key = str(material.GetPath())
        if key in self._material_index:
            return self._material_index[key]
        m = self._read(material, mesh_prim)
        if m is None:
            self.skipped.add(key)
            return None
        self._material_index[key] = len(self.materials)
        self.materials.append(m)
        return self._material_index[key]

    def _image(self, tex: UsdShade.Shader) -> int | None:
        inp = tex.GetInput("file")
        asset = inp.Get() if inp else None
        if asset is None or not asset.path:
            return None
        resolved = asset.resolvedPath or ""
        key = resolved or asset.path
        if key in self._image_index:
            return self._image_index[key]
        name = os.path.basename(asset.path.rstrip("]").split("[")[-1]) or "image.png"
        mime = _MIME.get(os.path.splitext(name)[1].lower(), "image/png")
        if resolved and "[" not in resolved and os.path.isfile(resolved):
            image = Image(name=name, mime_type=mime, path=resolved)
        elif resolved:
            found = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
            if not found:
                self.missing_images.add(asset.path)
                return None
            image = Image(name=name, mime_type=mime, data=bytes(found.GetBuffer()))
        else:
            self.missing_images.add(asset.path)
            return None
        self._image_index[key] = len(self.images)
        self.images.append(image)
        return self._image_index[key]

    def _texture_ref(self, tex: UsdShade.Shader, scale: float = 1.0) -> TextureRef | None:
        image = self._image(tex)
        if image is None:
            return None
        texcoord = 0
        st = tex.GetInput("st")
        if st and st.HasConnectedSource():
            reader = UsdShade.Shader(st.GetConnectedSource()[0].GetPrim())
            varname = reader.GetInput("varname").Get() if reader and reader.GetInput("varname") else "st"
            varname = str(varname or "st")
            texcoord = int(varname[2:]) if varname.startswith("st") and varname[2:].isdigit() else 0
        wraps = [str(_tex_input(tex, w, "repeat")) for w in ("wrapS", "wrapT")]
        wraps = [w if w in _WRAPS else "clamp" for w in wraps]
        return TextureRef(image=image, texcoord=texcoord, wrap_s=wraps[0], wrap_t=wraps[1], scale=float(scale))

    def _read(self, material: UsdShade.Material, mesh_prim: Usd.Prim) -> Material | None:
        from usdhands.formats.usd_common import SOURCE_NAME_KEY

        shader = material.ComputeSurfaceSource()[0]
        if not shader or shader.GetIdAttr().Get() != "UsdPreviewSurface":
            return None
        prim = material.GetPrim()
        name = prim.GetCustomDataByKey(SOURCE_NAME_KEY) or prim.GetName()
        textures: dict[str, TextureRef] = {}
        base = [1.0, 1.0, 1.0, 1.0]
        value, tex, _ = _input_value(shader, "diffuseColor")
        if tex is not None:
            scale = np.asarray(_tex_input(tex, "scale", Gf.Vec4f(1, 1, 1, 1)), dtype=np.float64)
            base = scale.tolist()
            ref = self._texture_ref(tex)
            if ref is not None:
                textures["baseColor"] = ref
        elif value is not None:
            base[:3] = [float(x) for x in value]
        opacity, otex, _ = _input_value(shader, "opacity")
        if opacity is not None:
            base[3] = float(opacity)
        threshold, _, _ = _input_value(shader, "opacityThreshold")
        alpha_mode = "OPAQUE"
        if threshold is not None and float(threshold) > 0:
            alpha_mode = "MASK"
        elif otex is not None or (opacity is not None and float(opacity) < 1.0):
            alpha_mode = "BLEND"
        recorded = prim.GetCustomDataByKey(ALPHA_MODE_KEY)
        if recorded in ALPHA_MODES:
            alpha_mode = recorded
        metallic, roughness = 0.0, 0.5  # UsdPreviewSurface's defaults
        mv, mtex, _ = _input_value(shader, "metallic")
        rv, rtex, _ = _input_value(shader, "roughness")
        mr = mtex or rtex
        if mr is not None:
            scale = np.asarray(_tex_input(mr, "scale", Gf.Vec4f(1, 1, 1, 1)), dtype=np.float64)
            metallic, roughness = float(scale[2]), float(scale[1])
            ref = self._texture_ref(mr)
            if ref is not None:
                textures["metallicRoughness"] = ref
        if mv is not None:
            metallic = float(mv)
        if rv is not None:
            roughness = float(rv)
        _, ntex, _ = _input_value(shader, "normal")
        if ntex is not None:
            scale = np.asarray(_tex_input(ntex, "scale", Gf.Vec4f(2, 2, 2, 1)), dtype=np.float64)
            ref = self._texture_ref(ntex, scale=float(scale[0]) / 2.0)
            if ref is not None:
                textures["normal"] = ref
        _, otex2, _ = _input_value(shader, "occlusion")
        if otex2 is not None:
            scale = np.asarray(_tex_input(otex2, "scale", Gf.Vec4f(1, 1, 1, 1)), dtype=np.float64)
            ref = self._texture_ref(otex2, scale=float(scale[0]))
            if ref is not None:
                textures["occlusion"] = ref
        emissive = [0.0, 0.0, 0.0]
        ev, etex, _ = _input_value(shader, "emissiveColor")
        if etex is not None:
            emissive = np.asarray(_tex_input(etex, "scale", Gf.Vec4f(1, 1, 1, 1)), dtype=np.float64)[:3].tolist()
            ref = self._texture_ref(etex)
            if ref is not None:
                textures["emissive"] = ref
        elif ev is not None:
            emissive = [float(x) for x in ev]
        cutoff = float(threshold) if alpha_mode == "MASK" and threshold is not None else 0.5
        gprim = UsdGeom.Gprim(mesh_prim if mesh_prim.IsA(UsdGeom.Gprim) else mesh_prim.GetParent())
        double = bool(prim.GetCustomDataByKey(DOUBLE_SIDED_KEY)) or bool(gprim and gprim.GetDoubleSidedAttr().Get())
        return Material(name=str(name), base_color=tuple(float(x) for x in base), metallic=metallic,
                        roughness=roughness, emissive=tuple(float(x) for x in emissive), alpha_mode=alpha_mode,
                        alpha_cutoff=cutoff, double_sided=double, textures=textures)
