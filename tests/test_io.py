"""Mesh output: paroct's own .vtu writer against meshio's reader and a plain decoder."""

from __future__ import annotations

import base64
import xml.etree.ElementTree as ET
import zlib

import meshio
import numpy as np
import pytest

from paroct.errors import ParoctError
from paroct.io import VTU_BLOCK_BYTES, _int_lines, read_mesh, write_mesh


def _random_mesh(seed: int, n_points: int, n_tets: int):
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=10.0 ** rng.integers(-300, 300, size=(n_points, 1)), size=(n_points, 3))
    points[:4] = [[0.0, -0.0, 1e-310], [np.pi, -np.e, 1e300], [1, 2, 3], [-1, -2, -3]]
    tets = rng.integers(0, n_points, size=(n_tets, 4))
    return points, tets


def _decode_vtu(path):
    """A plain reader of compressed inline .vtu arrays: name -> (dtype name, raw bytes)."""
    root = ET.parse(path).getroot()
    assert root.get("compressor") == "vtkZLibDataCompressor" and root.get("header_type") == "UInt64"
    arrays = {}
    for node in root.iter("DataArray"):
        text = node.text.strip()
        n_blocks = int(np.frombuffer(base64.b64decode(text[:12])[:8], "<u8")[0])
        header_chars = 4 * -(-8 * (3 + n_blocks) // 3)
        header = np.frombuffer(base64.b64decode(text[:header_chars]), "<u8")
        assert len(header) == 3 + n_blocks and header[1] == VTU_BLOCK_BYTES
        blob = base64.b64decode(text[header_chars:])
        assert len(blob) == header[3:].sum()
        ends = np.cumsum(header[3:])
        blocks = [zlib.decompress(blob[a:b]) for a, b in zip(np.r_[0, ends[:-1]], ends)]
        assert all(len(b) == VTU_BLOCK_BYTES for b in blocks[:-1]) and len((blocks or [b""])[-1]) == header[2]
        arrays[node.get("Name")] = (node.get("type"), b"".join(blocks))
    return arrays


def test_vtu_round_trips_exactly_through_meshio_and_a_plain_decoder(tmp_path):
    points, tets = _random_mesh(7, 5000, 20000)  # connectivity spans several blocks
    tag = (np.arange(len(tets)) % 5).astype(np.int32)
    quality = np.linspace(0, 1, len(tets))
    path = tmp_path / "m.vtu"
    write_mesh(path, points, tets, {"tag": tag, "quality": quality})

    back = meshio.read(path)
    assert np.array_equal(back.points, points)  # bit for bit, -0.0 and subnormals included
    assert np.array_equal(np.signbit(back.points), np.signbit(points))
    assert [b.type for b in back.cells] == ["tetra"] and np.array_equal(back.cells[0].data, tets)
    assert np.array_equal(back.cell_data["tag"][0], tag) and np.array_equal(back.cell_data["quality"][0], quality)

    raw = _decode_vtu(path)
    assert raw["Points"] == ("Float64", points.astype("<f8").tobytes())
    assert raw["connectivity"] == ("Int32", tets.astype("<i4").tobytes())
    assert raw["offsets"] == ("Int32", np.arange(4, 4 * len(tets) + 1, 4, dtype="<i4").tobytes())
    assert raw["types"] == ("UInt8", bytes([10]) * len(tets))
    components = {a.get("Name"): a.get("NumberOfComponents") for a in ET.parse(path).getroot().iter("DataArray")}
    assert components == {"Points": "3", "connectivity": None, "offsets": None, "types": None, "tag": None, "quality": None}

    # The same arrays give the same bytes, and read_mesh reads them.
    again = tmp_path / "again.vtu"
    write_mesh(again, points, tets.astype(np.int32), {"tag": tag, "quality": quality})
    assert again.read_bytes() == path.read_bytes()
    p, t = read_mesh(again)
    assert np.array_equal(p, points) and np.array_equal(t, tets)


def test_vtu_is_smaller_than_meshios_for_the_same_mesh(tmp_path):
    # A lattice-like mesh: neighbouring tets share vertices, as in paroct's output.
    points, _ = _random_mesh(3, 20000, 1)
    base = np.arange(0, 20000 - 8, 2)
    tets = np.stack([base, base + 1, base + 5, base + 8], axis=1)
    write_mesh(tmp_path / "ours.vtu", points, tets)
    meshio.write(tmp_path / "meshio.vtu", meshio.Mesh(points, [("tetra", tets)]), binary=True)
    ours, theirs = meshio.read(tmp_path / "ours.vtu"), meshio.read(tmp_path / "meshio.vtu")
    assert np.array_equal(ours.points, theirs.points) and np.array_equal(ours.cells[0].data, theirs.cells[0].data)
    assert (tmp_path / "ours.vtu").stat().st_size < (tmp_path / "meshio.vtu").stat().st_size


def test_vtu_of_no_tets_is_a_valid_empty_grid(tmp_path):
    path = tmp_path / "empty.vtu"
    write_mesh(path, np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64))
    raw = _decode_vtu(path)
    assert all(data == b"" for _, data in raw.values())


@pytest.mark.parametrize(
    "points, tets, cell_data, match",
    [
        (np.zeros((4, 2)), np.zeros((1, 4), int), None, r"points.shape = \(4, 2\)"),
        (np.zeros((4, 3)), np.zeros((1, 3), int), None, r"tets.shape = \(1, 3\)"),
        (np.zeros((4, 3)), np.zeros((1, 4)), None, r"tets.shape = \(1, 4\) \(float64\)"),
        (np.full((4, 3), np.nan), np.zeros((1, 4), int), None, "a point coordinate is NaN or infinite"),
        (np.zeros((4, 3)), np.zeros((2, 4), int), {"tag": np.zeros(3)}, r"cell_data\['tag'\]: shape \(3,\), float64; want"),
        (np.zeros((4, 3)), np.zeros((1, 4), int), {"name": np.array(["a"])}, r"cell_data\['name'\]: shape \(1,\), <U1"),
        (np.zeros((4, 3)), np.zeros((1, 4), int), {"z": np.array([1j])}, r"cell_data\['z'\]: shape \(1,\), complex128"),
        (np.zeros((4, 3)), np.zeros((1, 4), int), [np.zeros(1)], r"cell_data = list: give a dict"),
    ],
)
def test_writers_refuse_arrays_they_cannot_write(tmp_path, points, tets, cell_data, match):
    for suffix in (".vtu", ".msh", ".vtk"):
        with pytest.raises(ParoctError, match=match):
            write_mesh(tmp_path / f"bad{suffix}", points, tets, cell_data)
        assert not (tmp_path / f"bad{suffix}").exists()


def test_cell_data_round_trips_through_every_format_that_holds_it(tmp_path):
    points, tets = _random_mesh(4, 50, 80)
    data = {"tag": (np.arange(80) % 7).astype(np.int32), "quality": np.linspace(0, 1, 80),
            "flag": np.arange(80) % 2 == 0, "vector": np.arange(240.0).reshape(80, 3)}
    for suffix in (".vtu", ".vtk", ".msh"):
        write_mesh(tmp_path / f"m{suffix}", points, tets, data)
        back = meshio.read(tmp_path / f"m{suffix}")
        for name, values in data.items():
            assert np.array_equal(np.asarray(back.cell_data[name][0]).reshape(values.shape), values), (suffix, name)
    for suffix in (".inp", ".mesh", ".vol"):
        with pytest.raises(ParoctError, match="hold no cell data here"):
            write_mesh(tmp_path / f"m{suffix}", points, tets, data)


def test_write_mesh_into_a_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(ParoctError, match="does not exist"):
        write_mesh(tmp_path / "no" / "m.vtu", np.zeros((4, 3)), np.array([[0, 1, 2, 3]]))


@pytest.mark.parametrize("suffix", [".inp", ".mesh"])
def test_text_formats_round_trip_exactly_through_meshio(tmp_path, suffix):
    points, tets = _random_mesh(11, 3000, 7000)
    path = tmp_path / f"m{suffix}"
    write_mesh(path, points, tets.astype(np.int32))
    back = meshio.read(path)
    assert np.array_equal(back.points, points) and np.array_equal(np.signbit(back.points), np.signbit(points))
    assert [b.type for b in back.cells] == ["tetra"] and np.array_equal(back.cells[0].data, tets)
    # meshio's own writer gives a file that reads back to the same arrays.
    meshio.write(tmp_path / f"theirs{suffix}", meshio.Mesh(points, [("tetra", tets)]))
    theirs = meshio.read(tmp_path / f"theirs{suffix}")
    assert np.array_equal(theirs.points, back.points) and np.array_equal(theirs.cells[0].data, back.cells[0].data)


def test_int_lines_match_python_formatting():
    rng = np.random.default_rng(5)
    rows = np.concatenate([rng.integers(0, 10 ** rng.integers(1, 18), size=(500, 4)),
                           [[0, 8, 9, 98], [99, 998, 999, 10**18 - 1]]])
    for first_id, reference, sep in [(1, -1, ", "), (-1, 1, " "), (7, 0, ","), (-1, -1, "\t")]:
        text = _int_lines(rows, first_id, reference, np.frombuffer(sep.encode(), np.uint8)).tobytes().decode()
        want = "".join(sep.join(([str(first_id + i)] if first_id >= 0 else []) + [str(v + 1) for v in row]
                                + ([str(reference)] if reference >= 0 else [])) + "\n" for i, row in enumerate(rows))
        assert text == want


def test_writers_refuse_ids_outside_the_points(tmp_path):
    for suffix in (".vtu", ".inp", ".mesh", ".msh"):
        with pytest.raises(ParoctError, match=r"vertex ids 0 \.\. 4, len\(points\) = 4"):
            write_mesh(tmp_path / f"bad{suffix}", np.zeros((4, 3)), np.array([[0, 1, 2, 4]]))


def test_every_format_written_reads_back_the_same_tets(tmp_path):
    """Every extension write_mesh accepts gives a file that reads back to the same tets (or
    asks for an extra package); the others are refused with a reason, before any writing.
    meshio's Nastran, .meshb and .ugrid writers gave files that do not (session 38's fuzzing)."""
    import warnings

    from paroct.io import output_format

    import manifold3d

    import paroct

    mesh = paroct.mesh(manifold3d.Manifold.cube([1, 2, 3]), size=1.0).mesh  # positive tets: some formats reorder others
    points, tets = mesh.points, mesh.tets
    written, refused = [], []
    for ext in sorted(meshio.extension_to_filetypes):
        path = tmp_path / f"m{ext}"
        try:
            output_format(path)
        except ParoctError as exc:
            refused.append(ext)
            assert "\n" not in str(exc) and not path.exists()
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                write_mesh(path, points, tets)
        except ParoctError as exc:
            assert "needs an extra package" in str(exc) or "needs the package" in str(exc)
            continue
        p, t = read_mesh(path)
        assert np.allclose(p, points, rtol=1e-6, atol=1e-9) and np.array_equal(t, tets), ext
        written.append(ext)
    assert {".bdf", ".nas", ".meshb", ".ugrid", ".wkt", ".stl"} <= set(refused)
    assert {".vtu", ".msh", ".mesh", ".inp", ".vtk", ".vol.gz", ".ele"} <= set(written)
