"""The command line's rough edges closed: absurd sizes refused before allocation with the estimate, bad
values one line, warnings one clean line naming the file and strand, ``--version``."""

import time

import numpy as np
import pytest

from taichi_hair.cli.main import main
from taichi_hair.io import Groom, geometry_warnings, save_groom


def test_an_absurd_strand_count_is_refused_at_once_with_the_estimate(capsys):
    """1e8 strands of 41 vertices: ~1.2 kB each = ~5 TB, refused in well under a second of work (bound 20 s:
    a shared VM) and before ti.init (nothing compiled, nothing allocated)."""
    t0 = time.perf_counter()
    rc = main(["simulate", "hang", "--strands", "100000000", "--out", "/tmp/never-written"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and time.perf_counter() - t0 < 20.0
    assert "4,100,000,000 vertices" in err and "needs an estimated" in err and "TB" in err and "\n" not in err


def test_a_generator_refuses_a_groom_too_large_for_memory():
    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, sphere_surface

    with pytest.raises(ValueError, match="generating 1,000,000,000 strands .* needs an estimated"):
        generate_groom(sphere_surface(0.09), GeneratorConfig(strands=10 ** 9, vertices_per_strand=16))


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("taichi-hair ")


def _lines(radius=5e-5, first_edge=5e-3):
    t = np.linspace(0.0, 0.1, 11)
    lines = [np.c_[0.01 * k + 0 * t, -t, 0 * t] for k in range(3)]
    lines[2][1, 1] = lines[2][0, 1] - first_edge
    return Groom.from_polylines(lines, radius=np.full(3, radius), units="m")


def test_implausible_radii_and_degenerate_edges_are_named_by_strand():
    """Radius 0.5 mm (a .hair file's default thickness 1 mm): outside 5-250 um; strand 2's first edge 10 um:
    shorter than 20 um.  A plausible groom gives no warning."""
    assert geometry_warnings(_lines()) == []
    (w,) = geometry_warnings(_lines(radius=5e-4), "g.hair")
    assert w.startswith("g.hair: strand 0: radius 500 um is implausible") and "3 strands" in w
    (w,) = geometry_warnings(_lines(first_edge=1e-5), "g.hair")
    assert w.startswith("g.hair: strand 2: edge 0 is 10 um long") and "1 edges shorter than 20 um" in w


def test_warnings_are_one_clean_line_naming_the_file(tmp_path, capsys):
    """Not Python's 'file:line: UserWarning' with a line of source code."""
    p = tmp_path / "thick.hair"
    save_groom(_lines(radius=5e-4), p)
    assert main(["info", str(p)]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert err and all(ln.startswith("warning: ") for ln in err), err
    assert any(str(p) in ln and "radius" in ln for ln in err) and not any("UserWarning" in ln for ln in err)


def test_more_strands_than_the_file_has_is_said(tmp_path):
    from taichi_hair.scene.file import load_scene

    s = tmp_path / "s.toml"
    s.write_text('[groom]\nfile = "%s"\nscale = 0.0035\nstrands = 10000\n'
                 % (str(__import__("os").path.abspath("assets/ponytail/tail.tfx"))))
    with pytest.warns(UserWarning, match=r"10,000 asked, the file has 255; simulating all of them"):
        scene = load_scene(s)
    assert scene.groom.strand_count == 255


def test_a_usc_data_file_is_labelled_metres_only_when_its_size_is_hair_in_metres(tmp_path):
    # USC-HairSalon's format carries no unit: a 20 cm strand stored in metres reads as "m"; the same groom
    # stored in centimetres (a median of 20 "m") keeps unknown units and warns, instead of a wrong label.
    import warnings

    from taichi_hair.io import load_groom

    t = np.linspace(0.0, 0.2, 9)
    pts = np.concatenate([np.stack([np.full(9, 0.01 * s), -t, np.zeros(9)], axis=1) for s in range(20)])
    g = Groom(points=pts.astype(np.float32), strand_offsets=np.arange(0, 181, 9))
    save_groom(g, tmp_path / "m.data")
    save_groom(g.scaled(100.0), tmp_path / "cm.data")
    assert load_groom(tmp_path / "m.data").units == "m"
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        cm = load_groom(tmp_path / "cm.data")
    assert cm.units == "" and any("centimetres" in str(x.message) for x in w)
    assert load_groom(tmp_path / "cm.data", scale=0.01).units == "m"
