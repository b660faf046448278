"""Contacts (Daviet 2023 Sec. 4.4-4.6): colliders, broad phase (hash grid, strand boxes), continuous
collision detection, narrow phase and projection, and the pipeline that runs them in Algorithm 1.

* :mod:`.colliders`: plane, sphere, capsule and mesh bodies (signed distance, normal, friction);
* :mod:`.mesh_query`: exact distance and inside/outside against a mesh's triangles (quality figures);
* :mod:`.grid`: the hash grid of edge boxes, strand boxes and the host strand-level broad phase;
* :mod:`.narrow`: the narrow phase (contacts from candidates, re-linearisation, vertex adjacency, Delassus);
* :mod:`.ccd`: continuous edge-edge and vertex-body detection;
* :mod:`.projection`: the z-step (Coulomb cone projection, hybrid Gauss-Seidel/Jacobi) and the
  end-of-step geometric correction that holds edge lengths;
* :mod:`.pipeline`: :class:`ContactPipeline`, detection -> projection -> correction for one Model.
"""
