"""Make ``assets/head.obj``: a procedural human head and neck, watertight, in metres.

    python assets/make_head.py            # rewrites assets/head.obj (deterministic)

The head is an implicit surface: a smooth union (polynomial smooth minimum,
blend radius ``BLEND``) of ellipsoids for the cranium, the face and jaw, the
nose and the ears, and a capsule for the neck, cut flat below the neck.  The
zero level set is extracted with marching cubes (scikit-image) on a grid of
``SPACING`` metres, then cleaned with trimesh (merged vertices, consistent
winding, outward normals).  It is a stand-in for a scanned head, not an
anatomical model.

Frame: y up, the face looks along +z, x to the head's left.  The origin is the
pivot of a head turn or a nod (roughly the top of the spine, behind the jaw),
so a body rotation about the origin moves the head plausibly.  The top of the
head is at y ~ 0.175 m, the chin at y ~ -0.06 m, the neck is cut at y = -0.14 m.

Scalp region: the OBJ has two groups, ``g scalp`` then ``g skin``.  A face is
in the scalp when its centroid lies above the hairline height

    y_hair(theta) = 0.0725 + 0.0525 cos(theta),   theta = atan2(x, z)

(0.125 m at the forehead, 0.0725 m above the ears, 0.02 m at the nape) and
within ``SCALP_SHELL`` of the cranium ellipsoid (which keeps ears, face and
neck out).  ``taichi_hair.groom.generators.load_head`` reads the groups in file
order; trimesh (``MeshCollider``) loads the same file as one watertight mesh.
"""

from __future__ import annotations

import os

import numpy as np

#: Marching-cubes grid spacing [m].
SPACING = 0.0085
#: Blend radius of the smooth union [m].
BLEND = 0.02
#: Neck cut height [m].
NECK_CUT_Y = -0.14
#: Scalp faces lie within this distance (ellipsoid-normalised) of the cranium [-].
SCALP_SHELL = 0.08

# (centre [m], half-axes [m]) of each ellipsoid.
CRANIUM = ((0.0, 0.085, -0.01), (0.075, 0.09, 0.097))
FACE = ((0.0, 0.025, 0.03), (0.066, 0.08, 0.075))
NOSE = ((0.0, 0.045, 0.098), (0.012, 0.022, 0.018))
EARS = [((sx * 0.074, 0.045, -0.012), (0.012, 0.028, 0.018)) for sx in (-1.0, 1.0)]
NECK = ((0.0, NECK_CUT_Y - 0.05, -0.015), (0.0, 0.03, -0.02), 0.055)  # p0, p1, radius [m]


def ellipsoid_sdf(p, center, axes):
    """Approximate signed distance to an ellipsoid [m] (exact on the surface's zero set)."""
    q = (p - np.asarray(center)) / np.asarray(axes)
    return (np.linalg.norm(q, axis=-1) - 1.0) * min(axes)


def capsule_sdf(p, a, b, r):
    a, b = np.asarray(a), np.asarray(b)
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1) - r


def smooth_min(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def head_sdf(p):
    """Signed distance (approximate away from the surface) of the head and neck at points p (..., 3) [m]."""
    d = ellipsoid_sdf(p, *CRANIUM)
    for c, ax in (FACE, NOSE, *EARS):
        d = smooth_min(d, ellipsoid_sdf(p, c, ax), BLEND if c is not NOSE[0] else 0.01)
    d = smooth_min(d, capsule_sdf(p, *NECK), BLEND)
    return np.maximum(d, NECK_CUT_Y - p[..., 1])  # flat cut under the neck


def scalp_mask(centroids):
    """True for the face centroids (F, 3) [m] in the scalp region (see the module docstring)."""
    x, y, z = centroids[:, 0], centroids[:, 1], centroids[:, 2]
    theta = np.arctan2(x, z)
    y_hair = 0.0725 + 0.0525 * np.cos(theta)
    q = (centroids - np.asarray(CRANIUM[0])) / np.asarray(CRANIUM[1])
    near_cranium = np.abs(np.linalg.norm(q, axis=1) - 1.0) < SCALP_SHELL
    return (y > y_hair) & near_cranium


def make_head():
    """(vertices (V, 3) [m], faces (F, 3), scalp face mask (F,)) of the head mesh."""
    import trimesh
    from skimage.measure import marching_cubes

    lo = np.array([-0.11, NECK_CUT_Y - 0.02, -0.13])
    hi = np.array([0.11, 0.20, 0.14])
    n = np.ceil((hi - lo) / SPACING).astype(int) + 1
    axes = [lo[i] + SPACING * np.arange(n[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    vol = head_sdf(grid)
    verts, faces, _, _ = marching_cubes(vol, level=0.0, spacing=(SPACING,) * 3)
    mesh = trimesh.Trimesh(verts + lo, faces, process=True)
    trimesh.repair.fix_normals(mesh)
    if not mesh.is_watertight or mesh.volume <= 0:
        raise RuntimeError("head mesh is not a closed outward-facing surface")
    mask = scalp_mask(mesh.triangles_center)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces), mask


def write_obj(path, vertices, faces, mask):
    """OBJ with ``g scalp`` (faces where mask) then ``g skin``; written to a temporary name, then renamed."""
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write("# taichi-hair procedural head (assets/make_head.py), metres, y up, face along +z\n")
        fh.write(f"# {len(vertices)} vertices, {len(faces)} triangles, {int(mask.sum())} in group scalp\n")
        for v in vertices:
            fh.write(f"v {v[0]:.6f} {v[1]:.6f} {v[2]:.6f}\n")
        for name, sel in (("scalp", mask), ("skin", ~mask)):
            fh.write(f"g {name}\n")
            for f in faces[sel]:
                fh.write(f"f {f[0] + 1} {f[1] + 1} {f[2] + 1}\n")
    os.replace(tmp, path)


if __name__ == "__main__":
    v, f, m = make_head()
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "head.obj")
    write_obj(out, v, f, m)
    print(f"wrote {out}: {len(v)} vertices, {len(f)} triangles, {int(m.sum())} scalp triangles")
