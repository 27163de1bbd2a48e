"""The command line's overrides as words (ddfbench.run.overrides): each problem Hydra would answer in many lines is one
line naming the override, before Hydra composes."""

import pytest

from ddfbench import cli
from ddfbench.core.errors import InputError
from ddfbench.run.overrides import check_overrides, check_shape_path, values_of


@pytest.mark.parametrize("arg,line", [
    ("model=ddff", "model=ddff: no model named 'ddff' (did you mean ddf? model options: ddf, ddf_line_grid,"),
    ("+experiment=ablaton", "+experiment=ablaton: no experiment named 'ablaton' (did you mean ablation, ablation_grid?"),
    ("shape=bunnny", "shape=bunnny: no shape named 'bunnny' (did you mean bunny, bunny10k?"),
    ("+form=fast", "+form=fast: no form named 'fast' (form options: quick)"),
    ("model=mesh,mesh_lodd500", "model=mesh,mesh_lodd500: no model named 'mesh_lodd500' (did you mean mesh_lod500,"),
])
def test_a_config_option_that_has_no_file_is_one_line_with_the_near_names(arg, line):
    with pytest.raises(InputError) as err:
        check_overrides([arg], sweeps=True)
    assert str(err.value).startswith(line) and "\n" not in str(err.value)


@pytest.mark.parametrize("value", ["/data/chair.obj", "chair.obj", "scans/chair.PLY"])
def test_a_mesh_file_given_as_the_shape_says_how_to_read_a_file(value):
    with pytest.raises(InputError) as err:
        check_overrides([f"shape={value}"], sweeps=True)
    assert str(err.value).startswith(f"shape={value}: no shape named {value!r} (a mesh file is read with shape=file "
                                     f"shape.path={value}; shape options: ")


def test_a_bare_extension_given_as_the_shape_is_no_file():
    with pytest.raises(InputError) as err:
        check_overrides(["shape=obj"], sweeps=True)
    assert "shape=file" not in str(err.value)


def test_a_shape_path_without_shape_file_stops_instead_of_running_the_catalog_shape():
    for args in (["shape.path=/data/chair.obj"], ["model=grid_sdf", "+shape.path=/data/chair.obj"],
                 ["+experiment=ablation", "shape.path=/data/chair.obj"]):
        with pytest.raises(InputError, match=r"^shape.path=/data/chair.obj: a path is read only with shape=file .*"
                                             r"add shape=file$"):
            check_shape_path(args)
    for args in (["shape=bunny", "shape.path=/data/chair.obj"], ["-m", "shape.name=cube,torus", "shape.path=/d/c.obj"]):
        with pytest.raises(InputError, match=r"^shape.path=/d.*: shape=.* is a catalog shape, which ignores a path: "
                                             r"use shape=file$"):
            check_shape_path(args)
    for args in (["shape=file", "shape.path=/data/chair.obj"], ["-m", "shape=cube,file", "shape.path=/data/c.obj"],
                 ["shape.name=file", "shape.path=/data/chair.obj"], ["model=mesh"],
                 ["-cd", "/data/myconf", "shape.path=/data/chair.obj"]):
        check_shape_path(args)


def test_a_list_of_values_needs_a_sweep():
    with pytest.raises(InputError, match=r"^model=mesh,mesh_lod500: a list of values is a sweep: add -m"):
        check_overrides(["model=mesh,mesh_lod500"], sweeps=False)
    check_overrides(["model=mesh,mesh_lod500", "seed=0,1"], sweeps=True)
    assert not cli.sweeps(["model=mesh,mesh_lod500"])
    assert cli.sweeps(["model=mesh,mesh_lod500", "-m"]) and cli.sweeps(["+experiment=ablation"])
    assert cli.sweeps(["shape=cow"])  # the default run: a sweep over the families


def test_a_value_hydra_cannot_read_names_the_override_and_how_to_quote_it():
    with pytest.raises(InputError) as err:
        check_overrides(["shape=file", "shape.path=/data/chair(1).obj"], sweeps=False)
    assert str(err.value) == ("shape.path=/data/chair(1).obj: Hydra cannot read this value (mismatched input '(' "
                              "expecting <EOF>); a value with ( ) [ ] { } , = ' \" or spaces needs quotes: "
                              "\"shape.path='/data/chair(1).obj'\"")
    check_overrides(["shape=file", "shape.path='/data/chair(1).obj'"], sweeps=False)


def test_what_hydra_reads_passes():
    check_overrides(["model=ddf_tuned", "shape=cube", "scene=depth", "sampling=surface", "sampling.s_p=20",
                     "hydra/launcher=local_parallel", "train.max_steps=5", "eval.radii=[0.01,0.02]", "~tracking",
                     "+form=quick", "model=null", "-m", "--help"], sweeps=True)


def test_globs_interpolations_and_other_config_folders_are_left_to_hydra():
    check_overrides(["shape=glob(cu*)", "model=mesh", "-m"], sweeps=True)  # a glob needs Hydra's config loader
    check_overrides(["shape=cube,${oc.env:MY_SHAPE}", "-m"], sweeps=True)  # resolved when the job composes
    for flag in (["-cd", "/data/myconf"], ["--config-dir=/data/myconf"], ["hydra.searchpath=[file:///data/myconf]"]):
        check_overrides([*flag, "+experiment=mine", "shape=chair"], sweeps=True)  # options of another folder
    with pytest.raises(InputError, match="no shape named 'chair'"):
        check_overrides(["+experiment=default", "shape=chair"], sweeps=True)


def test_hydra_mode_run_is_not_a_sweep_unless_m_is_given():
    assert not cli.sweeps(["+experiment=default", "hydra.mode=RUN", "seed=0,1"])
    assert cli.sweeps(["+experiment=default", "hydra.mode=RUN", "-m"])


def test_a_tuning_study_names_one_model_with_a_search_space():
    with pytest.raises(InputError, match=r"^\+experiment=tune: name one model to study \(model=<name>; models with a "
                                         r"search space: .*ddf"):
        cli.check_tune(["+experiment=tune"])
    with pytest.raises(InputError, match=r"^model=mesh: conf/model/mesh.yaml declares no experiments.tune search"):
        cli.check_tune(["+experiment=tune", "model=mesh"])
    cli.check_tune(["+experiment=tune", "model=ddf"])
    cli.check_tune(["model=mesh"])  # not a study



def test_values_of_a_key_are_those_its_words_give_in_order():
    args = ["model=mesh,grid_sdf", "+experiment=tune", "++capacity=s", "~capacity=m", "-m", "model.lr=1e-3",
            "capacity=l=1"]
    assert values_of(args, "model") == ["mesh,grid_sdf"]
    assert values_of(args, "experiment") == ["tune"]
    assert values_of(args, "capacity") == ["s", "l=1"]  # `~` deletes: no value; the value keeps its own `=`
    assert values_of(args, "seed") == []


def test_a_command_naming_a_model_or_an_experiment_in_any_form_is_not_the_default_run():
    """Only a command that names no model, no experiment and no flag runs +experiment=default. Kills dropping the
    plain `experiment=` form from wants_default_experiment (the default experiment would be appended beside it)."""
    assert cli.wants_default_experiment(["shape=cow", "seed=1"])
    for named in (["model=ddf"], ["+model=ddf"], ["experiment=sampling"], ["+experiment=sampling"], ["-m"]):
        assert not cli.wants_default_experiment(["shape=cow", *named]), named


def test_threads_empty_or_null_means_every_core_and_a_negative_count_is_refused():
    """threads= and threads=null are 0 (every core), accepted before Hydra starts; -2 is one line. Kills check_threads
    refusing the empty value."""
    for fine in (["threads="], ["threads=null"], ["threads=0"], ["threads=3"], ["threads=1,2"]):
        cli.check_threads(fine)
    with pytest.raises(InputError, match=r"^threads=-2: must be an integer >= 0"):
        cli.check_threads(["threads=-2"])


def test_a_nan_given_on_the_command_line_is_left_to_the_value_checks_not_called_replaced_by_a_level(tmp_path):
    """check_levels_keep compares what was asked with what the job's levels run; a NaN is never equal to itself, so
    without the NaN rule every NaN override would read as replaced by a level (the value checks name it instead).
    Kills dropping _both_nan."""
    from tests.hard_cases.conftest import compose

    cfg = compose("shape=cube", "model=mesh", out_dir=tmp_path)
    cfg["train"] = {**cfg["train"], "max_seconds": float("nan")}
    cli.check_levels_keep(cfg, {"model": "mesh"}, ["train.max_seconds=nan"])
