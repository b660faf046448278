"""How good a simulated frame is, measured on the host (NumPy and the exact mesh queries of
:mod:`taichi_hair.contact.mesh_query`): edge strain, penetration into bodies, hair-hair figures, rest.

    q = frame_quality(x, v, model.host, colliders, body_rotation, body_translation, solver.contact_stats)
    q["strain_p99"], q["body_penetration_max_m"], q["vertices_inside"], q["worst_strand"]

Each figure is independent of the solver that made the frame (admm, shape, xpbd all give positions):

- edge strain: |e_j| / e_rest_j - 1 over every real edge (ghost edges, of rest length 0, left out); the
  statistics are of its absolute value (a stretch and a compression of 5 % count alike) [-];
- penetration depth of a free vertex (clamped roots follow the body and are left out) into a body: its
  distance to the collider's TRUE surface where it is inside, 0 outside [m].  Plane, sphere and capsule are
  analytic.  A mesh is judged in two stages: the voxel SDF that the solve uses (trilinear, as the contact
  kernel) picks the vertices it puts inside; for those, the exact distance to the triangles and the exact
  generalized winding number (inside where w >= 1/2, right also for meshes with holes) decide.  A vertex
  that the voxel SDF puts outside but that is inside the true surface is missed; it can only be within the
  SDF's interpolation error of the surface (on assets/head.obj at 64^3, mesh2sdf's node values are within
  0.2 mm of the exact distances, well under ``INSIDE_TOLERANCE_M``).  For a mesh with holes the depth is at
  most the SDF's, which over a hole measures to the winding number's cap (w = 1/2), not to a triangle;
- vertices inside a body: free vertices deeper than ``INSIDE_TOLERANCE_M`` in any body [-];
- hair-hair: the ADMM solver's ``contact_stats`` keys ``hair_penetration_p99_m``,
  ``hair_penetration_max_m``, ``crossed_pairs`` and ``rest_overlap_contacts`` (pairs closer at rest than two
  radii, held at that distance: ``ContactConfig.keep_rest_overlaps``) when it provides them;
- rest: the largest vertex speed of the frame [m/s]; a dynamic run "came to rest" when it is below
  ``REST_SPEED_M_S`` in its last frame;
- shape drift: the distance of each free vertex of a clamped strand from its authored position carried by
  the strand's body, |x - (R_b x* + T_b)|, p90 and max [m]: how far the groom is from the shape it was
  authored in (the sag-free rest pose, issue 14, is judged by it);
- shape distance: the p90 distance between the free vertices and the authored polylines, both ways
  (:func:`shape_distance`): the drift without who-is-where, measured on a run's last frame.
"""

from __future__ import annotations

import numpy as np

#: A free vertex deeper than this inside a body counts as inside [m]: 0.5 mm, ten hair diameters, and
#: more than the 0.2 mm by which the voxel SDF of assets/head.obj (64^3) departs from the exact distance.
INSIDE_TOLERANCE_M = 0.5e-3
#: A run whose p99 edge strain passes this fraction ends with a warning [-].
STRAIN_WARNING = 0.05
#: A dynamic run came to rest when no vertex moves faster than this in its last frame [m/s].
REST_SPEED_M_S = 1e-2
#: Hair-hair figures read from ``SolverADMM.contact_stats`` when present.
HAIR_KEYS = ("hair_penetration_p99_m", "hair_penetration_max_m", "crossed_pairs", "rest_overlap_contacts")


def edge_strain(positions, edge_rest_length) -> np.ndarray:
    """|x_{j+1} - x_j| / e_rest_j - 1 of every vertex slot j, (V, 3) [m] and (V,) [m] -> (V,) [-].

    Edge j joins vertex j to j + 1 (the Model's layout); slots whose rest length is 0 (the last vertex of
    each strand) get 0."""
    x = np.asarray(positions, np.float64)
    rest = np.asarray(edge_rest_length, np.float64)
    e = np.zeros(len(x))
    e[:-1] = np.linalg.norm(x[1:] - x[:-1], axis=1)
    real = rest > 0
    out = np.zeros(len(x))
    out[real] = e[real] / rest[real] - 1.0
    return out


def strain_statistics(positions, edge_rest_length, vertex_strand) -> dict:
    """p50, p99 and max of |edge strain| over the real edges [-], and the strand of the largest (index).

    Args:
        positions: (V, 3) [m].  edge_rest_length: (V,) [m] (0 on ghost edges).  vertex_strand: (V,) [-].
    """
    s = edge_strain(positions, edge_rest_length)
    real = np.asarray(edge_rest_length) > 0
    a = np.abs(s[real])
    if a.size == 0:
        return dict(strain_p50=0.0, strain_p99=0.0, strain_max=0.0, strain_worst_strand=-1)
    k = int(np.argmax(a))
    return dict(strain_p50=float(np.percentile(a, 50)), strain_p99=float(np.percentile(a, 99)),
                strain_max=float(a[k]), strain_worst_strand=int(np.asarray(vertex_strand)[real][k]))


# --------------------------------------------------------------------------- bodies
def _analytic_signed_distance(c, p) -> np.ndarray:
    """Signed distance [m] of body-frame points p (N, 3) to a plane, sphere or capsule collider."""
    from .contact.colliders import CapsuleCollider, PlaneCollider, SphereCollider

    if isinstance(c, PlaneCollider):
        return (p - c.point) @ c.normal
    if isinstance(c, SphereCollider):
        return np.linalg.norm(p - c.center, axis=1) - c.radius
    if isinstance(c, CapsuleCollider):
        ab = c.p1 - c.p0
        t = np.clip((p - c.p0) @ ab / max(float(ab @ ab), 1e-30), 0.0, 1.0)
        return np.linalg.norm(p - (c.p0 + t[:, None] * ab), axis=1) - c.radius
    raise TypeError(type(c).__name__)


def static_signed_distance(colliders, points) -> np.ndarray:
    """The smallest signed distance [m] of world points (N, 3) to colliders that do not move (body -1, or a body
    whose transform is the identity, as in a grooming session): analytic for planes, spheres and capsules, the voxel
    SDF for meshes (the solver's distance; +inf with no collider)."""
    from .contact.colliders import MeshCollider

    p = np.asarray(points, np.float64).reshape(-1, 3)
    d = np.full(len(p), np.inf)
    for c in colliders:
        d = np.minimum(d, c.sdf_numpy(p) if isinstance(c, MeshCollider) else _analytic_signed_distance(c, p))
    return d


def mesh_penetration_depth(collider, points_body) -> np.ndarray:
    """Depth [m] of body-frame points (N, 3) inside a :class:`~taichi_hair.contact.colliders.MeshCollider`'s true
    surface, 0 where outside (see the module docstring for the two stages)."""
    p = np.asarray(points_body, np.float64).reshape(-1, 3)
    depth = np.zeros(len(p))
    cand = np.nonzero(collider.sdf_numpy(p) < 0.0)[0]
    if len(cand):
        q = collider.triangle_query
        inside = q.winding_number(p[cand]) >= 0.5
        cand = cand[inside]
        if len(cand):
            depth[cand] = q.unsigned_distance(p[cand])
            if collider.sign_method == "winding":
                # Over a hole the surface is the cap (w = 1/2), not a triangle: the SDF's distance to it
                # bounds the depth there (elsewhere the SDF's |phi| is larger, up to interpolation error).
                depth[cand] = np.minimum(depth[cand], -collider.sdf_numpy(p[cand]))
    return depth


def body_penetration(positions, colliders, body_rotation, body_translation, vertex_strand, free) -> np.ndarray:
    """Deepest penetration of each vertex into any collider, (V,) [m] (0: outside all, and at fixed vertices).

    Args:
        positions: (V, 3) world [m].  colliders: those of :mod:`taichi_hair.contact.colliders`.
        body_rotation: (B, 3, 3) [-] and body_translation: (B, 3) [m], the transforms the frame ended with.
        vertex_strand: (V,) [-] (for collider strand ranges).  free: (V,) bool, vertices the solver moves.
    """
    from .contact.colliders import MeshCollider

    x = np.asarray(positions, np.float64)
    out = np.zeros(len(x))
    strand = np.asarray(vertex_strand)
    for c in colliders:
        sel = np.asarray(free, bool).copy()
        if c.strands is not None:
            sel &= (strand >= c.strands[0]) & (strand < c.strands[1])
        idx = np.nonzero(sel)[0]
        if len(idx) == 0:
            continue
        p = x[idx]
        if c.body >= 0:
            R = np.asarray(body_rotation[c.body], np.float64)
            p = (p - np.asarray(body_translation[c.body], np.float64)) @ R  # R^T (x - T), row-wise
        if isinstance(c, MeshCollider):
            d = mesh_penetration_depth(c, p)
        else:
            d = np.maximum(-_analytic_signed_distance(c, p), 0.0)
        out[idx] = np.maximum(out[idx], d)
    return out


# --------------------------------------------------------------------------- shape
def _authored_shape(host: dict, body_rotation, body_translation):
    """(ref, held, sel) for the drift and the shape distance: ref (V, 3) the authored shape x* carried by the bodies,
    R_b x* + T_b, on the vertices of clamped strands (x* elsewhere) [m]; held: those vertices; sel: their free ones.
    None for a host without an authored shape (hand-made frames).  Identity transforms when ``body_rotation`` is None."""
    if not all(k in host for k in ("strand_body", "vertex_rest_position", "vertex_is_fixed")):
        return None
    body = np.asarray(host["strand_body"])[np.asarray(host["vertex_strand"])]
    held = body >= 0
    sel = held & (np.asarray(host["vertex_is_fixed"]) == 0)
    ref = np.array(host["vertex_rest_position"], np.float64)
    if body_rotation is not None and held.any():
        R = np.asarray(body_rotation, np.float64)[body[held]]
        T = np.asarray(body_translation, np.float64)[body[held]]
        ref[held] = np.einsum("kij,kj->ki", R, ref[held]) + T
    return ref, held, sel


def shape_drift(positions, host: dict, body_rotation=None, body_translation=None) -> dict:
    """p90 and max of |x - (R_b x* + T_b)| over the free vertices of clamped strands [m] (see the module
    docstring); x* = ``host["vertex_rest_position"]``, the authored shape in the body frame.  Identity
    transforms when ``body_rotation`` is None."""
    shape = _authored_shape(host, body_rotation, body_translation)
    if shape is None:
        return {}  # a host without an authored shape (hand-made frames): no drift to measure
    ref, _, sel = shape
    if not sel.any():
        return dict(drift_p90_m=0.0, drift_max_m=0.0)
    d = np.linalg.norm(np.asarray(positions, np.float64)[sel] - ref[sel], axis=1)
    return dict(drift_p90_m=float(np.percentile(d, 90)), drift_max_m=float(d.max()))


def segment_set_distance(points, seg_a, seg_b, k: int = 16, chunk: int = 1 << 16) -> np.ndarray:
    """Exact distance [m] of each point (N, 3) to the nearest of the segments [a_j, b_j] ((S, 3) each).

    A k-d tree of the segment midpoints gives each point its k nearest segments; a point whose k-th midpoint
    is farther than its best distance plus half the longest segment has its answer (every point of a segment
    lies within half its length of its midpoint), the others search the ball of that radius.  Points go
    ``chunk`` at a time (memory ~ chunk x k x 100 bytes).  Measured through :func:`shape_distance` (both ways) on a
    synthetic groom of 86,000 strands x 14 vertices: 33 s and 1.1 GB peak on 2 cores; 300 strands: 0.3 s."""
    from scipy.spatial import cKDTree

    p = np.asarray(points, np.float64).reshape(-1, 3)
    a = np.asarray(seg_a, np.float64).reshape(-1, 3)
    ab = np.asarray(seg_b, np.float64).reshape(-1, 3) - a
    if len(p) == 0 or len(a) == 0:
        return np.full(len(p), np.inf)
    # Each segment cut into pieces of at most a quarter of the median length (the same set of points, so the
    # same distances): the ball of the exactness test shrinks with the longest piece.
    ln = np.sqrt(np.einsum("ij,ij->i", ab, ab))
    pieces = np.minimum(np.ceil(ln / max(0.25 * float(np.median(ln)), 1e-300)), 64).astype(np.int64)
    pieces = np.maximum(pieces, 1)
    if pieces.max() > 1:
        j = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
        owner = np.repeat(np.arange(len(a)), pieces)
        step = ab[owner] / pieces[owner][:, None]
        a, ab = a[owner] + j[:, None] * step, step
    ll = np.einsum("ij,ij->i", ab, ab)
    half = 0.5 * float(np.sqrt(ll.max()))
    ll = np.maximum(ll, 1e-300)
    tree = cKDTree(a + 0.5 * ab)

    def to(pts, idx):  # distances of pts (M, 3) to the segments idx (M, K) -> (M, K)
        d = pts[:, None, :] - a[idx]
        t = np.clip(np.einsum("mkj,mkj->mk", d, ab[idx]) / ll[idx], 0.0, 1.0)
        d -= t[..., None] * ab[idx]
        return np.sqrt(np.einsum("mkj,mkj->mk", d, d))

    k = min(k, len(a))
    best = np.empty(len(p))
    for lo in range(0, len(p), chunk):
        q = p[lo:lo + chunk]
        dm, idx = tree.query(q, k=k, workers=-1)
        dm, idx = dm.reshape(len(q), k), idx.reshape(len(q), k)
        b = to(q, idx).min(axis=1)
        need = np.nonzero(dm[:, -1] <= b + half)[0]
        if need.size:
            balls = tree.query_ball_point(q[need], b[need] + half, workers=-1)
            sizes = np.fromiter((len(x) for x in balls), np.int64, need.size)
            if sizes.sum():
                seg = np.fromiter((j for x in balls for j in x), np.int64, int(sizes.sum()))
                owner = np.repeat(need, sizes)
                dist = to(q[owner], seg[:, None])[:, 0]
                np.minimum.at(b, owner, dist)
        best[lo:lo + chunk] = b
    return best


def shape_distance(positions, host: dict, body_rotation=None, body_translation=None) -> dict:
    """How far the groom's shape is from its authored one, whichever strand is where: the p90 distance of the
    free vertices of clamped strands to the authored polylines (carried by their bodies, as in
    :func:`shape_drift`), and of the authored vertices to the current polylines; ``shape_distance_p90_m`` is the
    larger [m].  Unlike the drift it does not grow when strands trade places inside the groom (a ponytail's
    wisps reordered by a head turn): it measures the envelope and the strands' courses, not who is where."""
    shape = _authored_shape(host, body_rotation, body_translation)
    if shape is None:
        return {}
    ref, held, sel = shape
    if not sel.any():
        return dict(shape_distance_p90_m=0.0)
    x = np.asarray(positions, np.float64)
    rest = np.asarray(host["edge_rest_length"])
    e = np.nonzero((rest[:-1] > 0) & held[:-1])[0]  # the edges j -> j + 1 of clamped strands
    to_authored = segment_set_distance(x[sel], ref[e], ref[e + 1])
    to_current = segment_set_distance(ref[sel], x[e], x[e + 1])
    return dict(shape_distance_p90_m=float(max(np.percentile(to_authored, 90), np.percentile(to_current, 90))))


def last_frame_figures(positions, velocities, host: dict, body_rotation, body_translation, shape: bool,
                       speeds: bool) -> dict:
    """What a run's summary adds from its last frame alone: with ``shape``, ``shape_distance_p90_last_m``
    (:func:`shape_distance`, once: a k-d tree of a large groom's edges costs seconds); with ``speeds`` (a dynamic
    run's "came to rest"), ``last_frame_speed_p99_m_s`` and ``last_frame_vertices_above_rest_speed`` (vertices
    at ``REST_SPEED_M_S`` or faster): how far from rest, beyond the one fastest vertex the criterion reads."""
    out = {}
    if shape:
        d = shape_distance(positions, host, body_rotation, body_translation)
        if d:
            out["shape_distance_p90_last_m"] = d["shape_distance_p90_m"]
    if speeds:
        s = np.linalg.norm(np.asarray(velocities, np.float64), axis=1)
        out.update(last_frame_speed_p99_m_s=float(np.percentile(s, 99)) if s.size else 0.0,
                   last_frame_vertices_above_rest_speed=int(np.count_nonzero(s >= REST_SPEED_M_S)))
    return out


# --------------------------------------------------------------------------- one frame
def frame_quality(positions, velocities, host: dict, colliders=(), body_rotation=None, body_translation=None,
                  contact_stats=None, tolerance: float = INSIDE_TOLERANCE_M) -> dict:
    """Every figure of the module docstring for one frame.

    Args:
        positions, velocities: (V, 3) [m], [m/s].  host: ``Model.host`` (edge_rest_length, vertex_strand,
        vertex_is_fixed).  colliders, body_rotation (B, 3, 3), body_translation (B, 3): the bodies.
        contact_stats: the solver's ``contact_stats`` (hair-hair keys read with ``.get``), or None.
        tolerance: depth beyond which a vertex counts as inside a body [m].

    Returns a flat dict: strain_p50/p99/max [-], strain_worst_strand, body_penetration_p99_m/max_m (over
    the free vertices, 0 where outside) [m], vertices_inside [-], penetration_worst_strand (-1: none),
    drift_p90_m/drift_max_m [m] (:func:`shape_drift`), max_speed_m_s [m/s], and the hair-hair keys that the
    solver gave.
    """
    strand = np.asarray(host["vertex_strand"])
    q = strain_statistics(positions, host["edge_rest_length"], strand)
    free = np.asarray(host.get("vertex_is_fixed", np.zeros(len(strand)))) == 0
    if colliders:
        depth = body_penetration(positions, colliders, body_rotation, body_translation, strand, free)
        d = depth[free] if free.any() else np.zeros(1)
        k = int(np.argmax(depth))
        q.update(body_penetration_p99_m=float(np.percentile(d, 99)), body_penetration_max_m=float(depth[k]),
                 vertices_inside=int(np.count_nonzero(depth > tolerance)),
                 penetration_worst_strand=int(strand[k]) if depth[k] > 0 else -1)
    q.update(shape_drift(positions, host, body_rotation, body_translation))
    v = np.asarray(velocities, np.float64)
    q["max_speed_m_s"] = float(np.max(np.linalg.norm(v, axis=1))) if len(v) else 0.0
    for key in HAIR_KEYS:
        if contact_stats and contact_stats.get(key) is not None:
            q[key] = contact_stats.get(key)
    return q


def quality_warnings(q: dict, tolerance: float = INSIDE_TOLERANCE_M) -> list:
    """One line per failed figure of a frame's :func:`frame_quality` (empty: the frame is fine)."""
    out = []
    if q["strain_p99"] > STRAIN_WARNING:
        out.append(f"p99 edge strain {100 * q['strain_p99']:.2f} % passes {100 * STRAIN_WARNING:g} % (max "
                   f"{100 * q['strain_max']:.2f} % on strand {q['strain_worst_strand']})")
    if q.get("vertices_inside", 0) > 0:
        out.append(f"{q['vertices_inside']} vertices deeper than {1e3 * tolerance:g} mm inside a body (deepest "
                   f"{1e3 * q['body_penetration_max_m']:.2f} mm, strand {q['penetration_worst_strand']})")
    return out
