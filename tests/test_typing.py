"""paroct is a typed package (py.typed): its own annotations agree with its code, and a
user's type checker sees them."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

mypy_api = pytest.importorskip("mypy.api")  # in the test extra


def test_the_package_type_checks():
    out, err, status = mypy_api.run(["--config-file", str(ROOT / "pyproject.toml"), str(ROOT / "src" / "paroct")])
    assert status == 0, out + err


def test_a_users_type_checker_sees_the_public_api(tmp_path):
    """With the py.typed marker mypy reads paroct's annotations (without it, every name is Any
    and the wrong line below passes): exactly one error, on that line."""
    user = tmp_path / "user.py"
    user.write_text(
        "import paroct\n"
        "result: paroct.MeshResult = paroct.mesh('part.stl', size=0.1, max_size=0.8)\n"
        "angle: float = result.report.min_dihedral\n"
        "wrong: str = result.report.n_tets\n"
    )
    out, err, status = mypy_api.run(["--no-incremental", "--cache-dir", str(tmp_path / "cache"), str(user)])
    errors = [line for line in out.splitlines() if ": error:" in line]
    assert status == 1 and len(errors) == 1, out + err
    assert "user.py:4:" in errors[0] and "str" in errors[0], errors
