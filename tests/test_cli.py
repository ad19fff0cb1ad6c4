"""The paroct command: mesh -> file -> check round trip, exit codes, one-line errors."""

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import manifold3d
import meshio
import numpy as np
import pytest

import paroct
import paroct.mesher
from paroct.cli import main
from paroct.io import write_mesh
from paroct.lattice import leaf_tets

DATA = Path(__file__).resolve().parent.parent / "data"

BOX = (1.0, 0.8, 0.6)
BOX_ROTATION = (10.0, 20.0, 30.0)


def _surface_arrays(solid=None):
    solid = solid or manifold3d.Manifold.cube(list(BOX)).rotate(list(BOX_ROTATION))
    m = solid.to_mesh64()
    return np.asarray(m.vert_properties)[:, :3].copy(), np.asarray(m.tri_verts).astype(np.int64)


def _write_surface(path, vertices=None, faces=None):
    """An ASCII STL (or other meshio surface format, by extension) of the rotated box by default."""
    if vertices is None:
        vertices, faces = _surface_arrays()
    with np.errstate(invalid="ignore", divide="ignore"):  # meshio's STL normals of NaN input
        options = {"binary": False} if str(path).endswith(".stl") else {}
        meshio.write(path, meshio.Mesh(vertices, [("triangle", faces)]), **options)
    return path


def _binary_box_bytes(tmp_path):
    path = tmp_path / "binary_box.stl"
    vertices, faces = _surface_arrays()
    meshio.write(path, meshio.Mesh(vertices, [("triangle", faces)]), binary=True)
    return path.read_bytes()


def _block(n=2):
    g = np.arange(n)
    anchors = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = leaf_tets(anchors, np.ones(len(anchors), dtype=np.int64))
    return coords.astype(float), tets.astype(np.int64)


def _run(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _assert_one_line_error(rc, out, err, match):
    assert rc == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("paroct: error: "), err
    assert "Traceback" not in err
    assert re.search(match, err), err


def test_mesh_writes_a_vtu_that_checks_ok(tmp_path, capsys):
    stl = _write_surface(tmp_path / "box.stl")
    out = tmp_path / "box_mesh.vtu"
    rc, text, err = _run(capsys, "mesh", stl, "-o", out, "--size", 0.1)
    assert rc == 0, err
    written = meshio.read(out)
    tets = np.concatenate([b.data for b in written.cells if b.type == "tetra"])
    n_tets = int(re.search(r": (\d+) tets, (\d+) vertices", text).group(1))
    assert n_tets == len(tets) > 0
    # Signed volumes from the file: all positive, total close to the box's.
    p = written.points[tets]
    vols = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6
    assert vols.min() > 0 and vols.sum() == pytest.approx(np.prod(BOX), rel=0.05)
    assert re.search(r"^time \d+\.\d+ s$", text, re.M)

    rc, report, err = _run(capsys, "check", out, "--against", stl)
    assert rc == 0, report
    assert report.splitlines()[-1] == "ok"
    hausdorff = float(re.search(r"Hausdorff distance (\S+) x diagonal", report).group(1))
    assert hausdorff < 0.1 / np.linalg.norm(BOX)  # the boundary is within one element size of the surface


def test_default_output_is_the_surface_stem_in_the_current_folder(tmp_path, capsys, monkeypatch):
    (tmp_path / "in").mkdir()
    (tmp_path / "work").mkdir()
    stl = _write_surface(tmp_path / "in" / "part.stl")
    monkeypatch.chdir(tmp_path / "work")
    rc, out, err = _run(capsys, "mesh", stl, "--divisions", 8, "--quiet")
    assert rc == 0, err
    assert out == ""  # --quiet
    assert (tmp_path / "work" / "part.vtu").is_file() and not (tmp_path / "in" / "part.vtu").exists()


def test_verbose_reports_stages_as_they_end_and_their_times(tmp_path, capsys):
    stl = _write_surface(tmp_path / "box.stl")
    rc, out, err = _run(capsys, "mesh", stl, "-o", tmp_path / "a.vtu", "--divisions", 8, "--verbose")
    assert rc == 0, err
    done = re.findall(r"^paroct: (\w+) done$", err, re.M)
    timed = re.findall(r"^  (\w+) +\d+\.\d+ s$", out, re.M)
    assert done and set(done) <= set(timed) and "write" in timed
    from paroct.memory import start_peak_count

    if start_peak_count() is not None:  # Linux: the peak of the run is measured
        assert re.search(r"^peak memory \d+\.\d MiB above the start, \d+ bytes per tet \(kernels loaded included\)$",
                         out, re.M)
    rc, out, err = _run(capsys, "mesh", stl, "-o", tmp_path / "b.vtu", "--divisions", 8)
    assert rc == 0
    assert "done" not in err and not re.search(r"^  \w+ +\d", out, re.M)
    assert re.search(r"^time \d+\.\d+ s$", out, re.M)
    # Same input, same options: the same bytes.
    assert (tmp_path / "a.vtu").read_bytes() == (tmp_path / "b.vtu").read_bytes()


def test_verbose_load_time_includes_the_surface_the_cli_loaded(tmp_path, capsys):
    from paroct.cli import format_mesh_summary

    stl = _write_surface(tmp_path / "box.stl")
    report = paroct.mesh(stl, divisions=8).report
    report.stage_seconds.update(load=0.125, octree=1.0)
    text = format_mesh_summary(report, "out.vtu", mesh_seconds=2.0, write_seconds=0.5, verbose=True, load_seconds=0.25)
    assert "  load          0.375 s" in text.splitlines() and "  octree        1.000 s" in text.splitlines()
    assert text.splitlines()[-1] == "time 2.500 s"
    assert "peak memory" not in text  # not measured


def test_verbose_summary_reports_peak_memory_per_tet(tmp_path):
    from paroct.cli import format_mesh_summary

    report = paroct.mesh(_write_surface(tmp_path / "box.stl"), divisions=8).report
    text = format_mesh_summary(report, "out.vtu", mesh_seconds=1.0, write_seconds=0.5, verbose=True,
                               peak_bytes=3 * 2**20)
    line = f"peak memory 3.0 MiB above the start, {3 * 2**20 / report.n_tets:.0f} bytes per tet (kernels loaded included)"
    assert line in text.splitlines()
    assert "peak memory" not in format_mesh_summary(report, "out.vtu", 1.0, 0.5, verbose=False, peak_bytes=3 * 2**20)


def test_mesher_warnings_are_one_line_each_on_stderr(tmp_path, capsys, monkeypatch):
    real = paroct.mesher.mesh

    def warned(*args, **kwargs):
        result = real(*args, **kwargs)
        result.report.warnings.extend(["the fin was lost", "two\nlines"])
        return result

    monkeypatch.setattr(paroct.mesher, "mesh", warned)
    stl = _write_surface(tmp_path / "box.stl")
    rc, out, err = _run(capsys, "mesh", stl, "-o", tmp_path / "a.vtu", "--divisions", 8)
    assert rc == 0
    lines = err.splitlines()
    assert "paroct: warning: the fin was lost" in lines and "paroct: warning: two; lines" in lines
    assert "paroct: warning" not in out


def test_interrupt_exits_130(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(paroct.mesher, "mesh", interrupted)
    rc, out, err = _run(capsys, "mesh", _write_surface(tmp_path / "box.stl"))
    assert rc == 130 and err == "paroct: interrupted\n" and "Traceback" not in err


def test_bad_output_is_refused_before_meshing(tmp_path, capsys, monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("meshed although the output was bad")

    monkeypatch.setattr(paroct.mesher, "mesh", never)
    stl = _write_surface(tmp_path / "box.stl")
    (tmp_path / "folder.vtu").mkdir()
    for out, match in [("out.xyz", "unknown mesh format"), ("out.stl", "surfaces only"), ("no/such/out.vtu", "does not exist"),
                       ("folder.vtu", "is a folder")]:
        _assert_one_line_error(*_run(capsys, "mesh", stl, "-o", tmp_path / out), match)
    _assert_one_line_error(*_run(capsys, "mesh", stl, "-o", tmp_path / "out.node", "--patches"), "hold no boundary patches")
    _assert_one_line_error(*_run(capsys, "mesh", stl, "-o", ""), "-o '': give a file name")
    missing = next((ext for ext, fmt in [(".xdmf", "h5py"), (".med", "h5py"), (".exo", "netCDF4")]
                    if importlib.util.find_spec(fmt) is None), None)
    if missing:  # a writer's package, asked for before meshing
        _assert_one_line_error(*_run(capsys, "mesh", stl, "-o", tmp_path / f"out{missing}"), "needs the package")


def _written(path, data: bytes):
    path.write_bytes(data)
    return path


def _open_box(tmp_path):
    v, f = _surface_arrays()
    return _write_surface(tmp_path / "open.stl", v, f[1:])


def _nan_box(tmp_path):
    v, f = _surface_arrays()
    v[0, 0] = np.nan
    return _write_surface(tmp_path / "nan.stl", v, f)


def _scaled_box(tmp_path, scale):
    v, f = _surface_arrays()
    return _write_surface(tmp_path / "scaled.obj", v * scale, f)


def _inside_out_box(tmp_path):
    v, f = _surface_arrays()
    return _write_surface(tmp_path / "inside_out.stl", v, f[:, ::-1])


def test_an_inside_out_surface_is_meshed_turned_with_a_warning(tmp_path, capsys):
    """One closed shell bounds one solid whichever way its triangles face: turned, it is meshed,
    and the warning says what was mended."""
    out = tmp_path / "out.vtu"
    rc, text, err = _run(capsys, "mesh", _inside_out_box(tmp_path), "-o", out, "--size", 0.1)
    assert rc == 0 and out.exists() and "solid 0.48 " in text
    assert "warning: " in err and "inside_out.stl: the surface was inside out (its triangles faced in): all 12 turned" in err


def _unknown_extension(tmp_path):
    path = tmp_path / "part.xyz"
    path.write_text("1 2 3\n")
    return path


@pytest.mark.parametrize(
    "make_args,match",
    [
        (lambda t, s: ["mesh", t / "missing.stl"], "no such file"),
        (lambda t, s: ["mesh", _unknown_extension(t)], "unknown surface format '.xyz'"),
        (lambda t, s: ["mesh", _open_box(t)], r"open surface, \d+ boundary edges"),
        (lambda t, s: ["mesh", _nan_box(t)], "NaN"),
        (lambda t, s: ["mesh", _scaled_box(t, 1e110)], r"coordinate reaches 1.\d+e\+110; .* up to 1e\+100 .* scale the part"),
        (lambda t, s: ["mesh", _scaled_box(t, 1e-110)], r"spans only 1.39e-110 \(longest side of its bounding box\); .* 1e-100 or more .* scale the part"),
        (lambda t, s: ["mesh", _written(t / "cut.stl", b"solid x\nfacet normal 0 0 1\n")], "cannot read .* as STL"),
        (lambda t, s: ["mesh", _written(t / "none.stl", bytes(84))], "empty surface"),
        (lambda t, s: ["mesh", _written(t / "cut.stl", _binary_box_bytes(t)[:-30])],
         r"cannot read .*cut.stl as STL: neither ASCII STL .* complete binary STL: 654 bytes, its header says 12 triangles \(84 \+ 50 x 12 = 684 bytes\)"),
        (lambda t, s: ["mesh", _written(t / "noise.stl", np.random.default_rng(0).bytes(1000))], "not an STL file"),
        (lambda t, s: ["mesh", _written(t / "tiny.stl", b"\x00\x01")], "neither ASCII STL .* 2 bytes;"),
        (lambda t, s: ["mesh", s, "--size", "0"], "size = 0"),
        (lambda t, s: ["mesh", s, "--size", "-1"], "size = -1"),
        (lambda t, s: ["mesh", s, "--size", "nan"], "size = nan"),
        (lambda t, s: ["mesh", s, "--divisions", "0"], "divisions = 0"),
        (lambda t, s: ["mesh", s, "--size", "abc"], "invalid float value: 'abc'"),
        (lambda t, s: ["mesh", s, "--size", "1", "--divisions", "3"], "not allowed with"),
        (lambda t, s: ["mesh", s, "--max-memory", "0"], "--max-memory 0"),
        (lambda t, s: ["mesh", s, "--max-memory", "1e300"], r"--max-memory 1e\+300: must be a positive number"),
        (lambda t, s: ["mesh", s, "--size", "1e-4", "--max-memory", "1"], "GiB"),
        (lambda t, s: ["mesh", s, "-o", t / "out.xyz"], "unknown mesh format"),
        (lambda t, s: ["mesh", s, "--max-size", "1e-9"], "max_size = 1e-09 must be at least size"),
        (lambda t, s: ["mesh", s, "--max-size", "2", "--uniform"], "not allowed with"),
        (lambda t, s: ["mesh", s, "--refine-sphere", "0", "0", "0", "1", "-1"], "region size = -1"),
        (lambda t, s: ["mesh", s, "--refine-box", "1", "1", "1", "0", "0", "0", "0.1"], "exceeds hi"),
        (lambda t, s: ["mesh", s, "--min-size", "0"], "min_size = 0"),
        (lambda t, s: ["mesh", s, "--threads", "0"], r"--threads 0: must be from 1 to \d+"),
        (lambda t, s: ["mesh", s, "--threads", "100000"], r"--threads 100000: must be from 1 to \d+"),
        (lambda t, s: ["mesh", s, "--threads", "1.5"], "invalid int value: '1.5'"),
        (lambda t, s: ["mesh"], "required: SURFACE"),
        (lambda t, s: [], "choose a command"),
        (lambda t, s: ["frobnicate"], "invalid choice"),
        (lambda t, s: ["check", t / "missing.vtu"], "no such file"),
        (lambda t, s: ["check", s], "no tetrahedra"),
        (lambda t, s: ["check", _written(t / "cut.vtu", (t / "good.vtu").read_bytes()[:400])],
         r"cannot read .*cut.vtu: not a vtu file, or a damaged one$"),
        (lambda t, s: ["check", _written(t / "cut.msh", b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4")],
         r"cannot read .*cut.msh as Gmsh MSH: section \$Nodes has no \$EndNodes$"),
        (lambda t, s: ["check", t / "good.vtu", "--against", _open_box(t)], "open surface"),
    ],
)
def test_user_errors_are_one_line_with_exit_2(tmp_path, capsys, make_args, match):
    stl = _write_surface(tmp_path / "box.stl")
    points, tets = _block()
    write_mesh(tmp_path / "good.vtu", points, tets)
    _assert_one_line_error(*_run(capsys, *make_args(tmp_path, stl)), match)


def test_a_surface_past_the_triangle_limit_is_one_line_with_exit_2(tmp_path, capsys, monkeypatch):
    """The weld numbers corners in int32: more than surface.MAX_FACES triangles (lowered here:
    a real one would be a 36 GB STL) are refused up front, not by the kernel."""
    import paroct.surface

    stl = _write_surface(tmp_path / "box.stl")
    monkeypatch.setattr(paroct.surface, "MAX_FACES", 10)
    _assert_one_line_error(*_run(capsys, "mesh", stl), r"len\(faces\) = 12; paroct reads surfaces of at most 10 triangles")


def test_check_passes_a_valid_mesh_and_fails_broken_ones(tmp_path, capsys):
    points, tets = _block(3)
    write_mesh(tmp_path / "good.vtu", points, tets)
    rc, out, _ = _run(capsys, "check", tmp_path / "good.vtu")
    assert rc == 0 and out.splitlines()[-1] == "ok"
    # .msh is Gmsh's and ANSYS's: an ANSYS file is read too.
    meshio.write(tmp_path / "ansys.msh", meshio.Mesh(points, [("tetra", tets)]), file_format="ansys")
    rc, out, _ = _run(capsys, "check", tmp_path / "ansys.msh")
    assert rc == 0 and out.splitlines()[-1] == "ok" and "tets 162," in out

    flipped = tets.copy()
    flipped[0, [0, 1]] = flipped[0, [1, 0]]
    write_mesh(tmp_path / "inverted.vtu", points, flipped)
    rc, out, _ = _run(capsys, "check", tmp_path / "inverted.vtu")
    assert rc == 1
    assert "FAIL: 1 of 162 tets are inverted or flat (signed volume <= 0)" in out.splitlines()

    # Two tets sharing only an edge: the boundary is not a manifold.
    pts = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    write_mesh(tmp_path / "bowtie.msh", pts, np.array([[0, 2, 3, 1], [0, 4, 5, 1]]))
    rc, out, _ = _run(capsys, "check", tmp_path / "bowtie.msh")
    assert rc == 1
    assert any(line.startswith("FAIL: boundary not closed and manifold: 1 of its edges") for line in out.splitlines())


def test_paper_table_command(capsys):
    rc, out, err = _run(capsys, "paper-table")
    assert rc == 0 and err == ""
    assert "0.948683" in out and "Errata:" in out


def test_version_and_help(capsys):
    rc, out, _ = _run(capsys, "--version")
    assert rc == 0 and out.strip() == f"paroct {paroct.__version__}"
    rc, out, _ = _run(capsys, "mesh", "--help")
    assert rc == 0 and "--divisions" in out


def test_python_dash_m_paroct(tmp_path):
    done = subprocess.run([sys.executable, "-m", "paroct", "--version"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.strip() == f"paroct {paroct.__version__}"
    done = subprocess.run([sys.executable, "-m", "paroct", "mesh", "missing.stl"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr == "paroct: error: no such file: missing.stl\n"
    # In a real process (no pytest warning capture), reading an ASCII STL adds no warning lines.
    _open_box(tmp_path)
    done = subprocess.run([sys.executable, "-m", "paroct", "mesh", "open.stl"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.startswith("paroct: error: open.stl: open surface")
    assert done.stderr.count("\n") == 1, done.stderr


def test_grading_options_change_the_mesh(tmp_path, capsys):
    stl = DATA / "bunny.stl"
    counts = {}
    for name, extra in [("graded", []), ("uniform", ["--uniform"]), ("coarse", ["--max-size", "1"]),
                        ("sphere", ["--max-size", "1", "--refine-sphere", "-0.02", "0.1", "0", "0.03", "0.001"])]:
        rc, out, err = _run(capsys, "mesh", stl, "--divisions", "60", "-o", tmp_path / f"{name}.vtu", *extra)
        assert rc == 0, err
        counts[name] = int(re.search(r"(\d+) tets", out).group(1))
        levels = int(re.search(r"\((\d+) leaf levels\)", out).group(1))
        assert (levels == 1) == (name == "uniform")
    assert counts["uniform"] > counts["graded"] > 0
    assert counts["sphere"] > counts["coarse"]


def test_threads_give_the_same_file_and_leave_numbas_count_as_it_was(tmp_path, capsys):
    """--threads 1 writes the same bytes as every thread (the kernels' chunks do not depend on
    the thread count), and main() restores numba's thread count for the process after."""
    import numba

    before = numba.get_num_threads()
    stl = DATA / "angle_block.stl"
    assert _run(capsys, "mesh", stl, "-o", tmp_path / "all.msh", "--patches")[0] == 0
    assert _run(capsys, "mesh", stl, "-o", tmp_path / "one.msh", "--patches", "--threads", "1")[0] == 0
    assert numba.get_num_threads() == before
    assert (tmp_path / "one.msh").read_bytes() == (tmp_path / "all.msh").read_bytes()


@pytest.mark.parametrize("env, want", [({}, "PASSIVE"), ({"OMP_WAIT_POLICY": "ACTIVE"}, "ACTIVE"),
                                       ({"GOMP_SPINCOUNT": "10000"}, None)])
def test_the_program_lets_idle_threads_sleep_unless_told_otherwise(monkeypatch, env, want):
    """console_main (the paroct program) asks OpenMP to let idle threads sleep, so that runs
    side by side share the cores (two spinning runs took 720 ms a call each where one took
    24), but keeps what the environment says."""
    import paroct.cli as cli

    for name in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    seen = {}

    def main(argv=None):
        seen["policy"] = os.environ.get("OMP_WAIT_POLICY")
        return 0

    monkeypatch.setattr(cli, "main", main)
    assert cli.console_main() == 0
    assert seen["policy"] == want


def test_status_line_shows_long_runs_only_and_is_erased_before_other_output(monkeypatch):
    """On a terminal a run says which stage ended once it has taken StatusLine.SHOW_AFTER
    seconds, on one line rewritten in place; a message erases the line first, so nothing is
    printed after it on the same line."""
    import io

    from paroct import cli

    now = [0.0]
    stream = io.StringIO()
    status = cli.StatusLine(stream, clock=lambda: now[0])
    status("load")  # at 0 s: a short run shows nothing
    now[0] = 0.5
    status("octree")
    assert stream.getvalue() == "" and not status.shown
    now[0] = 1.25
    status("stuff")
    assert stream.getvalue() == "\r\x1b[Kparoct: stuff done (1.2 s)" and status.shown
    now[0] = 2.0
    status.show("writing part.vtu")
    assert stream.getvalue().endswith("\r\x1b[Kparoct: writing part.vtu (2.0 s)")
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(cli, "_status", status)
    cli._err("warning: something")
    assert stream.getvalue().endswith("\r\x1b[K") and not status.shown
    assert err.getvalue() == "paroct: warning: something\n"
    status.clear()  # nothing shown: nothing to erase
    assert stream.getvalue().endswith("(2.0 s)\r\x1b[K")
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal: no status line at all
    with cli._terminal_status(True) as off:
        assert off is None and cli._status is None
