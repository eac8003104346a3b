"""Built interaction cases with known geometry: the sample humanoid's left hand closing on a
cylinder held under its palm, and the sample cup in the path of a curling hand."""

from __future__ import annotations

import numpy as np
import trimesh

from usdhands.algorithms.interaction.colliders import Colliders, mesh_collider
from usdhands.algorithms.interaction.finger_geometry import finger_chains
from usdhands.model.clip import Clip
from usdhands.model.finger_dofs import FingerCurves, apply_finger_curves, finger_curves
from usdhands.model.prop import PropMesh
from usdhands.samples.humanoid import humanoid_handmap, humanoid_skeleton

CURL_DEG = (55.0, 70.0, 45.0)  # flexion of the three joints of each long finger at full curl


def closing_hand_clip(frames: int = 60, fps: float = 30.0, noise_deg: float = 0.0, seed: int = 0) -> Clip:
    """The humanoid in its rest pose while the left hand's four long fingers curl from straight
    to :data:`CURL_DEG` and open again (a smooth bump), the thumb still; cm, Y up.

    The hand points along +X with the palm facing -Y (T-pose); ``noise_deg`` adds white
    noise to the curled fingers' flexion (capture jitter).
    """
    sk = humanoid_skeleton()
    hand = humanoid_handmap(sk)["left"]
    t = np.arange(frames) / max(frames - 1, 1)
    s = np.sin(np.pi * t) ** 2  # 0 -> 1 -> 0
    rng = np.random.default_rng(seed)
    rot = np.tile(sk.rest_rotations, (frames, 1, 1))
    clip = Clip(sk, fps, rot, name="closing_hand")
    for chain in finger_chains(sk, hand):
        if chain.finger == "thumb":
            continue
        n = len(chain.joints)
        e = np.zeros((frames, n, 3))
        for k in range(n):
            e[:, k, chain.axes[k, 0]] = chain.flexion_sign[k] * (CURL_DEG[k] * s + noise_deg * rng.normal(size=frames))
        names = tuple(sk.joint_names[j] for j in chain.joints)
        clip = apply_finger_curves(clip, FingerCurves(chain.joints, names, e.reshape(frames, -1)))
    return clip


def cylinder_under_palm(radius_cm: float = 2.0) -> PropMesh:
    """A closed cylinder across the left palm (along Z), under the fingers' middle phalanges; cm."""
    cyl = trimesh.creation.cylinder(radius=radius_cm, height=7.5, sections=48)
    # the left wrist is at (70, 144, -1), fingers along +X, palm facing -Y; the straight
    # fingers (radius 9 mm) clear the top by 3 mm, the thumb passes beside the end
    cyl.apply_translation([70.0 + 12.0, 144.0 - 1.2 - radius_cm, -1.0])
    return PropMesh("cylinder", cyl.vertices, cyl.faces)


def colliders_for(clip: Clip, *props: PropMesh) -> Colliders:
    """Static colliders for ``props`` at every frame of ``clip``."""
    return Colliders([mesh_collider(p, clip.times) for p in props])


def exact_capsule_gaps_mm(clip: Clip, props: list[PropMesh], posers, frames=None,
                          samples_per_cm: int = 40) -> np.ndarray:
    """Gap between each chain's capsules and the props per frame, ``(chains, T)`` mm (negative:
    penetration depth), by trimesh's exact signed distance at axis samples every 0.25 mm.

    Independent of the fast path (libigl, the clearance search); NaN for frames not asked;
    only axis points within 15 mm of a prop's bounding box are measured, so gaps above
    about 5 mm come back as inf.
    """
    meshes = [trimesh.Trimesh(np.asarray(p.vertices), np.asarray(p.faces), process=False) for p in props]
    T = clip.num_frames
    frames = np.arange(T) if frames is None else np.asarray(frames)
    mm = 0.001 / clip.skeleton.meters_per_unit
    gaps = np.full((len(posers), T), np.nan)
    for c, poser in enumerate(posers):
        n = len(poser.chain.joints)
        angles = finger_curves(clip, poser.chain.joints).values.reshape(T, n, 3)
        a, b = poser.capsules(frames, angles[frames])
        length = np.linalg.norm(b - a, axis=-1).max()
        m = int(np.ceil(length * samples_per_cm / (10 * mm))) + 1
        t = np.linspace(0.0, 1.0, m)
        pts = a[:, :, None] + t[None, None, :, None] * (b - a)[:, :, None]
        flat = pts.reshape(-1, 3)
        sd = np.full(len(flat), np.inf)
        for mesh in meshes:
            lo, hi = mesh.bounds
            near = np.all((flat > lo - 15 * mm) & (flat < hi + 15 * mm), axis=1)
            if near.any():
                sd[near] = np.minimum(sd[near], -trimesh.proximity.signed_distance(mesh, flat[near]))
        gap = (sd.reshape(pts.shape[:3]) - poser.chain.radii[None, :, None]).min(axis=(1, 2)) / mm
        gaps[c, frames] = gap
    return gaps


def exact_capsule_depth_mm(clip: Clip, props: list[PropMesh], posers, frames=None) -> np.ndarray:
    """Deepest penetration of any chain per frame, ``(T,)`` mm (0 where clear), from :func:`exact_capsule_gaps_mm`."""
    gaps = exact_capsule_gaps_mm(clip, props, posers, frames)
    return np.nan_to_num(np.maximum(-gaps, 0.0)).max(axis=0)


def curled_index_clip(frames: int = 12, fps: float = 30.0) -> Clip:
    """The humanoid at rest with only the left index curled to :data:`CURL_DEG` (still); cm."""
    sk = humanoid_skeleton()
    hand = humanoid_handmap(sk)["left"]
    clip = Clip(sk, fps, np.tile(sk.rest_rotations, (frames, 1, 1)), name="curled_index")
    chain = next(c for c in finger_chains(sk, hand) if c.finger == "index")
    e = np.zeros((frames, 3, 3))
    for k in range(3):
        e[:, k, chain.axes[k, 0]] = chain.flexion_sign[k] * CURL_DEG[k]
    names = tuple(sk.joint_names[j] for j in chain.joints)
    return apply_finger_curves(clip, FingerCurves(chain.joints, names, e.reshape(frames, -1)))


def cup_against_tip(tip: np.ndarray, depth_cm: float, tip_radius_cm: float) -> PropMesh:
    """The sample cup placed so a sphere of ``tip_radius_cm`` at ``tip`` enters its outer wall by
    ``depth_cm``, at the centre of a wall face (the lathe's faces are flat: 32 sections), the cup
    on the -X side of the tip with its handle turned away (-X) and its base 7.5 cm below the tip."""
    from usdhands.samples.props import CUP_RADIUS_CM, cup_mesh

    theta = np.pi / 32  # a face centre of the 32-section lathe (x = r cos a, z = -r sin a)
    inner = CUP_RADIUS_CM * np.cos(np.pi / 32)  # distance from the axis to a face's plane
    rho = inner + tip_radius_cm - depth_cm
    centre = np.array([tip[0] - rho * np.cos(theta), tip[1] - 7.5, tip[2] + rho * np.sin(theta)])
    cup = cup_mesh()
    turned = cup.vertices * [-1.0, 1.0, -1.0]  # half a turn about +Y: the handle toward -X
    return PropMesh("cup", turned + centre, cup.faces)


def grasping_clip(seconds: float = 60.0, fps: float = 30.0, noise_deg: float = 0.5, seed: int = 0) -> Clip:
    """Both hands of the humanoid curl and open every 3 s (the four long fingers; fully curled as
    the left hand passes the middle of its sweep) while the left arm sweeps forward and back about
    the vertical every 6 s; cm, Y up.

    The left hand's path at the middle of a sweep is :func:`grasping_mug_position`.
    """
    from usdhands.model.rotations import quat_multiply

    sk = humanoid_skeleton()
    hm = humanoid_handmap(sk)
    T = int(round(seconds * fps)) + 1
    t = np.arange(T) / fps
    rng = np.random.default_rng(seed)
    rot = np.tile(sk.rest_rotations, (T, 1, 1))
    arm = sk.index("LeftArm")
    yaw = np.radians(25.0) * np.sin(2 * np.pi * t / 6.0)
    q = np.stack([np.zeros(T), np.sin(yaw / 2), np.zeros(T), np.cos(yaw / 2)], axis=1)
    # the rotation about world +Y expressed in the arm's parent frame is applied before its rest
    parent_world = sk.rest_world_xforms()[sk.parents[arm], :3, :3]
    from usdhands.model.rotations import matrix_to_quat

    pq = matrix_to_quat(parent_world)
    pq_inv = pq * [-1, -1, -1, 1]
    local = quat_multiply(quat_multiply(pq_inv[None], q), quat_multiply(pq[None], rot[:, arm]))
    rot[:, arm] = local
    clip = Clip(sk, fps, rot, name="grasping")
    s = 0.5 + 0.5 * np.cos(2 * np.pi * t / 3.0)
    for side in ("left", "right"):
        for chain in finger_chains(sk, hm[side]):
            n = len(chain.joints)
            amount = 0.0 if chain.finger == "thumb" else 1.0
            e = np.zeros((T, n, 3))
            for k in range(n):
                e[:, k, chain.axes[k, 0]] = chain.flexion_sign[k] * (amount * CURL_DEG[k] * s
                                                                     + noise_deg * rng.normal(size=T))
            names = tuple(sk.joint_names[j] for j in chain.joints)
            clip = apply_finger_curves(clip, FingerCurves(chain.joints, names, e.reshape(T, -1)))
    return clip


def grasping_mug_position() -> np.ndarray:
    """Where to put the mug's origin (cm) so it sits under the left palm's little-finger side at the
    middle of a sweep, its rim 4.2 cm below the palm, clear of the open hand and of the thumb (which
    hangs 4 cm below); the curled middle, ring and little fingers reach over its rim."""
    return np.array([81.0, 144.0 - 4.2 - 7.2, -4.5])


def write_closing_scene(folder):
    """``folder/closing.usda`` (:func:`closing_hand_clip`, 24 frames, 1 degree of jitter: fingers 15+ mm
    into the cylinder) and ``folder/cyl.obj`` (:func:`cylinder_under_palm`); returns the clip."""
    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset

    clip = closing_hand_clip(frames=24, noise_deg=1.0)
    write_asset(Asset("closing", (clip.skeleton,), (clip,)), folder / "closing.usda")
    prop = cylinder_under_palm()
    trimesh.Trimesh(np.asarray(prop.vertices), np.asarray(prop.faces)).export(folder / "cyl.obj")
    return clip
