"""Study configs: schema, ranges, validation errors, shipped presets, the commented example.

No FEA is solved here (validation only builds the Blank/Coating/MeshSpec objects); the
end-to-end runs are in tests/test_study_run.py.
"""
import re
import tomllib

import pytest

from pipeline.study.cases import FEAGroup
from pipeline.study.config import (
    example_config_text,
    list_presets,
    load_study_config,
    loads_study_config,
    preset_path,
)
from pipeline.study.profile_specs import ProfileSpec
from pipeline.study.schema import FEA_KEYS, PROFILE_KEYS, ConfigError
from pipeline.study.study_config import StudyConfig
from pipeline.study.run import default_study


def test_builtin_default_equals_the_shipped_paper_config():
    assert load_study_config(preset_path("paper_default")) == default_study()


def test_default_study_is_the_papers():
    cfg = default_study()
    labels = [c.label for c in cfg.cases()]
    assert labels[:3] == ["200/100", "200/75", "200/50"] and len(labels) == 15
    assert labels[9:] == ["holes 200", "holes 150", "holes 100", "surfaces 200", "surfaces 150", "surfaces 100"]
    # cache keys as `cryograting tables` makes them: the paper's cases are shared between the two
    assert cfg.cases()[0].params == {"coverage": "all", "t0_um": 200.0, "polish": 1.0}
    jobs = cfg.profile_jobs()
    assert len(jobs) == 27 + 18 + 18 + 9
    assert {(j.grating, j.order, j.deformation) for j in jobs if j.set == "multigrating"} == {
        ("J", -2, "200/50"), ("H", -3, "200/75"), ("K", -4, "200/75")}
    assert sorted({j.wavelength_um for j in jobs if j.grating == "K"}) == [1.25, 1.95, 2.2, 2.45]


def test_example_loads_and_comments_every_key():
    text = example_config_text()
    cfg = loads_study_config(text, "example")
    assert len(cfg.cases()) == 4 and len(cfg.figures) == 4
    keys = [*FEA_KEYS, *PROFILE_KEYS, "set", "deformation", "name", "title", "description", "kind", "file",
            "heading", "cases", "titles", "case", "lines", "grating", "pixel_scale_mas", "figures", "report",
            "exports"]
    for key in keys:
        line = next((ln for ln in text.splitlines() if re.match(rf"\s*#?\s*{key}\s*=", ln)), None)
        assert line is not None, f"{key} is missing from the example"
        assert "#" in line.split("=", 1)[1] or line.lstrip().startswith("#"), f"{key} has no comment"


def test_cli_prints_the_example(capsys):
    from pipeline.cli import main

    assert main(["config", "--example"]) == 0
    out = capsys.readouterr().out
    assert out == example_config_text()
    loads_study_config(out)


def test_cli_checks_a_preset(capsys):
    from pipeline.cli import main

    assert main(["config", "--preset", "whatif_alsi40"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("valid: ") and "200/50 AlSi40" in out


@pytest.mark.parametrize("name", ["paper_default", "whatif_period_doubled", "whatif_no_lightweighting",
                                  "whatif_alsi40"])
def test_presets_load_and_validate(name):
    assert name in list_presets()
    cfg = load_study_config(preset_path(name))
    assert cfg.profile_jobs(), "every preset computes line profiles"
    assert all(f.file.endswith(".png") for f in cfg.figures)


def test_whatif_presets_change_what_the_paper_says():
    from fea.geometry import Blank

    def whatif(name):
        cases = load_study_config(preset_path(name)).cases()
        base, new = cases[:3], cases[3:]
        assert [c.full["polish"] for c in new] == [1.0, 0.75, 0.5]
        assert all(c.is_paper_setup for c in base) and not any(c.is_paper_setup for c in new)
        return new[0].full

    p = whatif("whatif_period_doubled")
    assert (p["pitch_x_mm"], p["pitch_y_mm"]) == (42.0, 36.0)
    blank = Blank(**{k: p[k] for k in Blank().key()})            # holes inside the blank
    assert blank.hole_x_positions_mm.max() == 63.0 and blank.hole_y_positions_mm.max() == 54.0
    with pytest.raises(ValueError, match="outside the side face"):  # one more hole would not fit
        Blank(**{**Blank().key(), "pitch_x_mm": 42.0, "n_holes_x": 5})
    assert whatif("whatif_no_lightweighting")["n_holes_x"] == 0
    assert whatif("whatif_alsi40")["substrate"] == "AlSi40"


def test_period_doubled_cannot_keep_seven_holes():
    with pytest.raises(ConfigError, match=r"fea.cases\[0\]: invalid case .*outside the side face"):
        loads_study_config("[[fea.cases]]\npitch_x_mm = 42\n")


@pytest.mark.parametrize("value, expected", [
    ("200", (200.0,)),
    ("[200, 150]", (200.0, 150.0)),
    ("{start = 100, stop = 200, step = 50}", (100.0, 150.0, 200.0)),
    ("{start = 100, stop = 200, num = 3}", (100.0, 150.0, 200.0)),
    ("{start = 150, stop = 150, num = 1}", (150.0,)),
    ('"100:200:50"', (100.0, 150.0, 200.0)),
    ('"100,150"', (100.0, 150.0)),
])
def test_values_lists_and_ranges(value, expected):
    cfg = loads_study_config(f"[fea]\nt0_um = {value}\n")
    assert cfg.fea[0].axes == (("t0_um", expected),)


def test_integer_ranges_and_product_order():
    cfg = loads_study_config("[fea]\nt0_um = [200, 100]\npolish = {start = 0.5, stop = 1, step = 0.5}\n"
                             "n_holes_x = {start = 5, stop = 7, step = 2}\n")
    assert dict(cfg.fea[0].axes)["n_holes_x"] == (5, 7)
    assert [(c.full["t0_um"], c.full["polish"], c.full["n_holes_x"]) for c in cfg.cases()][:3] == [
        (200.0, 0.5, 5), (200.0, 0.5, 7), (200.0, 1.0, 5)]
    assert cfg.cases()[0].label == "200/50, n_holes_x=5"   # what varies is named


def test_python_construction_and_mesh_override():
    cfg = StudyConfig(fea=(FEAGroup("g", {"t0_um": [100, 200]}),),
                      profiles=(ProfileSpec(grating="K", wavelength_um=2.2, deformation={"t0_um": 100}),))
    coarse = cfg.with_mesh(5, 10)
    assert coarse.cases()[0].params == {"coverage": "all", "t0_um": 100.0, "polish": 0.75,
                                        "mesh_size_mm": 5.0, "mesh_bulk_mm": 10.0}
    assert [j.deformation for j in coarse.profile_jobs()] == ["100/75"] * 3
    with pytest.raises(ConfigError, match=r"mesh_bulk_mm = 1.0: .*mesh_bulk_mm=1.0: valid range is >= mesh_size_mm"):
        cfg.with_mesh(5, 1)


@pytest.mark.parametrize("text, message", [
    ("[fae]\n", r"^t\.toml: fae: unknown key; did you mean 'fea'\?"),
    ("[fea]\nt0_mu = 200\n", r"fea\.t0_mu: unknown key; did you mean 't0_um'\?"),
    ("[fea]\nt0_um = 'thick'\n", r"fea\.t0_um = 'thick': .*valid forms"),
    ("[fea]\nt0_um = true\n", r"fea\.t0_um = True: must be a number \(µm, \(0, 2000\]\)"),
    ("[fea]\nt0_um = []\n", r"fea\.t0_um = \[\]: empty list"),
    ("[fea]\npolish = {start = 1, stop = 0.5, step = 0.25}\n", r"fea\.polish = .*empty or invalid range.*goes away"),
    ("[fea]\npolish = {start = 0.5, stop = 1}\n", r"fea\.polish = .*\{start, stop, step\} or \{start, stop, num\}"),
    ("[fea]\npolish = {start = 0.5, stop = 1, steps = 0.1}\n", r"fea\.polish\.steps: unknown key; did you mean 'step'"),
    ("[fea]\nt0_um = [200, 200.0]\n", r"fea\.t0_um = .*repeats the value 200.0"),
    ("[fea]\nt0_um = -10\n", r"fea\.t0_um = -10\.0: t0_um=-10\.0 is outside the valid range \(0, 2000\] µm"),
    ("[fea]\npolish = 1.5\n", r"fea\.polish = 1\.5: polish=1\.5 is outside the valid range \(0, 1\]"),
    ("[fea]\ncold_K = 500\n", r"fea\.cold_K = 500\.0: cold_K=500\.0 K is outside .* \(4\.\.300 K\)"),
    ("[fea]\nsubstrate = 'steel'\n", r"fea\.substrate = 'steel': unknown value.*allowed: one of Al6061-T6, AlSi40, NiP"),
    ("[fea]\ncoverage = 'hole'\n", r"fea\.coverage = 'hole': unknown value; did you mean 'holes'\?"),
    ("[fea]\nn_holes_x = 3.5\n", r"fea\.n_holes_x = 3\.5: must be an integer"),
    ("[[fea.cases]]\n[[fea.cases]]\nhole_diameter_mm = 25\n",
     r"fea\.cases\[1\]\.hole_diameter_mm = 25\.0: hole_diameter_mm=25\.0: .*breaks through"),
    ("[fea]\nthickness_mm = 10\n[[fea.cases]]\nname = 'a'\n",
     r"fea\.cases\[0\]: invalid case thickness_mm=10\.0: hole_diameter_mm=15\.0: .*breaks through"),
    ("[fea]\npolish = 0.5\npolish_front = 0.5\n", r"fea\.polish_front: give either polish"),
    ("[fea]\nmesh_size_mm = 0\n", r"fea\.mesh_size_mm = 0\.0: mesh_size_mm=0\.0: valid range"),
    ("[[fea.cases]]\nname = 'a'\n[[fea.cases]]\nname = 'a'\nsubstrate = 'AlSi40'\n",  # labels would clash
     r"fea\.cases: two different cases get the label '200/75 a'; give the \[\[fea\.cases\]\] tables distinct"),
    ("[[profiles]]\ngrating = 'Q'\n", r"profiles\[0\]\.grating = 'Q': unknown value"),
    ("[[profiles]]\ngrating = 'J'\nwavelength_um = 6.0\norder = -2\n",
     r"profiles\[0\]\.wavelength_um = 6\.0: .*no propagating order -2.*valid range"),
    ("[[profiles]]\npixel_scale_mas = 50\n", r"profiles\[0\]\.pixel_scale_mas = 50: unknown pixel scale"),
    ("[[profiles]]\norder = 0\n", r"profiles\[0\]\.order = 0: must be a non-zero integer"),
    ("[[profiles]]\ndeformation = [{t0_um = 150}]\n", r"profiles\[0\]\.deformation\[0\]: the selector .* matches no"),
    ("[[profiles]]\ndeformation = [{t0 = 150}]\n",
     r"profiles\[0\]\.deformation\[0\]\.t0: unknown selector key; did you mean 't0_um'"),
    ("[[profiles]]\ndeformation = [{polish = 0.75}]\npupil_shift_x_mm = [0, 20]\n",
     r"profiles\[0\]\.pupil_shift_x_mm = 20\.0: the J pupil footprint .* allowed \|shift\| <= 11\.94 mm"),
    ("[[profiles]]\nset = 'a'\n[[figures]]\nkind = 'profiles'\nfile = 'x.png'\nset = 'b'\n",
     r"figures\[0\]\.set = 'b': no \[\[profiles\]\] table has this set"),
    ("[[figures]]\nkind = 'map'\nfile = 'x.png'\n", r"figures\[0\]\.kind = 'map': unknown figure kind"),
    ("[[figures]]\nkind = 'sag_maps'\nfile = '../x.png'\ncases = [{t0_um = 200}]\n",
     r"figures\[0\]\.file = '\.\./x\.png': must be a PNG file name"),
    ("[output]\nfigures = 'yes'\n", r"output\.figures = 'yes': must be true or false"),
    ("[fea]\nt0_um = 200\n  = 3\n", r"malformed TOML: .*\(at line 3, column 3\)"),
])
def test_bad_configs_name_the_key_value_and_what_is_allowed(text, message):
    with pytest.raises(ConfigError, match=message) as info:
        loads_study_config(text, "t.toml")
    assert "\n" not in str(info.value)
    assert str(info.value).startswith("t.toml: ")


def test_missing_file_and_unknown_preset(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found; did you mean --preset whatif_alsi40"):
        load_study_config(tmp_path / "whatif_alsi40.toml")
    with pytest.raises(FileNotFoundError, match=r"unknown preset 'whatif_alsi4'; did you mean 'whatif_alsi40'"):
        preset_path("whatif_alsi4")


def test_every_shipped_toml_is_valid_toml():
    for name in [*list_presets(), "example"]:
        path = preset_path(name) if name != "example" else preset_path("paper_default").with_name("example.toml")
        tomllib.loads(path.read_text())


def _leaf_paths(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaf_paths(v, (*path, k))
    elif isinstance(node, list) and node and all(isinstance(x, dict) for x in node):
        for i, v in enumerate(node):
            yield from _leaf_paths(v, (*path, i))
    else:
        yield path


def test_any_wrong_value_anywhere_gives_a_one_line_config_error():
    """Every key of the example replaced by wrong types/shapes or removed: a ConfigError or a
    valid config, never another exception."""
    import copy

    from pipeline.study.config import study_config_from_dict

    base = tomllib.loads(example_config_text())
    for path in _leaf_paths(base):
        for value in (3, "x", [], {}, [[1]], [{"a": 1}], ...):
            data = copy.deepcopy(base)
            node = data
            for k in path[:-1]:
                node = node[k]
            if value is ...:
                del node[path[-1]]
            else:
                node[path[-1]] = value
            try:
                study_config_from_dict(data, "x.toml")
            except ConfigError as exc:
                assert "\n" not in str(exc) and str(exc).startswith("x.toml: "), (path, value, str(exc))


def test_set_overrides_sweep_any_key_from_the_command_line():
    """`--set` takes lists, ranges and names for FEA and profile keys, validated like a file."""
    from pipeline.study.config import apply_overrides, parse_override, read_study_data, study_config_from_dict

    assert parse_override("fea.t0_um=[100, 150]") == ("fea.t0_um", [100, 150])
    assert parse_override("profiles.grating=J,K") == ("profiles.grating", ["J", "K"])
    assert parse_override("fea.polish=0.5:1:3n") == ("fea.polish", "0.5:1:3n")
    assert parse_override("fea.substrate=AlSi40") == ("fea.substrate", "AlSi40")
    data = apply_overrides(read_study_data(None), ["fea.cases[1].t0_um=100:200:50",
                                                   "profiles.pupil_shift_x_mm=-4,0,4"])
    base = study_config_from_dict(read_study_data(None))
    cfg = study_config_from_dict(data)
    assert len(cfg.profile_jobs()) == 3 * len(base.profile_jobs())
    assert {c.params["t0_um"] for c in cfg.cases()} >= {100.0, 150.0, 200.0}


@pytest.mark.parametrize("override, match", [
    ("fea.t0_umm=100", "did you mean 't0_um'"),
    ("profiles.pupil_shift_x_mm=40", "allowed |shift|"),
    ("fea.cases[9].polish=0.5", "only"),
    ("nonsense", "KEY=VALUE"),
    ("colour.t0_um=1", "unknown override key"),
])
def test_bad_set_override_names_key_and_range(override, match):
    from pipeline.study.config import apply_overrides, read_study_data, study_config_from_dict

    with pytest.raises(ValueError, match=re.escape(match)):
        study_config_from_dict(apply_overrides(read_study_data(None), [override]))


def test_set_fea_key_reaches_tables_that_set_it_themselves():
    from pipeline.study.config import apply_overrides, study_config_from_dict

    data = {"fea": {"t0_um": 200, "cases": [{"name": "a", "t0_um": 150, "polish": 0.5},
                                            {"name": "b", "polish": 1.0}]}}
    cfg = study_config_from_dict(apply_overrides(data, ["fea.t0_um=[100, 120]"]))
    assert sorted(c.params["t0_um"] for c in cfg.cases()) == [100, 100, 120, 120]
