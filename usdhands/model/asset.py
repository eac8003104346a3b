"""What a reader returns: the skeletons, clips, meshes (with their blend shapes) and materials of one file."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from usdhands.model.clip import Clip
from usdhands.model.material import Image, Material
from usdhands.model.skeleton import Skeleton

__all__ = ["BlendShape", "SkinnedMesh", "Asset", "BlendShapeWeights", "RootNode"]


class RootNode(NamedTuple):
    """A transform node above a skeleton's root joints that the source held as a node of its own
    (a USD ``Xform`` usdhands wrote from glTF's ``RobotArmature`` or Mixamo's ``Armature``).

    Parameters
    ----------
    name : str
        The node's name in the source.
    local : (4, 4) float
        Its local transform (column vectors) as folded into the root joints' rest transforms.
    motion : dict str -> (F, 4, 4) float, optional
        Clip name -> its local transform at each of the clip's frames, for a node that moves
        (folded into the root joints frame by frame); None for a static node.
    rest : (4, 4) float, optional
        The node's own rest transform where it differs from ``local`` (an animated USD
        ``Xform``'s default value, ``local`` being its earliest time sample).
    """

    name: str
    local: np.ndarray
    motion: dict[str, np.ndarray] | None = None
    rest: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class BlendShape:
    """A morph target of a mesh: offsets added to its points, weighted by an animated weight.

    Parameters
    ----------
    name : str
        The weight channel it follows (UsdSkel's blend shape token): meshes whose shapes
        share a name follow the same weight (the primitives of one glTF mesh do).
    offsets : (V, 3) float
        Point offsets in the mesh's units and space.
    normal_offsets : (V, 3) float, optional
    default_weight : float
        Weight where no animation drives it (glTF ``mesh.weights``).
    source_name : str, optional
        The target's name in the file it came from where ``name`` differs from it.
    """

    name: str
    offsets: np.ndarray
    normal_offsets: np.ndarray | None = None
    default_weight: float = 0.0
    source_name: str | None = None


@dataclass(frozen=True, eq=False)
class BlendShapeWeights:
    """The blend shape weights of one clip: ``names`` (B,) and ``weights`` (T, B) at the clip's frames."""

    names: tuple[str, ...]
    weights: np.ndarray


@dataclass(frozen=True, eq=False)
class SkinnedMesh:
    """A triangle or polygon mesh bound to a skeleton.

    Parameters
    ----------
    name : str
    points : (V, 3) float
        Positions in the asset's units, in the mesh's bind space.
    face_vertex_counts : (F,) int
        Vertices per face (3 for triangles).
    face_vertex_indices : (sum(counts),) int
        Indices into ``points``.
    normals : (V, 3) float, optional
        Per-vertex normals.
    uvs : (V, 2) float, optional
        Per-vertex texture coordinates, v up (USD convention; glTF flips).
    joint_indices : (V, K) int, optional
        Skeleton joint indices of the influences, K per vertex (any K).
    joint_weights : (V, K) float, optional
        Weights of the influences, rows summing to 1.
    geom_bind_xform : (4, 4) float
        Mesh-to-skeleton-space transform at bind time (column vectors).
    skeleton_index : int
        Which skeleton of the asset it is bound to; -1 for a mesh on no skeleton (a prop, a
        static part), which has no influences and whose ``geom_bind_xform`` is its
        mesh-to-world transform.
    group : str, optional
        The source mesh this one is a part of (a glTF mesh with several primitives gives
        one SkinnedMesh per primitive, all with the glTF mesh's name here); writers put
        the parts of one group back into one mesh where the format can.
    node : str, optional
        Name of the node that carries the mesh in the source (glTF node name).
    material : int, optional
        Index into ``Asset.materials``.
    blend_shapes : tuple of BlendShape
    """

    name: str
    points: np.ndarray
    face_vertex_counts: np.ndarray
    face_vertex_indices: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    joint_indices: np.ndarray | None = None
    joint_weights: np.ndarray | None = None
    geom_bind_xform: np.ndarray = field(default_factory=lambda: np.eye(4))
    skeleton_index: int = 0
    group: str | None = None
    node: str | None = None
    material: int | None = None
    blend_shapes: tuple[BlendShape, ...] = ()

    def rigid_joint(self) -> int | None:
        """The one joint every point follows with full weight (a rigid mesh parented to a joint), else None."""
        if self.joint_indices is None or self.joint_weights is None:
            return None
        idx = np.asarray(self.joint_indices).reshape(len(self.points), -1)
        w = np.asarray(self.joint_weights, dtype=np.float64).reshape(idx.shape)
        if not idx.size:
            return None
        main = idx[np.arange(len(idx)), np.argmax(w, axis=1)]
        if np.all(main == main[0]) and np.allclose(w.max(axis=1), 1.0, atol=1e-6):
            return int(main[0])
        return None


@dataclass(frozen=True, eq=False)
class Asset:
    """The content of one file, as the model sees it.

    Parameters
    ----------
    path : str
        The file read.
    skeletons : tuple of Skeleton
    clips : tuple of Clip
        Every animation, each on one of ``skeletons`` (same object).
    meshes : tuple of SkinnedMesh
    provenance : dict str -> dict
        Clip name -> how its finger motion was made (a record of
        :func:`usdhands.model.provenance.provenance_record`), for the clips whose file
        recorded one; writers record it again.
    source_names : dict str -> str
        Clip name -> the animation's name where the file could not hold it as it was
        (a USD prim name is an identifier: ``dance-01`` is the prim ``dance_01``);
        writers use it to restore the name.
    left_out : tuple of str
        What the file holds that the reader did not read (``"3 material(s)"``, ...),
        so a conversion can say what it does not carry.
    non_skin_joints : dict int -> tuple of str
        Skeleton index -> names of its joints that no skin lists (glTF nodes above the
        skin's joints, kept for their transforms: Mixamo's ``Armature``); the USD writer
        puts the static ones above every skin joint on ``Xform`` prims instead.
    materials : tuple of Material
        Surface materials (glTF PBR metallic-roughness, USD ``UsdPreviewSurface``) the meshes use.
    images : tuple of Image
        Texture images the materials use.
    blend_shape_weights : dict str -> BlendShapeWeights
        Clip name -> the blend shape weights it animates, at its frames.
    interpolation : dict str -> str
        Clip name -> ``"STEP"`` or ``"CUBICSPLINE"`` where the source's samplers were such
        (absent: linear), so a writer that can hold it writes it again.
    key_times : dict str -> (K,) float
        Clip name -> the seconds the source keyed, where it keyed fewer times than the clip
        has frames (a hand-keyed glTF animation); each is one of the clip's frames, so a
        writer that can key at will (glTF) keys there only, and the key count is the source's.
    root_nodes : dict int -> tuple of RootNode
        Skeleton index -> the transform nodes above it (top first), already folded into its
        root joints, that the source held as nodes of their own (a USD file usdhands wrote
        from glTF: ``RobotArmature``); the glTF writer makes them plain nodes above the skin's
        joints again, animated where they move.
    """

    path: str
    skeletons: tuple[Skeleton, ...] = ()
    clips: tuple[Clip, ...] = ()
    meshes: tuple[SkinnedMesh, ...] = ()
    provenance: dict[str, dict] = field(default_factory=dict)
    source_names: dict[str, str] = field(default_factory=dict)
    left_out: tuple[str, ...] = ()
    non_skin_joints: dict[int, tuple[str, ...]] = field(default_factory=dict)
    materials: tuple[Material, ...] = ()
    images: tuple[Image, ...] = ()
    blend_shape_weights: dict[str, BlendShapeWeights] = field(default_factory=dict)
    interpolation: dict[str, str] = field(default_factory=dict)
    key_times: dict[str, np.ndarray] = field(default_factory=dict)
    root_nodes: dict[int, tuple] = field(default_factory=dict)

    def clip(self, animation: str | int | None = None) -> Clip:
        """One clip by name or index; the first when ``animation`` is None.

        Raises
        ------
        KeyError
            Listing the animations there are.
        """
        if not self.clips:
            raise KeyError(f"{self.path}: no animation in file")
        if animation is None:
            return self.clips[0]
        if isinstance(animation, int) or (isinstance(animation, str) and animation.isdigit()
                                          and not any(c.name == animation for c in self.clips)):
            i = int(animation)
            if not 0 <= i < len(self.clips):
                raise KeyError(f"{self.path}: animation index {i} out of range 0..{len(self.clips) - 1}")
            return self.clips[i]
        for c in self.clips:
            if c.name == animation or c.name.rsplit("/", 1)[-1] == animation:
                return c
        names = ", ".join(repr(c.name) for c in self.clips)
        raise KeyError(f"{self.path}: no animation named {animation!r}; there are {names}")
