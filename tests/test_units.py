"""Unit strings at the edge (``ks_jax.units``): one number and its unit, the dimension checked, pint's parsed
definitions kept in a folder."""

import math

import pytest

from ks_jax import units as U


def test_parse_quantity_rules():
    assert U.parse_quantity("21 mph", "velocity") == pytest.approx(21 * 0.44704, rel=1e-12)
    assert U.parse_quantity("2300 lbf*ft*s^2", "inertia") == pytest.approx(2300 * 4.4482216152605 * 0.3048, rel=1e-12)
    assert U.parse_quantity(30, "angle") == pytest.approx(math.radians(30))
    assert U.parse_quantity("30 deg", "angle") == pytest.approx(math.radians(30))
    assert U.parse_quantity(45, "angular_velocity") == pytest.approx(math.radians(45))
    assert U.parse_quantity("0.06 s", "time") == pytest.approx(0.06)
    assert U.parse_quantity("155.75 slug", "mass") == pytest.approx(155.75 * 14.593902937206364, rel=1e-12)
    with pytest.raises(U.UnitError, match="dimension"):
        U.parse_quantity("21 mph", "mass")
    with pytest.raises(U.UnitError, match="unknown unit"):
        U.parse_quantity("21 furlongs_per_blink", "velocity")


def test_unit_strings_read_one_number_and_its_unit():
    """A thousands separator, a decimal comma, a second number or an expression is refused, where pint
    alone would read "1 500 kg" as 500 kg, "4,5 m" as 45 m and "30 mph 2" as 60 mph. A hyphen between
    unit names is a product, as US reports write energies and impulses; a rate needs an angle in its unit
    (Hz or 1/s could count radians or turns); restitution and friction take no unit (pint would take an
    angle: "30 deg" as 0.52)."""
    for text, kind in [("1 500 kg", "mass"), ("3 000 kg", "mass"), ("4,5 m", "length"), ("12,5 km/h", "velocity"),
                       ("0,1", "dimensionless"), ("30 mph 2", "velocity"), ("0.1 0.2", "dimensionless"),
                       ("5 kg + 3 kg", "mass"), ("1 250 mm", "length"), ("a", "velocity"), ("mph", "velocity")]:
        with pytest.raises(U.UnitError, match="one number, then its unit"):
            U.parse_quantity(text, kind)
    # the seed chapter's energy and impulse as its US panel writes them (docs/model.md, "Worked examples")
    assert U.parse_quantity("14117.71 ft-lbf", "energy") == pytest.approx(14117.71 * 0.3048 * 4.4482216152605,
                                                                          rel=1e-12)
    assert U.parse_quantity("1336.904 lbf-s", "impulse") == pytest.approx(5946.847, abs=2e-3)
    assert U.parse_quantity("2300 lbf-ft-s^2", "inertia") == U.parse_quantity("2300 lbf*ft*s^2", "inertia")
    assert U.parse_quantity("60 rpm", "angular_velocity") == pytest.approx(2 * math.pi)
    assert U.parse_quantity("2 rad/s", "angular_velocity") == 2.0
    for text in ("1 Hz", "2 1/s"):
        with pytest.raises(U.UnitError, match="needs an angle"):
            U.parse_quantity(text, "angular_velocity")
    with pytest.raises(U.UnitError, match="takes no unit"):
        U.parse_quantity("30 deg", "dimensionless")


def test_unit_definitions_kept_in_a_folder_read_the_same(tmp_path, monkeypatch):
    """With ``units.REGISTRY_CACHE`` (the command line sets it) pint keeps its parsed unit definitions in that
    folder and reads them back in the next process; quantities read that way equal the exact definitions, and
    a folder that cannot be made (under a file) is passed over: the definitions are parsed as without one."""
    lbf, ft = 0.45359237 * 9.80665, 0.3048
    texts = [("21 mph", "velocity", 21 * 1609.344 / 3600), ("2300 lbf*ft*s^2", "inertia", 2300 * lbf * ft),
             ("155.75 slug", "mass", 155.75 * lbf / ft), ("14117.71 ft-lbf", "energy", 14117.71 * ft * lbf),
             ("60 rpm", "angular_velocity", 2 * math.pi), ("12 in", "length", 12 * 0.0254)]
    (tmp_path / "a_file").write_text("not a folder")
    folder = tmp_path / "units"
    try:
        for where in (folder, folder, tmp_path / "a_file" / "units"):  # written, read back, unusable
            monkeypatch.setattr(U, "REGISTRY_CACHE", where)
            U._registry.cache_clear()
            for text, kind, want in texts:
                assert U.parse_quantity(text, kind) == pytest.approx(want, rel=1e-12), (where, text)
            if where == folder:
                assert any(folder.iterdir())
    finally:
        U._registry.cache_clear()
