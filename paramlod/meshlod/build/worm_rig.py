"""A skinned mesh of our own at scale: the giant worm's body (functions/giant_worm.py) tessellated
at its pose of time 0, rigged along its spine and animated with a wave, written as a GLB file with
pygltflib so that it goes through the same loader as any skinned file
(paramlod.meshlod.skinned.load_skinned).

Driven by the skinned bench (``paramlod bench --extras skinned``), the gallery's skinned worm and
the tests (a small one). No twin (an offline build): tests/meshlod/test_skinned.py checks that the
file loads back, that the bind pose is the tessellated surface and that the wave moves it.

- Tessellation: ``nu`` x ``nv`` samples of the body (u from the mouth to the tail, v around, the
  seam shared), 2 (nu - 1) nv triangles facing outwards; normals from the surface's derivatives.
- A closed shell (``shell``): the body has a wall. An inner surface, the outer one scaled by
  1 - ``wall`` towards each ring's centre, faces inwards, and two flat rings join the two at the
  mouth and at the tail end. A closed, consistently oriented surface shows no back face to a camera
  outside it, so backface culling is exact for it even with the two-sided rasterizers (an open tube
  would show its back faces through the mouth, which any backface culling then removes), and the
  mouth still opens onto the inner wall. 4 (nu - 1) nv + 4 nv triangles: the full size (nu 400,
  nv 192) has 307,200.
- Rig: ``bones`` joints in a chain along the centreline (the mean of each ring of samples; the
  skin relief averages out over a ring), joint k at u_k = k / (bones - 1), its frame the tangent,
  the side direction (world x less its tangent part, as the body's own frame) and their cross
  product. Weights by distance along the spine: a vertex at u has s = u (bones - 1) and weights
  (1 - |s - k| / 1.5)^2 on the up to four joints k within 1.5 of s, normalised, so neighbouring
  bones blend smoothly.
- Animation ("wave"): each joint turns about its own third axis (bending the body sideways, as the
  parametric worm sways) by amplitude * sin(2 pi (t / period - k / wavelength)), with the
  amplitude growing towards the head; ``keys`` keyframes per period, LINEAR, one period long and
  periodic (the last key equals the first).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from paramlod.core.files import write_atomically
from paramlod.errors import MeshError
from paramlod.function.registry import get_function
from paramlod.meshlod.skinned import matrix_quat

FULL = {"nu": 400, "nv": 192, "bones": 64}
SMALL = {"nu": 48, "nv": 24, "bones": 12}


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (x, y, z, w), broadcast."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, np.float64), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, np.float64), -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], -1)


def tessellate(nu: int, nv: int, t: float = 0.0):
    """(vertices float32 [nu nv, 3], normals float32, triangles uint32 [2 (nu - 1) nv, 3], u per
    vertex float64) of the giant worm's body at time ``t``."""
    if nu < 3 or nv < 8:
        raise MeshError(f"worm tessellation needs nu >= 3 and nv >= 8, got {nu} x {nv}")
    fn = get_function("giant_worm")
    u = np.linspace(0.0, 1.0, nu)
    v = np.arange(nv) * (2 * math.pi / nv)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    pos, du, dv = fn.surface(uu, vv, t=t)
    n = np.cross(du, dv)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv), indexing="ij")
    a = i * nv + j
    b = (i + 1) * nv + j
    c = i * nv + (j + 1) % nv
    d = (i + 1) * nv + (j + 1) % nv
    # (u, v), (u + du, v), (u, v + dv) runs counter-clockwise about du x dv: the outward normal
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([c, b, d], -1).reshape(-1, 3)])
    return (pos.reshape(-1, 3).astype(np.float32), n.reshape(-1, 3).astype(np.float32), tris.astype(np.uint32),
            uu.reshape(-1), pos.mean(axis=1))


def shell(nu: int, nv: int, wall: float = 0.15, t: float = 0.0):
    """(vertices, normals, triangles, u per vertex, ring centres) of the worm's closed body with a
    wall (see the module docstring): outer samples first (as ``tessellate``), then the inner ones,
    then the two rim rings (own vertices, flat normals)."""
    if not 0 < wall < 1:
        raise MeshError(f"worm wall must be in (0, 1) of the radius, got {wall}")
    v, n, f, u, centre = tessellate(nu, nv, t)
    ring = np.repeat(centre, nv, axis=0)
    inner = ring + (v - ring) * (1 - wall)
    tang = np.gradient(centre, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    nvx = nu * nv
    j = np.arange(nv)
    parts_v, parts_n, parts_u, tris = [v, inner], [n, -n], [u, u], [f, f[:, ::-1] + nvx]
    at = 2 * nvx
    for i, normal in ((0, -tang[0]), (nu - 1, tang[-1])):   # mouth rim, tail rim: outer ring then inner ring
        o = i * nv + j
        parts_v += [v[o], inner[o]]
        parts_n += [np.tile(normal, (nv, 1)), np.tile(normal, (nv, 1))]
        parts_u += [u[o], u[o]]
        a, b = at + j, at + (j + 1) % nv            # outer ring of the rim
        c, d = at + nv + j, at + nv + (j + 1) % nv  # inner ring
        quad = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
        # wind each rim so that its face normal is the rim's (away from the body)
        p = np.concatenate(parts_v).astype(np.float64)
        fn = np.cross(p[quad[:, 1]] - p[quad[:, 0]], p[quad[:, 2]] - p[quad[:, 0]]).sum(axis=0)
        tris.append(quad if fn @ normal > 0 else quad[:, ::-1])
        at += 2 * nv
    return (np.concatenate(parts_v).astype(np.float32), np.concatenate(parts_n).astype(np.float32),
            np.concatenate(tris).astype(np.uint32), np.concatenate(parts_u), centre)


def _frames(points: np.ndarray) -> np.ndarray:
    """float64 [B, 4, 4] joint frames along a polyline: tangent, side (x less its tangent part), cross."""
    tang = np.gradient(points, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    side = np.array([1.0, 0, 0]) - tang * tang[:, :1]
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    third = np.cross(tang, side)
    m = np.tile(np.eye(4), (len(points), 1, 1))
    m[:, :3, 0], m[:, :3, 1], m[:, :3, 2], m[:, :3, 3] = tang, side, third, points
    return m


def worm_rig(nu: int = FULL["nu"], nv: int = FULL["nv"], bones: int = FULL["bones"], period: float = 2.0,
             keys: int = 16, amplitude: float = 0.05, wavelength: float = 24.0, wall: float = 0.15) -> dict:
    """The worm's closed body (``shell``), rig and clip as arrays (what write_skinned_glb writes)."""
    if not 2 <= bones <= 255:
        raise MeshError(f"the worm rig needs 2..255 bones, got {bones}")
    if keys < 2 or not period > 0:
        raise MeshError("the worm wave needs keys >= 2 and a period > 0")
    v, n, f, u, centre = shell(nu, nv, wall)
    uk = np.linspace(0.0, 1.0, bones)
    spine = np.stack([np.interp(uk, np.linspace(0, 1, nu), centre[:, k]) for k in range(3)], 1)
    bind = _frames(spine)
    # local rest transforms of the chain: G_{k-1}^-1 G_k
    local = np.concatenate([bind[:1], np.linalg.inv(bind[:-1]) @ bind[1:]])
    rest_t = local[:, :3, 3]
    rest_q = np.stack([matrix_quat(m[:3, :3]) for m in local])
    # weights by distance along the spine
    s = u * (bones - 1)
    k0 = np.floor(s).astype(np.int64) - 1
    js = np.clip(k0[:, None] + np.arange(4), 0, bones - 1)
    w = np.clip(1 - np.abs(s[:, None] - (k0[:, None] + np.arange(4))) / 1.5, 0, None) ** 2
    w[(k0[:, None] + np.arange(4) < 0) | (k0[:, None] + np.arange(4) > bones - 1)] = 0
    w /= w.sum(axis=1, keepdims=True)
    # the wave: rotation about each joint's third axis, growing towards the head (joint 0)
    times = np.linspace(0.0, period, keys + 1)
    grow = 0.4 + 0.6 * (1 - uk)
    ang = amplitude * grow[None, :] * np.sin(2 * np.pi * (times[:, None] / period - np.arange(bones)[None, :] / wavelength))
    ang[-1] = ang[0]   # periodic: exactly the first pose again
    qz = np.stack([np.zeros_like(ang), np.zeros_like(ang), np.sin(ang / 2), np.cos(ang / 2)], -1)
    rot = quat_mul(rest_q[None], qz)   # [K, B, 4]: T R_rest R_z(angle)
    channels = [(b, "rotation", times, rot[:, b]) for b in range(bones)]
    return {"vertices": v, "normals": n, "triangles": f, "joints": js.astype(np.uint16), "weights": w.astype(np.float32),
            "parents": np.arange(bones) - 1, "inverse_bind": np.linalg.inv(bind),
            "rest": (rest_t, rest_q, np.ones((bones, 3))), "channels": channels, "animation": "wave",
            "names": [f"spine{k:02d}" for k in range(bones)]}


def write_skinned_glb(path, vertices, normals, triangles, joints, weights, parents, inverse_bind, rest, channels,
                      animation: str = "clip", names=None, interpolation: str = "LINEAR", **_) -> Path:
    """Write a GLB with one skinned mesh (node 0, not a joint) and a joint hierarchy (``parents``,
    parents before children; joint j is node j + 1), its inverse bind matrices, rest TRS and one
    animation of ``channels`` (node, path, times, values; CUBICSPLINE values [K, 3, d]).
    Atomically; MeshError for an output that cannot be written."""
    import pygltflib as G   # optional: only the generator writes glTF

    vertices = np.ascontiguousarray(vertices, np.float32)
    blobs, views, accessors = [], [], []

    def add(a, comp, kind, target=None, minmax=False):
        a = np.ascontiguousarray(a)
        off = sum(len(b) for b in blobs)
        data = a.tobytes()
        blobs.append(data + b"\0" * (-len(data) % 4))
        views.append(G.BufferView(buffer=0, byteOffset=off, byteLength=len(data), target=target))
        acc = G.Accessor(bufferView=len(views) - 1, componentType=comp, count=len(a), type=kind)
        if minmax:
            acc.min = a.min(axis=0).astype(float).tolist()
            acc.max = a.max(axis=0).astype(float).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    j = np.asarray(joints)
    jcomp, jdt = (G.UNSIGNED_BYTE, np.uint8) if j.max() < 256 else (G.UNSIGNED_SHORT, np.uint16)
    attrs = G.Attributes(
        POSITION=add(vertices, G.FLOAT, G.VEC3, G.ARRAY_BUFFER, True),
        NORMAL=add(np.asarray(normals, np.float32), G.FLOAT, G.VEC3, G.ARRAY_BUFFER),
        JOINTS_0=add(j.astype(jdt), jcomp, G.VEC4, G.ARRAY_BUFFER),
        WEIGHTS_0=add(np.asarray(weights, np.float32), G.FLOAT, G.VEC4, G.ARRAY_BUFFER))
    idx = add(np.asarray(triangles, np.uint32).reshape(-1), G.UNSIGNED_INT, G.SCALAR, G.ELEMENT_ARRAY_BUFFER)
    ibm = add(np.ascontiguousarray(np.transpose(np.asarray(inverse_bind, np.float32), (0, 2, 1))).reshape(-1, 16),
              G.FLOAT, G.MAT4)
    t, q, s = rest
    parents = np.asarray(parents, np.int64)
    nb = len(parents)
    names = names or [f"joint{k}" for k in range(nb)]
    nodes = [G.Node(name="mesh", mesh=0, skin=0)]
    for b in range(nb):
        nodes.append(G.Node(name=names[b], translation=[float(x) for x in t[b]], rotation=[float(x) for x in q[b]],
                            scale=[float(x) for x in s[b]],
                            children=[int(c) + 1 for c in np.flatnonzero(parents == b)] or None))
    samplers, chans = [], []
    for node, prop, times, values in channels:
        times = np.asarray(times, np.float32)
        inp = add(times, G.FLOAT, G.SCALAR)
        accessors[inp].min, accessors[inp].max = [float(times.min())], [float(times.max())]
        vals = np.asarray(values, np.float32)
        width = vals.shape[-1]
        out = add(vals.reshape(-1, width), G.FLOAT, G.VEC4 if width == 4 else G.VEC3)
        samplers.append(G.AnimationSampler(input=inp, output=out, interpolation=interpolation))
        chans.append(G.AnimationChannel(sampler=len(samplers) - 1, target=G.AnimationChannelTarget(node=int(node) + 1, path=prop)))
    roots = [0] + [b + 1 for b in range(nb) if parents[b] < 0]
    blob = b"".join(blobs)
    g = G.GLTF2(asset=G.Asset(generator="paramlod worm_rig", version="2.0"), scene=0, scenes=[G.Scene(nodes=roots)],
                nodes=nodes, meshes=[G.Mesh(primitives=[G.Primitive(attributes=attrs, indices=idx, mode=G.TRIANGLES)])],
                skins=[G.Skin(joints=list(range(1, nb + 1)), inverseBindMatrices=ibm, skeleton=roots[1] if len(roots) > 1 else None)],
                animations=[G.Animation(name=animation, samplers=samplers, channels=chans)] if chans else [],
                accessors=accessors, bufferViews=views, buffers=[G.Buffer(byteLength=len(blob))])
    g.set_binary_blob(blob)
    return write_atomically(path, lambda tmp: g.save_binary(tmp))


def write_worm(path, size: str | dict = "full", **wave) -> Path:
    """Generate the rigged, animated worm (``size`` "full", "small" or a dict of nu, nv, bones)
    and write it to ``path`` (.glb)."""
    dims = {"full": FULL, "small": SMALL}.get(size, size) if isinstance(size, str) else size
    if not isinstance(dims, dict):
        raise MeshError(f"worm size must be 'full', 'small' or a dict of nu, nv, bones, got {size!r}")
    if Path(path).suffix.lower() != ".glb":
        raise MeshError(f"the worm is written as a .glb file, got {path}")
    return write_skinned_glb(path, **worm_rig(**dims, **wave))
