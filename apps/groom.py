"""The grooming window (Daviet 2023, Sec. 5.3): ``taichi-hair groom [GROOM]`` or ``python apps/groom.py [GROOM]``.

A GGUI window draws the head mesh and the strands (lines coloured by region, strand, selection or the
skinning interpolation error) while a quasistatic :class:`~taichi_hair.groom.session.GroomingSession` runs a
few ADMM iterations per displayed frame with proximity contacts only.  Everything the window does goes
through :class:`GroomApp`, whose methods take pixel coordinates and keys, so the tools are testable off
screen (``tests/test_groom_app.py``) and every edit lands in the session log (``Save session`` writes it;
``taichi-hair groom GROOM --offscreen --script`` replays it).

Mouse and keys (also listed in the side panel):

* left drag with the active tool -- ``select`` (click: strands under the cursor, within the brush
  radius of the pick ray; shift adds), ``drag`` (grab the strands under the cursor and pull them in the
  plane facing the camera; release to let go), ``trim`` (click: cut along the plane through the pick
  ray and the screen's horizontal), ``comb`` (sweeps a comb along the mouse stroke: a capsule tooth of
  the brush radius along the view direction, through the whole groom's depth, moving in the plane facing
  the camera through the strands under the cursor; it is a frictional collider of the simulation
  (``GroomingSession.comb``, friction ``comb_friction``), run one segment of about a brush radius at a
  time, each segment an undoable, logged edit), ``pin`` (pins the vertices under the cursor; shift
  unpins);
* right drag orbits, middle drag (or shift + right drag) pans, ``-``/``=`` zoom (GGUI 1.7 reports no wheel);
* keys: 1-5 tools, ``u`` undo, ``y`` redo, ``space`` simulation on/off, ``c`` cycles colours,
  ``g`` grows (x1.2) and ``h`` shortens (x0.8) the selection, ``k``/``l`` curl x1.25 / x0.8,
  ``a`` selects all, ``s`` saves the groom, ``p`` writes a screenshot (PNG beside the autosave),
  ``r`` reloads the groom file from disk (a file that fails
  to load leaves the current groom open and shows the loader's message), ``escape`` quits.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

TOOLS = ("select", "drag", "trim", "comb", "pin")
COLOR_CYCLE = ("region", "strand", "error", "uniform")


class GroomApp:
    """A grooming session, a GGUI viewer and an orbit camera; the window's tools as methods.

    Args:
        session: the :class:`GroomingSession` being edited.
        viewer: a :class:`taichi_hair.render.ViewerGGUI` (on screen or off screen).
        head: optional (vertices, triangles, ...) head mesh [m] to draw.
        save_path: where ``s`` / Save writes the groom (``.thair.npz``); the log goes beside it.

    Attributes:
        tool: active tool, one of ``TOOLS``.
        color_mode: strand colours, one of ``COLOR_CYCLE``.
        brush_radius: pick radius around the mouse ray, and the comb's radius [m].
        comb_friction: Coulomb coefficient of the comb against hair [-].
        message: last status or error line (shown in the panel).
        frame_ms: wall time of the last displayed frame, simulation + skinning + drawing [ms].
        sim_ms: of which the session's ``advance`` [ms].
    """

    def __init__(self, session, viewer, head=None, save_path=None, make_session=None, groom_path=None):
        self.session = session
        self.groom_path = groom_path
        self.viewer = viewer
        self.head = head
        self.save_path = save_path
        self.make_session = make_session
        self.tool = "select"
        self.color_mode = "region"
        self.message = "ready"
        #: Frames drawn and frames with a simulation step, since the window opened [-].
        self.frames_drawn = 0
        self.frames_simulated = 0
        self.frame_ms = 0.0
        self.sim_ms = 0.0
        self._error_cache = None
        self._color_cache = None
        pts = session.groom.points.astype(np.float64)
        if head is not None:
            viewer.set_head(head[0], head[1])
            pts = np.vstack([pts, np.asarray(head[0], np.float64)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        self.target = 0.5 * (lo + hi)
        self.size = max(float(np.linalg.norm(hi - lo)), 1e-3)
        self.brush_radius = 0.02 * self.size
        self.comb_friction = 0.5
        self.yaw, self.pitch = math.radians(30.0), math.radians(12.0)
        self.distance = 1.7 * self.size
        self.fov = 35.0
        self._drag_plane = None
        self._comb_last = None
        self.update_view()

    # ------------------------------------------------------------------ camera
    def camera(self):
        from taichi_hair.render import CameraConfig

        d = np.array([math.cos(self.pitch) * math.sin(self.yaw), math.sin(self.pitch),
                      math.cos(self.pitch) * math.cos(self.yaw)])
        eye = self.target + self.distance * d
        return CameraConfig(eye=tuple(eye), target=tuple(self.target), fov=self.fov,
                            z_near=max(self.distance * 0.01, 1e-4), z_far=self.distance * 20 + 1.0)

    def orbit(self, dx: float, dy: float) -> None:
        """Turn the camera about the target by screen fractions dx, dy (1 = half a turn / 90 degrees)."""
        self.yaw -= math.pi * dx
        self.pitch = float(np.clip(self.pitch + 0.5 * math.pi * dy, -1.45, 1.45))

    def pan(self, dx: float, dy: float) -> None:
        """Move the target in the view plane by screen fractions."""
        from taichi_hair.render import _basis

        _, f, s, u = _basis(self.camera())
        h = 2 * self.distance * math.tan(math.radians(self.fov) / 2)
        self.target = self.target - dx * h * self.viewer.width / self.viewer.height * s - dy * h * u

    def zoom(self, factor: float) -> None:
        self.distance = float(np.clip(self.distance * factor, 0.05 * self.size, 20 * self.size))

    def ray(self, col: float, row: float):
        from taichi_hair.render import pick_ray

        return pick_ray(self.camera(), self.viewer.width, self.viewer.height, col, row)

    # ------------------------------------------------------------------ tools
    def _guard(self, action, fn):
        try:
            out = fn()
            return out
        except ValueError as exc:
            self.message = f"{action}: {exc}"
            return None

    def click(self, col: float, row: float, shift: bool = False) -> None:
        """Left press at pixel (col, row), row 0 at the top: starts the active tool."""
        o, d = self.ray(col, row)
        s = self.session
        if self.tool == "select":
            n = self._guard("select", lambda: s.select_ray(o.tolist(), d.tolist(), self.brush_radius,
                                                           mode="add" if shift else "replace"))
            if n is not None:
                self.message = f"{n} strands selected"
        elif self.tool == "pin":
            if self._guard("select", lambda: s.select_ray(o.tolist(), d.tolist(), self.brush_radius)):
                self._guard("pin", s.unpin if shift else s.pin)
                self.message = "unpinned" if shift else "pinned"
            else:
                self.message = "pin: no strand under the cursor"
        elif self.tool == "trim":
            from taichi_hair.render import _basis

            _, f, right, up = _basis(self.camera())
            normal = np.cross(d, right)  # the plane holds the ray and the screen's horizontal
            n = self._guard("trim", lambda: s.trim(o.tolist(), normal.tolist()))
            if n is not None:
                self.message = f"trimmed {n} strands"
        elif self.tool == "drag":
            hit = self._guard("select", lambda: s.select_ray(o.tolist(), d.tolist(), self.brush_radius))
            if not hit:
                self.message = f"{self.tool}: no strand under the cursor"
                return
            anchor = s.groom.points[s.vertex_selection].astype(np.float64).mean(axis=0)
            self._drag_plane = (anchor, -d)  # a plane facing the camera through the grabbed strands
            self.message = f"{self.tool}: {hit} strands"
        elif self.tool == "comb":
            # The stroke's plane faces the camera through the strands under the cursor (the groom's
            # centre when there are none); the selection is left alone.
            p = s.groom.points.astype(np.float64)
            t = (p - o) @ d
            near = (t > 0) & (np.linalg.norm(p - o - t[:, None] * d, axis=1) <= self.brush_radius)
            anchor = p[near].mean(axis=0) if near.any() else np.asarray(self.target, np.float64)
            self._drag_plane = (anchor, -d)
            self._comb_last = self._plane_point(col, row)
            self.message = f"comb: {int(np.logical_or.reduceat(near, s.groom.strand_offsets[:-1]).sum())} strands " \
                           "under the cursor"

    def _plane_point(self, col, row):
        o, d = self.ray(col, row)
        p0, n = self._drag_plane
        den = float(np.dot(d, n))
        if abs(den) < 1e-9:
            return None
        return o + d * float(np.dot(p0 - o, n)) / den

    def move(self, col: float, row: float) -> None:
        """Mouse moved with the left button held."""
        s = self.session
        if self._drag_plane is None:
            return
        p = self._plane_point(col, row)
        if p is None:
            return
        if self.tool == "drag":
            self._guard("drag", lambda: s.drag((p - self._drag_plane[0]).tolist(), stiffness=0.5))
        elif self.tool == "comb" and self._comb_last is not None:
            q = self._comb_last
            if np.linalg.norm(p - q) >= self.brush_radius:  # a segment of about a brush radius per comb edit
                axis = self._drag_plane[1]  # the view direction: the tooth goes through the whole depth
                n = self._guard("comb", lambda: s.comb([q.tolist(), p.tolist()], self.brush_radius,
                                                       axis=axis.tolist(), length=2.0 * self.size,
                                                       friction=self.comb_friction))
                if n is not None:
                    self.message = f"comb: {n} strands combed"
                self._comb_last = p

    def release(self) -> None:
        """Left button released: ends a drag or comb stroke."""
        if self.session.dragging:
            self._guard("release", self.session.release)
        self._drag_plane = None
        self._comb_last = None

    def key(self, k: str) -> bool:
        """Apply a key (see the module docstring); returns False for escape (quit)."""
        s = self.session
        if k in "12345" and len(k) == 1:
            self.tool = TOOLS[int(k) - 1]
            self.message = f"tool: {self.tool}"
        elif k == "u":
            self._guard("undo", s.undo)
        elif k == "y":
            self._guard("redo", s.redo)
        elif k == " ":
            s.simulate(not s.simulating)
            self.message = "simulation " + ("on" if s.simulating else "off")
        elif k == "c":
            self.color_mode = COLOR_CYCLE[(COLOR_CYCLE.index(self.color_mode) + 1) % len(COLOR_CYCLE)]
        elif k in ("g", "h"):
            self._guard("scale_length", lambda: s.scale_length(1.2 if k == "g" else 0.8))
        elif k in ("k", "l"):
            self._guard("scale_curl", lambda: s.scale_curl(1.25 if k == "k" else 0.8))
        elif k == "a":
            s.select_all()
        elif k == "s":
            self.save()
        elif k == "r":
            if self.groom_path is None:
                self.message = "reload: the groom was generated, not read from a file"
            else:
                self.open(self.groom_path)
        elif k in ("-", "="):
            self.zoom(1.1 if k == "-" else 1 / 1.1)
        elif k == "p":
            self.screenshot_requested = True  # taken by the window loop after the frame is drawn
        elif k == "Escape":
            return False
        return True

    def save(self) -> None:
        if self.save_path is None:
            self.message = "save: no path (open a groom file, or pass --autosave)"
            return
        try:
            self.session.save(self.save_path)
            log = self.save_path[: -len(".thair.npz")] if self.save_path.endswith(".thair.npz") else self.save_path
            self.session.write_log(log + ".session.json")
            self.message = f"saved {self.save_path} and {log}.session.json"
        except (OSError, ValueError) as exc:
            self.message = f"save: {exc}"

    def open(self, path) -> bool:
        """Load another groom; on failure keep the current one and show the loader's message."""
        from taichi_hair.groom.session import GroomingSession

        try:
            new = self.make_session(path) if self.make_session else GroomingSession.open(path)
        except (OSError, ValueError) as exc:
            self.message = f"open: {exc}"
            return False
        self.session = new
        self.save_path = new.autosave_path
        self._error_cache = None
        self.message = f"opened {path}"
        return True

    # ------------------------------------------------------------------ frames
    def colors(self):
        from taichi_hair.render import strand_colors

        g = self.session.groom
        if self.color_mode == "error":
            key = (g.points.tobytes().__hash__(), g.vertex_count)
            if self._error_cache is None or self._error_cache[0] != key:
                self._error_cache = (key, _interpolation_error(self.session))
            values = self._error_cache[1]
            return strand_colors(g, "error", values, selection=self.session.vertex_selection)
        # Colours change with the groom object (every edit makes a new one), the mode or the selection: not per
        # frame (86,000 strands: 21-46 ms each time, and the viewer uploads them only when they change).
        sel = self.session.vertex_selection
        key = (self.color_mode, None if sel is None else hash(np.asarray(sel).tobytes()))
        if self._color_cache is None or self._color_cache[0] != key or self._color_cache[1] is not g:
            self._color_cache = (key, g, strand_colors(g, self.color_mode, selection=sel))
        return self._color_cache[2]

    def update_view(self) -> None:
        g = self.session.groom
        self.viewer.set_camera(self.camera())
        self.viewer.set_strands(g.points, g.strand_offsets, self.colors())
        pinned = g.points[g.pinned] if g.pinned is not None else np.zeros((0, 3))
        self.viewer.set_points(pinned, radius=0.004 * self.size)

    def frame(self) -> None:
        """One displayed frame: a quasistatic step of the session (if on), then draw.

        The very first frame only draws: the first step builds the simulation and loads or compiles its
        kernels (~8 s with a warm kernel cache on 2 CPU cores, measured), and the groom should be on screen,
        with a message saying so, before that happens."""
        t0 = time.perf_counter()
        first = self.frames_drawn == 0
        if self.session.simulating and not first:
            self.session.advance(1)
            if self.frames_simulated == 0:
                print("first simulated frame", flush=True)
                self.message = "ready"
            self.frames_simulated += 1
        elif self.session.simulating:
            self.message = "building the simulation (kernels compile on first use)..."
        t1 = time.perf_counter()
        self.update_view()
        self.viewer.render()
        self.sim_ms = 1e3 * (t1 - t0)
        self.frame_ms = 1e3 * (time.perf_counter() - t0)
        self.frames_drawn += 1


def _interpolation_error(session) -> np.ndarray:
    """Per-strand distance between each strand and its skinned reconstruction from the session's guides
    (0 on guides; see ``groom_cli.skinning_error``) [m]."""
    from taichi_hair.cli.groom import skinning_error

    c = session.config
    return skinning_error(session.groom, c.guide_ratio, c.neighbour_count, c.seed)


# =========================================================================== the window loop
def _panel(app, window):
    gui = window.get_gui()
    s = app.session
    with gui.sub_window("taichi-hair groom", 0.0, 0.0, 0.28, 0.62) as w:
        w.text(f"frame {app.frame_ms:.1f} ms (simulation {app.sim_ms:.1f} ms)")
        w.text(f"{s.groom.strand_count} strands, {s.guide_strands.size} simulated")
        if s.built and s.config.contacts:
            q = s.quality(full=False)  # the last step's hair pairs (no pass over the groom)
            w.text(f"hair pairs: {q.get('crossed_pairs', 0)} crossed, deepest "
                   f"{1e6 * q.get('hair_penetration_max_m', 0.0):.0f} um ({q.get('contacts', 0)} contacts)")
        w.text(f"tool: {app.tool}  (1-5)")
        for i, t in enumerate(TOOLS):
            if w.button(f"{i + 1} {t}"):
                app.tool = t
        app.brush_radius = w.slider_float("brush [m]", app.brush_radius, 0.001 * app.size, 0.2 * app.size)
        it = w.slider_int("iterations", s.config.iterations, 1, 50)
        if it != s.config.iterations:
            app._guard("set_parameter", lambda: s.set_parameter("iterations", it))
        app.comb_friction = w.slider_float("comb friction", app.comb_friction, 0.0, 1.0)
        fr = w.slider_float("friction", s.config.friction, 0.0, 1.0)
        if abs(fr - s.config.friction) > 1e-6:
            app._guard("set_parameter", lambda: s.set_parameter("friction", fr))
        gy = w.slider_float("gravity y", s.config.gravity[1], -20.0, 20.0)
        if abs(gy - s.config.gravity[1]) > 1e-6:
            app._guard("set_parameter", lambda: s.set_parameter("gravity", [s.config.gravity[0], gy, s.config.gravity[2]]))
        le = w.slider_float("log10 E [Pa]", math.log10(s.config.youngs_modulus), 7.0, 11.0)
        if abs(le - math.log10(s.config.youngs_modulus)) > 1e-3:
            app._guard("set_parameter", lambda: s.set_parameter("youngs_modulus", 10.0 ** le))
        sim = w.checkbox("simulate (space)", s.simulating)
        if sim != s.simulating:
            s.simulate(sim)
        for label, k in (("grow x1.2 (g)", "g"), ("shorten x0.8 (h)", "h"), ("curl x1.25 (k)", "k"),
                         ("uncurl x0.8 (l)", "l"), ("undo (u)", "u"), ("redo (y)", "y"), ("select all (a)", "a"),
                         ("colours (c)", "c"), ("save (s)", "s"), ("reload file (r)", "r")):
            if w.button(label):
                app.key(k)
        w.text(f"colours: {app.color_mode}")
        w.text(app.message[:90])


def run_window(args) -> int:
    """The window of ``taichi-hair groom [GROOM]`` (arguments of ``taichi_hair.cli.groom``)."""
    import taichi as ti

    from taichi_hair.cli.common import _init_taichi
    from taichi_hair.cli.groom import head_colliders, load_groom_arg, load_head_mesh, session_config
    from taichi_hair.groom.session import GroomingSession
    from taichi_hair.io import load_groom
    from taichi_hair.render import ViewerGGUI

    from taichi_hair.cli.common import CLIError

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise CLIError("no display for the window (DISPLAY is not set); replay a session off screen with "
                       "--offscreen --script SESSION.json --out DIR")
    groom = load_groom_arg(args)
    head = load_head_mesh(args.head)
    cfg = session_config(groom, args)
    _init_taichi(args.arch, "f32")
    if args.autosave:
        autosave = args.autosave
    elif args.groom not in (None, "default"):
        base = os.path.splitext(args.groom[: -len(".npz")] if args.groom.endswith(".npz") else args.groom)[0]
        autosave = base + ".autosave.thair.npz"
    else:
        autosave = os.path.abspath("groom.autosave.thair.npz")
    session = GroomingSession(groom, cfg, colliders=head_colliders(head, cfg.contacts), autosave_path=autosave)

    def make_session(path):
        g = load_groom(path)
        return GroomingSession(g, session_config(g, args), colliders=head_colliders(head, cfg.contacts),
                               autosave_path=os.path.splitext(str(path))[0] + ".autosave.thair.npz")

    w, h = args.size
    try:
        viewer = ViewerGGUI(w, h, show_window=True, title="taichi-hair groom")
    except RuntimeError as exc:
        raise CLIError(f"cannot open the window ({exc}); use --offscreen --script SESSION.json --out DIR") from None
    app = GroomApp(session, viewer, head, save_path=autosave, make_session=make_session,
                   groom_path=None if args.groom in (None, "default") else args.groom)
    window = viewer.window
    last = None
    shown = False
    print(f"autosave: {autosave} (and its .session.json); compiling the kernels for the first frame can take "
          "a minute", flush=True)
    while window.running:
        for e in window.get_events(ti.ui.PRESS):
            if e.key == ti.ui.ESCAPE:
                window.running = False
            elif e.key == ti.ui.LMB:
                x, y = window.get_cursor_pos()
                if x > 0.28 or y < 0.38:  # not on the panel
                    app.click(x * w, (1 - y) * h, shift=window.is_pressed(ti.ui.SHIFT))
            elif isinstance(e.key, str) and len(e.key) == 1:
                app.key(e.key.lower())
        for e in window.get_events(ti.ui.RELEASE):
            if e.key == ti.ui.LMB:
                app.release()
        x, y = window.get_cursor_pos()
        if last is not None:
            dx, dy = x - last[0], y - last[1]
            if window.is_pressed(ti.ui.RMB) and not window.is_pressed(ti.ui.SHIFT):
                app.orbit(dx, dy)
            elif window.is_pressed(ti.ui.MMB) or (window.is_pressed(ti.ui.RMB) and window.is_pressed(ti.ui.SHIFT)):
                app.pan(dx, dy)
            elif window.is_pressed(ti.ui.LMB):
                app.move(x * w, (1 - y) * h)
        last = (x, y)
        app.frame()
        _panel(app, window)
        if getattr(app, "screenshot_requested", False):
            from taichi_hair.render import save_png

            app.screenshot_requested = False
            shot = autosave[: -len(".thair.npz")] + ".screenshot.png" if autosave.endswith(".thair.npz") \
                else autosave + ".screenshot.png"
            save_png(shot, viewer.image())
            app.message = f"screenshot: {shot}"
            print(f"screenshot {shot}", flush=True)
        window.show()
        if not shown:
            shown = True
            print("window ready", flush=True)  # the first frame is on screen (tests wait for this line)
    app.session.autosave()
    print(f"autosaved {autosave}")
    return 0


def main(argv=None) -> int:
    from taichi_hair.cli.groom import register

    p = argparse.ArgumentParser(prog="apps/groom.py")
    sub = p.add_subparsers(dest="command")
    register(sub)
    args = p.parse_args(["groom"] + list(sys.argv[1:] if argv is None else argv))
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
