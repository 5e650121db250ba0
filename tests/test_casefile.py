"""Case-file schema: defaults, unit conversion at the edge, and errors naming key and line."""

from pathlib import Path

import pytest

from femstudy.casefile import load_case, parse_case
from femstudy.errors import UserError

REPO = Path(__file__).resolve().parents[1]


def test_shipped_cases_load():
    for path in sorted((REPO / "cases").glob("*.toml")):
        case = load_case(path)
        assert case.name == path.stem


def test_thesis_defaults_and_unit_conversion():
    case = parse_case("name = 'x'\n")
    cortical = case.materials.cortical
    assert cortical.youngs_modulus_MPa == 16_000.0
    assert cortical.density_t_mm3 == pytest.approx(1.7e-9)
    assert case.materials.cancellous.youngs_modulus_MPa == 500.0
    assert (case.drilling.feed_mm_s, case.drilling.spindle_rpm) == (2.0, 1500.0)
    assert (case.time.end_s, case.time.step_s) == (3.0, 0.1)


def test_partial_material_keeps_table_3_1_values():
    case = parse_case("name = 'x'\n[materials.cortical]\nyoungs_modulus_GPa = 17.0\n")
    assert case.materials.cortical.youngs_modulus_GPa == 17.0
    assert case.materials.cortical.poissons_ratio == 0.4


def test_surface_path_is_relative_to_the_case_file(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[geometry]\nsurface = 'bones/f.stl'\n")
    with pytest.raises(UserError, match=r"c.toml:2: geometry.surface: .*bones/f.stl does not exist"):
        load_case(path)
    (tmp_path / "bones").mkdir()
    (tmp_path / "bones" / "f.stl").write_text("solid x\nendsolid x\n")
    assert load_case(path).surface_path() == tmp_path / "bones" / "f.stl"
    assert parse_case("name='x'").surface_path() is None


@pytest.mark.parametrize("text, expected", [
    ("name = 'x'\n[mesh\nsize_mm = 3\n", "TOML syntax error"),
    ("name = 'x'\n[mesh]\nsize_m = 3\n", ":3: mesh.size_m: unknown key; did you mean 'size_mm'?"),
    ("name = 'x'\n[meshh]\n", ":2: meshh: unknown key; did you mean 'mesh'?"),
    ("name = 'x'\n[mesh]\nsize_mm = 'big'\n", ":3: mesh.size_mm: Input should be a valid number"),
    ("name = 'x'\n\n[mesh]\nsize_mm = -3\n", ":4: mesh.size_mm: Input should be greater than 0, got -3"),
    ("name = 'x'\n[drilling]\nfeed_mm_s = 500\n", ":3: drilling.feed_mm_s: Input should be less than or equal to 50"),
    ("name = 'x'\n[drilling]\nspindle_rpm = 0\n", ":3: drilling.spindle_rpm: Input should be greater than or equal to 10"),
    ("name = 'x'\n[time]\nend_s = 1\nstep_s = 2\n", ":2: time: step_s = 2.0 s is larger than the span"),
    ("name = 'x'\n[site]\ndirection = 'up'\n", ":3: site.direction: Input should be 'anterior'"),
    ("name = 'x'\n[site]\ndirection = [1, 0]\n", "non-zero vector of three numbers"),
    ("name = 'x'\n[materials.cortical]\npoissons_ratio = 0.55\n", ":3: materials.cortical.poissons_ratio"),
    ("name = 'my case'\n", ":1: name: name may contain only letters"),
])
def test_errors_name_the_key_and_the_line(text, expected):
    with pytest.raises(UserError) as info:
        parse_case(text, Path("case.toml"))
    message = str(info.value)
    assert message.startswith("case.toml")
    assert expected in message
    assert "\n" not in message


def test_missing_case_file():
    with pytest.raises(UserError, match="does not exist"):
        load_case("no/such/case.toml")


def test_overrides_are_validated_like_the_file():
    from femstudy.casefile import with_overrides

    case = parse_case("name = 'x'\n")
    changed = with_overrides(case, {"drilling.feed_mm_s": 1.5, "site.direction": "lateral"})
    assert changed.drilling.feed_mm_s == 1.5 and changed.site.direction == "lateral"
    with pytest.raises(UserError, match="did you mean 'drilling.feed_mm_s'"):
        with_overrides(case, {"drilling.feed": 1.5})
    with pytest.raises(UserError, match="drilling.feed_mm_s: Input should be greater than or equal to 0.01"):
        with_overrides(case, {"drilling.feed_mm_s": -1})


def test_a_bad_sweep_file_is_refused_with_its_key_and_line(tmp_path):
    from femstudy.sweeps.spec import read_parameter_sweep

    path = tmp_path / "s.toml"
    path.write_text('case = "c.toml"\n\n[grid]\n"drilling.feed_mm_s" = []\n')
    with pytest.raises(UserError, match=r"s\.toml:4: grid\.drilling\.feed_mm_s: List should have at least 1 item"):
        read_parameter_sweep(path)
    path.write_text('case = "c.toml"\nnmae = "x"\n[grid]\n"a.b" = [1]\n')
    with pytest.raises(UserError, match=r"s\.toml:2: nmae: unknown key; did you mean 'name'"):
        read_parameter_sweep(path)
    path.write_text('case = "c.toml"\n')
    with pytest.raises(UserError, match=r"give a \[grid\] or at least one \[\[point\]\]"):
        read_parameter_sweep(path)
