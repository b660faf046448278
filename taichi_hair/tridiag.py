"""Per-strand tridiagonal solves for the ADMM global and twist steps (Sec. 4.3).

One interface, :class:`TridiagonalSolver`, three implementations:

* ``thomas``: the Thomas algorithm, one strand per thread, sequential along the
  strand.  Linear work; the fastest choice on CPU.  Its per-strand body,
  :func:`thomas_strand`, is also called by the fused strand schedule.
* ``pcr`` (global memory): Parallel Cyclic Reduction with one thread per
  vertex and ceil(log2 m_max) reduction levels, ping-ponging between two
  buffers.  Runs on every arch; it is how PCR is tested on CPU.
* ``pcr`` on CUDA: strand-block PCR.  Whole strands are packed into thread
  blocks of at most 1024 vertices and the reduction runs in shared memory
  with block synchronisation (Zhang et al. 2010; Daviet 2023 Sec. 4.3).
  Strands longer than 1024 vertices fall back to the global-memory PCR.

Systems are given as (lower, diag, upper, rhs) fields of shape (vertex_count,),
row i coupling vertex i to i-1 (lower) and i+1 (upper) within its strand; the
solution overwrites ``rhs`` (scalar or 3-vector: three systems with one
matrix).  Thomas also overwrites ``upper``.  Matrices must be diagonally
dominant or SPD (no pivoting), which the ADMM systems are.
"""


import numpy as np
import taichi as ti

BLOCK_MAX = 1024


@ti.func
def thomas_strand(start: ti.i32, m: ti.i32, lower: ti.template(), diag: ti.template(),
                  upper: ti.template(), rhs: ti.template()):
    """Thomas algorithm on rows start .. start+m-1, serially (one strand, one thread).

    Forward sweep: upper <- c', rhs <- d'; then back substitution into rhs.
    Shared by :func:`thomas_solve` and the fused strand schedule
    (:mod:`taichi_hair.schedule_strand`), so both do the same arithmetic.
    """
    # c'_{i-1}, d'_{i-1} and, going back, x_{i+1} are carried in registers: the same operations, without
    # loading again what the row before stored (the same carry made the contact correction's strand-serial edge
    # passes 2.8x faster, and this solve 20 % faster at 10,000 x 32: BENCHMARKS.md).
    inv = 1.0 / diag[start]
    cp = upper[start] * inv
    dp = rhs[start] * inv
    upper[start] = cp
    rhs[start] = dp
    for k in range(1, m):
        i = start + k
        low = lower[i]
        inv_k = 1.0 / (diag[i] - low * cp)
        cp = upper[i] * inv_k
        dp = (rhs[i] - low * dp) * inv_k
        upper[i] = cp
        rhs[i] = dp
    for kk in range(1, m):
        i = start + m - 1 - kk
        dp = rhs[i] - upper[i] * dp
        rhs[i] = dp


@ti.kernel
def thomas_solve(
    strand_vertex_start: ti.template(),
    strand_vertex_count: ti.template(),
    lower: ti.template(),
    diag: ti.template(),
    upper: ti.template(),
    rhs: ti.template(),
):
    for s in strand_vertex_start:
        thomas_strand(strand_vertex_start[s], strand_vertex_count[s], lower, diag, upper, rhs)


@ti.kernel
def pcr_solve_global(
    n_levels: ti.template(),
    vertex_strand: ti.template(),
    strand_vertex_start: ti.template(),
    strand_vertex_count: ti.template(),
    lower: ti.template(),
    diag: ti.template(),
    upper: ti.template(),
    rhs: ti.template(),
    A: ti.template(),
    B: ti.template(),
    C: ti.template(),
    D: ti.template(),
):
    """PCR in global memory; A, B, C, D have shape (2, vertex_count) (ping-pong)."""
    for i in rhs:
        A[0, i] = lower[i]
        B[0, i] = diag[i]
        C[0, i] = upper[i]
        D[0, i] = rhs[i]
    for lvl in ti.static(range(n_levels)):
        src = lvl % 2
        dst = 1 - src
        stride = 1 << lvl
        for i in rhs:
            s = vertex_strand[i]
            first = strand_vertex_start[s]
            last = first + strand_vertex_count[s] - 1
            a_i = A[src, i]
            b_i = B[src, i]
            c_i = C[src, i]
            d_i = D[src, i]
            # Rows outside the strand act as identity rows (a=0, b=1, c=0, d=0).
            a_m, b_m, c_m, d_m = 0.0, 1.0, 0.0, d_i * 0.0
            if i - stride >= first:
                a_m, b_m, c_m, d_m = A[src, i - stride], B[src, i - stride], C[src, i - stride], D[src, i - stride]
            a_p, b_p, c_p, d_p = 0.0, 1.0, 0.0, d_i * 0.0
            if i + stride <= last:
                a_p, b_p, c_p, d_p = A[src, i + stride], B[src, i + stride], C[src, i + stride], D[src, i + stride]
            alpha = -a_i / b_m
            beta = -c_i / b_p
            A[dst, i] = alpha * a_m
            C[dst, i] = beta * c_p
            B[dst, i] = b_i + alpha * c_m + beta * a_p
            D[dst, i] = d_i + alpha * d_m + beta * d_p
    for i in rhs:
        rhs[i] = D[n_levels % 2, i] / B[n_levels % 2, i]


@ti.kernel
def pcr_solve_shared(
    dtype: ti.template(),
    block_size: ti.template(),
    n_levels: ti.template(),
    ncomp: ti.template(),
    block_vertex_start: ti.template(),
    block_vertex_count: ti.template(),
    vertex_strand: ti.template(),
    strand_vertex_start: ti.template(),
    strand_vertex_count: ti.template(),
    lower: ti.template(),
    diag: ti.template(),
    upper: ti.template(),
    rhs: ti.template(),
):
    """Strand-block PCR in shared memory (CUDA and Vulkan).

    Thread ``lid`` of block ``blk`` owns vertex block_vertex_start[blk] + lid.
    Each level reads its neighbours at +-stride inside the same strand from
    shared memory, synchronises, writes, synchronises.
    """
    n_blocks = block_vertex_start.shape[0]
    ti.loop_config(block_dim=block_size)
    for t in range(n_blocks * block_size):
        blk = t // block_size
        lid = t % block_size
        sa = ti.simt.block.SharedArray((block_size,), dtype)
        sb = ti.simt.block.SharedArray((block_size,), dtype)
        sc = ti.simt.block.SharedArray((block_size,), dtype)
        sd = ti.simt.block.SharedArray((block_size, ncomp), dtype)
        count = block_vertex_count[blk]
        active = lid < count
        i = block_vertex_start[blk] + lid
        lo = lid
        hi = lid
        if active:
            s = vertex_strand[i]
            lo = strand_vertex_start[s] - block_vertex_start[blk]
            hi = lo + strand_vertex_count[s] - 1
            sa[lid] = lower[i]
            sb[lid] = diag[i]
            sc[lid] = upper[i]
            for c in ti.static(range(ncomp)):
                if ti.static(ncomp == 1):
                    sd[lid, c] = rhs[i]
                else:
                    sd[lid, c] = rhs[i][c]
        else:
            sa[lid] = 0.0
            sb[lid] = 1.0
            sc[lid] = 0.0
            for c in ti.static(range(ncomp)):
                sd[lid, c] = 0.0
        ti.simt.block.sync()
        for lvl in ti.static(range(n_levels)):
            stride = 1 << lvl
            a_i, b_i, c_i = sa[lid], sb[lid], sc[lid]
            a_m, b_m, c_m = 0.0, 1.0, 0.0
            a_p, b_p, c_p = 0.0, 1.0, 0.0
            has_m = active and lid - stride >= lo
            has_p = active and lid + stride <= hi
            if has_m:
                a_m, b_m, c_m = sa[lid - stride], sb[lid - stride], sc[lid - stride]
            if has_p:
                a_p, b_p, c_p = sa[lid + stride], sb[lid + stride], sc[lid + stride]
            alpha = -a_i / b_m
            beta = -c_i / b_p
            new_d = ti.Vector([0.0] * ncomp)
            for c in ti.static(range(ncomp)):
                d_m = 0.0
                d_p = 0.0
                if has_m:
                    d_m = sd[lid - stride, c]
                if has_p:
                    d_p = sd[lid + stride, c]
                new_d[c] = sd[lid, c] + alpha * d_m + beta * d_p
            new_a = alpha * a_m
            new_b = b_i + alpha * c_m + beta * a_p
            new_c = beta * c_p
            ti.simt.block.sync()
            sa[lid] = new_a
            sb[lid] = new_b
            sc[lid] = new_c
            for c in ti.static(range(ncomp)):
                sd[lid, c] = new_d[c]
            ti.simt.block.sync()
        if active:
            if ti.static(ncomp == 1):
                rhs[i] = sd[lid, 0] / sb[lid]
            else:
                for c in ti.static(range(ncomp)):
                    rhs[i][c] = sd[lid, c] / sb[lid]


def _levels(m: int) -> int:
    return max(1, int(np.ceil(np.log2(max(m, 2)))))


class TridiagonalSolver:
    """Batched per-strand tridiagonal solves behind one interface.

    Args:
        strand_vertex_start, strand_vertex_count: Taichi i32 fields (strand_count,).
        vertex_strand: Taichi i32 field (vertex_count,).
        counts: the strand vertex counts as a NumPy array (to plan blocks and levels).
        method: ``"thomas"`` or ``"pcr"``.
        use_shared: use the strand-block shared-memory PCR (default on CUDA and Vulkan).
    """

    def __init__(self, strand_vertex_start, strand_vertex_count, vertex_strand, counts, method="thomas",
                 use_shared=None):
        if method not in ("thomas", "pcr"):
            raise ValueError(f"tridiagonal method must be 'thomas' or 'pcr', got {method!r}")
        counts = np.asarray(counts, dtype=np.int64)
        self.method = method
        self.strand_vertex_start = strand_vertex_start
        self.strand_vertex_count = strand_vertex_count
        self.vertex_strand = vertex_strand
        n = int(counts.sum())
        self.max_count = int(counts.max())
        self.n_levels = _levels(self.max_count)
        if use_shared is None:
            use_shared = ti.lang.impl.current_cfg().arch in (ti.cuda, ti.vulkan)
        self.use_shared = bool(use_shared and method == "pcr" and self.max_count <= BLOCK_MAX)
        self._buffers = {}
        if method == "pcr" and not self.use_shared:
            # Ping-pong buffers, allocated once (scalar and 3-vector right-hand sides).
            self.A = ti.field(float, (2, n))
            self.B = ti.field(float, (2, n))
            self.C = ti.field(float, (2, n))
            self.D1 = ti.field(float, (2, n))
            self.D3 = ti.Vector.field(3, float, (2, n))
        if self.use_shared:
            self.block_size = max(32, 1 << _levels(self.max_count))
            starts, sizes = _pack_blocks(counts, self.block_size)
            self.block_vertex_start = ti.field(ti.i32, len(starts))
            self.block_vertex_count = ti.field(ti.i32, len(starts))
            self.block_vertex_start.from_numpy(starts.astype(np.int32))
            self.block_vertex_count.from_numpy(sizes.astype(np.int32))

    def solve(self, lower, diag, upper, rhs):
        """Solve in place: rhs <- M^{-1} rhs.  ``upper`` may be overwritten."""
        if self.method == "thomas":
            thomas_solve(self.strand_vertex_start, self.strand_vertex_count, lower, diag, upper, rhs)
        elif self.use_shared:
            ncomp = rhs.n if hasattr(rhs, "n") else 1
            pcr_solve_shared(ti.lang.impl.get_runtime().default_fp, self.block_size, self.n_levels, ncomp,
                             self.block_vertex_start, self.block_vertex_count,
                             self.vertex_strand, self.strand_vertex_start, self.strand_vertex_count,
                             lower, diag, upper, rhs)
        else:
            D = self.D3 if hasattr(rhs, "n") else self.D1
            pcr_solve_global(self.n_levels, self.vertex_strand, self.strand_vertex_start, self.strand_vertex_count,
                             lower, diag, upper, rhs, self.A, self.B, self.C, D)


def _pack_blocks(counts: np.ndarray, block_size: int):
    """Greedily pack consecutive whole strands into blocks of at most block_size vertices."""
    starts, sizes = [], []
    cur_start, cur_size, offset = 0, 0, 0
    for c in counts:
        c = int(c)
        if cur_size + c > block_size and cur_size > 0:
            starts.append(cur_start)
            sizes.append(cur_size)
            cur_start, cur_size = offset, 0
        cur_size += c
        offset += c
    if cur_size > 0:
        starts.append(cur_start)
        sizes.append(cur_size)
    return np.array(starts), np.array(sizes)
