"""Memory estimates, checked before anything is allocated: an absurd size is refused in one line with the
estimate, instead of a machine that swaps for minutes and a process killed without a word.

The per-vertex figures are measured (2-core VM, Taichi 1.7.4 CPU arch, f32, 2026-12-03; peak resident
memory of ``taichi-hair simulate`` for one frame at two sizes, the difference over the vertex difference):
``hang`` 500 -> 4,000 strands (20,500 -> 164,000 vertices): 219 -> 349 MB, 0.95 kB per vertex without
contacts; ``hairball`` 200 -> 1,000 strands (6,200 -> 31,000 vertices): 267 -> 311 MB, 1.8 kB per vertex
with hair-hair contacts.  The estimate rounds these up (1.2 and 2.5 kB) and adds the frames kept in memory
(12 B per vertex and frame) and ~250 MB of Taichi runtime.  A frame buffer larger than a quarter of the
available memory is streamed to a file beside the output instead (:func:`frames_in_memory`; ``simulate``
then checks the disk's free space), so it does not count against memory.  It is an estimate: the contact buffers grow
with the number of contacts, which depends on the scene.
"""

from __future__ import annotations

import os

#: Bytes per vertex of the Model, State and solver (rounded up from the measurements above).
BYTES_PER_VERTEX = 1200
BYTES_PER_VERTEX_CONTACTS = 2500
#: Bytes per vertex of a groom being generated or read (float64 points, radii, frames on the host).
BYTES_PER_VERTEX_HOST = 200
#: Taichi's runtime and the compiled kernels.
RUNTIME_BYTES = 250e6
#: A whole-run frame buffer above this fraction of the available memory is kept on disk (a memory map).
FRAME_BUFFER_FRACTION = 0.25


def available_memory() -> float:
    """Bytes the system can give now (``MemAvailable`` of /proc/meminfo; total RAM elsewhere)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return float("inf")


def format_bytes(n: float) -> str:
    for unit, f in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= f:
            return f"{n / f:.1f} {unit}"
    return f"{n / 1e3:.0f} kB"


def frame_buffer_bytes(vertices: int, frames: int, itemsize: int = 4) -> float:
    """Bytes of the positions of frames 0..frames (``itemsize`` 4 for f32, 8 for f64)."""
    return float(vertices) * 3.0 * itemsize * (frames + 1)


def frames_in_memory(vertices: int, frames: int, itemsize: int = 4) -> bool:
    """Whether a run keeps its frame buffer in memory (else it is streamed to a file beside the output)."""
    return frame_buffer_bytes(vertices, frames, itemsize) <= FRAME_BUFFER_FRACTION * available_memory()


def simulation_bytes(vertices: int, frames: int = 1, contacts: bool = False) -> float:
    """Estimated peak memory [bytes] of a simulation of ``vertices`` keeping ``frames`` + 1 frames (in
    memory when :func:`frames_in_memory`, else on disk and not counted)."""
    per = BYTES_PER_VERTEX_CONTACTS if contacts else BYTES_PER_VERTEX
    buffer = frame_buffer_bytes(vertices, frames) if frames_in_memory(vertices, frames) else 0.0
    return RUNTIME_BYTES + float(vertices) * per + buffer


def check_frame_buffer(vertices: int, frames: int, folder: str, itemsize: int = 4) -> None:
    """When the frames will not be kept in memory, refuse (ValueError) a folder without room for the
    streamed buffer and the frames written from it (twice the buffer); the folder may not exist yet (its
    nearest existing parent is checked)."""
    if frames_in_memory(vertices, frames, itemsize):
        return
    existing = os.path.abspath(folder)
    while not os.path.isdir(existing) and os.path.dirname(existing) != existing:
        existing = os.path.dirname(existing)
    check_disk(2.0 * frame_buffer_bytes(vertices, frames, itemsize), existing,
               f"{frames} frames of {vertices:,} vertices (streamed, too large for memory)")


def check_disk(nbytes: float, folder: str, what: str) -> None:
    """Raise ValueError when ``folder``'s file system has less than ``nbytes`` free."""
    import shutil

    free = float(shutil.disk_usage(folder).free)
    if nbytes > free:
        raise ValueError(f"{what} needs {format_bytes(nbytes)} of disk in {folder}, more than the "
                         f"{format_bytes(free)} free; use fewer frames or vertices")


def check_fits(estimate: float, what: str, hint: str = "", fraction: float = 0.9) -> None:
    """Raise ValueError naming ``what``, the estimate and the available memory when the estimate exceeds
    ``fraction`` of what the system can give."""
    avail = available_memory()
    if estimate > fraction * avail:
        raise ValueError(f"{what} needs an estimated {format_bytes(estimate)} of memory, more than the "
                         f"{format_bytes(avail)} available" + (f"; {hint}" if hint else ""))


def check_simulation(vertices: int, frames: int, contacts: bool, what: str, hint: str = "") -> None:
    check_fits(simulation_bytes(vertices, frames, contacts),
               f"{what} ({vertices:,} vertices, {frames} frames{', contacts' if contacts else ''})", hint)


def check_host(vertices: int, what: str, hint: str = "") -> None:
    check_fits(float(vertices) * BYTES_PER_VERTEX_HOST, f"{what} ({vertices:,} vertices)", hint)
