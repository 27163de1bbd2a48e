"""The suite file names the benchmark: a tier's plan expands each experiment's own grid, a malformed file or an
unknown tier is one line, and `status` tells a report whose code or config changed since its records."""

import os
import subprocess

import pytest

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.report import compact, suite
from ddfbench.run import runs

ROOT = suite.ROOT


def test_the_core_plan_expands_each_experiment_as_its_sweep_does():
    rows = {r["experiment"]: r for r in suite.plan("v1", "core")}
    assert rows["default"]["jobs"] == len(plugins.members("model", "default")) * 3  # seed=0,1,2 in the suite file
    assert rows["representations"]["jobs"] == len(plugins.members("model", "representations")) * 4 * 5
    assert rows["default"]["cpu_hours"] > 0 and rows["default"]["sources"] == ["reports/default"]
    rows = {r["experiment"]: r for r in suite.plan("v1", "long", only=["shape_suite", "tune_finalists"])}
    assert rows["shape_suite"]["jobs"] == len(plugins.members("model", "shape_suite")) * 12 * 3
    assert rows["tune_finalists"]["jobs"] == len(plugins.members("model", "tune_finalists")) * 3 * 4 * 3


def timed(model, level, seconds, fit_seconds, experiment="pareto"):
    return {"model": model, "experiment": experiment, "overrides": [f"model={model}", f"capacity={level}"],
            "started": "2026-01-01T00:00:00+00:00",
            "finished": f"2026-01-01T00:{seconds // 60:02d}:{seconds % 60:02d}+00:00",
            "fit": {"seconds": fit_seconds}}


def test_a_job_costs_what_its_own_level_cost_and_a_wall_clock_job_at_least_its_bound():
    entry = suite.Entry("pareto", "reports/pareto")
    records = {"reports/pareto": [timed("m", "c1", 10, 8), timed("m", "c4", 100, 90)],
               "reports/other": [timed("m", "c4", 500, 490, experiment="storage"), timed("m", "c3", 300, 290)]}
    assert suite.job_seconds(entry, suite.Job("m", "c4", "steps", 20.0), records) == (100, "reports/pareto")
    # no c2 in its own report: the model's median there
    assert suite.job_seconds(entry, suite.Job("m", "c2", "steps", 20.0), records) == (55, "reports/pareto")
    # not in its own report: the same experiment's level elsewhere; another experiment's c4 is another network
    others = {"reports/other": records["reports/other"]}
    assert suite.job_seconds(entry, suite.Job("m", "c3", "steps", 20.0), others) == (300, "other reports")
    assert suite.job_seconds(entry, suite.Job("m", "c4", "steps", 20.0), others) == (400, "other reports")
    clock = suite.Job("m", "c1", "wall-clock", 600.0)
    assert suite.job_seconds(entry, clock, records) == (602, "reports/pareto")  # 600 s + 2 s outside the fit
    assert suite.job_seconds(entry, suite.Job("x", "c1", "wall-clock", 600.0), records) == (None, "no record")
    long = {r["experiment"]: r for r in suite.plan("v1", "long", only=["convergence", "gan_epochs"])}
    assert long["convergence"]["cpu_hours"] >= long["convergence"]["jobs"] * 600 / 3600
    # a fixed-work job's fit time is scaled to its own steps or epochs: 10 s outside the fit + 20 s x 40 / 0.5
    short = {**timed("g", "", 30, 20), "fit": {"seconds": 20, "epochs": 0.5, "steps": 100}}
    assert suite.job_seconds(entry, suite.Job("g", "", "epochs", 0.0, 40.0), {"r": [short]}) == (1610, "other reports")
    assert suite.job_seconds(entry, suite.Job("g", "", "steps", 0.0, 200.0), {"r": [short]}) == (50, "other reports")
    assert suite.job_seconds(entry, suite.Job("g", "", "steps", 0.0), {"r": [short]}) == (30, "other reports")
    no_epochs = {**short, "fit": {"seconds": 20, "epochs": None, "steps": 100}}  # unknown work: unscaled
    assert suite.job_seconds(entry, suite.Job("g", "", "epochs", 0.0, 40.0), {"r": [no_epochs]}) == (30, "other reports")
    # a fit resumed from its checkpoint: started..finished spans its last process only (60 s of a 100 s fit)
    resumed = {**timed("g", "", 60, 100), "fit": {"seconds": 100, "epochs": 40.0, "steps": 1000}}
    assert suite.job_seconds(entry, suite.Job("g", "", "epochs", 0.0, 40.0), {"r": [resumed]}) == (100, "other reports")
    assert suite.job_seconds(entry, suite.Job("g", "", "epochs", 0.0, 80.0), {"r": [resumed]}) == (200, "other reports")
    # a level's own steps (conf/model/*.yaml experiments part: pareto's c1 of the tuned GAN is 9 steps)
    levels = {job.level: job.work for job in suite.expand(suite.Entry("pareto", "x")).jobs if job.model == "gan_sdf_tuned"}
    assert levels["c1"] == 9.0 and levels["c1"] < levels["c4"]
    # the thesis GAN's 40 epochs (model.epochs through the experiment's interpolation), 5 seeds: hours, not minutes
    assert {job.work for job in suite.expand(suite.Entry("gan_epochs", "x")).jobs} == {40.0}
    assert long["gan_epochs"]["cpu_hours"] > 5
    # a swept bound is each job's own: 20 s and 80 s jobs
    swept = suite.expand(suite.Entry("convergence", "x", ["train.max_seconds=20,80"]))
    assert {job.max_seconds for job in swept.jobs} == {20.0, 80.0}
    assert {job.budget for job in swept.jobs} == {"wall-clock"}


def test_a_bad_suite_or_tier_is_one_line_naming_it(tmp_path, monkeypatch):
    with pytest.raises(InputError, match=r"suite v1: no tier 'fast' \(tiers: core, long, gpu\)"):
        suite.plan("v1", "fast")
    with pytest.raises(InputError, match=r"suite v1, tier core: no experiment gan_epochs \(it has default, "):
        suite.plan("v1", "core", only=["default", "gan_epochs"])
    assert [r["experiment"] for r in suite.plan("v1", "long", only=["paper_ddf", "storage"])] == ["storage", "paper_ddf"]
    (tmp_path / "suite").mkdir()
    (tmp_path / "experiment").mkdir()
    (tmp_path / "suite" / "bad.yaml").write_text("tiers:\n  core:\n    nonesuch: {report: reports/x}\n")
    monkeypatch.setattr(suite, "CONF_DIR", str(tmp_path))
    with pytest.raises(InputError, match=r"conf/suite/bad.yaml: tiers.core.nonesuch: no conf/experiment/nonesuch.yaml"):
        suite.load_suite("bad")
    with pytest.raises(InputError, match=r"suite 'v2': no conf/suite/v2.yaml \(suites: bad\)"):
        suite.load_suite("v2")
    with pytest.raises(InputError, match=r"suite 'v2': no conf/suite/v2.yaml \(suites: bad\)"):
        suite.load_neutral("v2")  # `status` reads it first: one line too, not a FileNotFoundError


@pytest.mark.parametrize("text, says", [
    ("tiers:\n  core:\n    default: {report: r, overides: [seed=0]}\n",  # misspelt: it ran without its seeds
     r"tiers.core.default: unknown key overides \(known: report, overrides\)"),
    ("tiers:\n  core:\n    default: {report: r, overrides: 'seed=0,1'}\n",  # a string: one override a character
     r"tiers.core.default.overrides: needs a list of overrides \(strings\), not 'seed=0,1'"),
    ("tiers:\n  core:\n    - default\n", r"tiers.core: needs \{experiment: \{report: ...\}\}, not a list"),
    ("tiers:\n  core:\n    default: {report: r\n", r"not a readable YAML file \(expected ',' or '\}'.* at line 4\)"),
    ("- tiers\n", r"needs a mapping of version, tiers, result_neutral, not a list"),
    ("teirs: {}\n", r"unknown key teirs \(known: version, tiers, result_neutral\)"),
])
def test_a_suite_file_with_a_typo_is_one_line_naming_the_key(tmp_path, monkeypatch, capsys, text, says):
    """A misspelt key, a wrong type or broken YAML in a suite file: one line naming the file and key, exit 2 (a
    misspelt `overrides` was ignored, a string split into characters, the rest tracebacks)."""
    (tmp_path / "suite").mkdir()
    (tmp_path / "experiment").mkdir()
    (tmp_path / "experiment" / "default.yaml").write_text("")
    (tmp_path / "suite" / "bad.yaml").write_text(text)
    monkeypatch.setattr(suite, "CONF_DIR", str(tmp_path))
    with pytest.raises(InputError, match=r"^conf/suite/bad.yaml: " + says):
        suite.load_suite("bad")
    assert suite.main(["run", "bad", "--tier", "core", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ddfbench.suite: conf/suite/bad.yaml: ") and err.count("\n") == 1


def sha(rev):
    return subprocess.run(["git", "-C", ROOT, "rev-parse", rev], capture_output=True, text=True, check=True).stdout.strip()


def repo_with(folder, path, text):
    """A git repository in folder whose one commit holds `path` with `text`: (git, that commit), git run in folder
    (its output, stripped) as a committer named t."""
    def git(*args):
        return subprocess.run(["git", "-C", str(folder), "-c", "user.name=t", "-c", "user.email=t@t", *args],
                              capture_output=True, text=True, check=True).stdout.strip()

    (folder / path).parent.mkdir(parents=True)
    (folder / path).write_text(text)
    git("init", "-q")
    git("add", "-A")
    git("commit", "-qm", "ran")
    return git, git("rev-parse", "HEAD")


def record(commit, family, model):
    return {"env": {"code_sha": commit}, "family": family, "model": model}


def test_status_is_current_at_head_and_names_what_changed_but_not_a_membership_change():
    entry = suite.Entry("shape_suite", "reports/shape_suite")
    assert suite.stale(entry, [record(sha("HEAD"), "grid_sdf", "grid_sdf")])[1] == []
    # c65d9ad added the CAD shapes to the catalog and made grid_sdf join shape_suite (its YAML's experiments part)
    before = sha("c65d9ad~1")
    _, changed = suite.stale(entry, [record(before, "grid_sdf", "grid_sdf")])
    assert "ddfbench/truth/catalog.py" in changed and "conf/model/grid_sdf.yaml" not in changed
    assert suite._only_membership_changed(before, "conf/model/grid_sdf.yaml")
    assert not suite._only_membership_changed(before, "conf/model/neural_sdf.yaml")  # gained its grid keys since
    # a048786 added the device tracer to ddfbench/evaluate, a stage every run depends on; no run's code changed by it
    _, changed = suite.stale(entry, [record(sha("a048786~1"), "grid_sdf", "grid_sdf")])
    assert "ddfbench/evaluate/trace_device.py" not in changed and not any(c.startswith("commit") for c in changed)
    assert os.path.isfile(os.path.join(ROOT, "conf", "suite", "v1.yaml"))


def test_status_leaves_out_the_modules_that_write_nothing_into_a_record():
    entry = suite.Entry("default", "reports/default")
    # b4d251d changed the input checks alone; 2da0d56 the progress lines and the runner
    _, changed = suite.stale(entry, [record(sha("b4d251d~1"), "grid_sdf", "grid_sdf")])
    assert "ddfbench/run/checks.py" not in changed
    _, changed = suite.stale(entry, [record(sha("2da0d56~1"), "grid_sdf", "grid_sdf")])
    assert "ddfbench/run/runner.py" in changed and "ddfbench/run/progress.py" not in changed


@pytest.mark.parametrize("model", ["mesh", "grid_sdf", "neural_sdf_tuned", "ddf_tuned", "ddf_paper", "gan_sdf"])
def test_the_checks_a_job_passes_leave_its_config_as_it_was(tmp_path, model):
    """ddfbench/run/checks.py is RESULT_NEUTRAL: a job it lets through runs the config it was given."""
    import copy

    from ddfbench.run.checks import check_job
    from tests.hard_cases.conftest import compose

    cfg = compose(f"model={model}", "scene=depth", out_dir=tmp_path)
    before = copy.deepcopy(cfg)
    check_job(cfg)
    assert cfg == before


def test_run_adds_the_overrides_after_the_double_dash_to_every_experiment_and_writes_each_report(monkeypatch):
    commands = []

    class Done:
        returncode = 0

    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or Done())
    assert suite.main(["run", "v1", "--tier", "core", "--results", "out", "--", "threads=1", "hydra/launcher=ray"]) == 0
    fits = [c for c in commands if c[2] == "ddfbench"]
    assert [c[3] for c in fits] == [f"+experiment={e.experiment}" for e in suite.load_suite("v1")["core"]]
    assert all(c[4:] == ["out_dir=out", "quiet=true", *suite.load_suite("v1")["core"][i].overrides, "threads=1",
                         "hydra/launcher=ray"] for i, c in enumerate(fits))  # no "--" leaks into a command
    reports = [c for c in commands if c[2] == "ddfbench.report"]
    assert [c[3] for c in reports][:2] == [os.path.join("out", "default"), os.path.join("out", "representations")]


def test_the_report_reads_the_records_folder_an_experiment_name_override_names(monkeypatch, tmp_path):
    """The gpu tier's convergence run named apart from the long tier's (its records would otherwise pool with the
    CPU's in one results folder): the report is written from the folder the runs wrote."""
    commands = []

    class Done:
        returncode = 0

    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or Done())
    assert suite.main(["run", "v1", "--tier", "gpu", "--results", str(tmp_path), "--",
                       "experiment_name=convergence_gpu_try"]) == 0
    (report,) = [c for c in commands if c[2] == "ddfbench.report"]
    assert report[3] == str(tmp_path / "convergence_gpu_try")


def test_a_sweep_with_failed_jobs_keeps_the_committed_report_and_writes_its_own_beside_the_records(
        monkeypatch, tmp_path, capsys):
    commands = []

    class Failed:
        returncode = 1  # ddfbench: k of n jobs failed

    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or Failed())
    assert suite.main(["run", "v1", "--tier", "core", "--only", "default", "--results", str(tmp_path),
                       "--", "eval.n_points=0"]) == 1
    (report,) = [c for c in commands if c[2] == "ddfbench.report"]
    assert report[3:] == [str(tmp_path / "default"), "--out", str(tmp_path / "default" / "report")]
    out = capsys.readouterr().out
    assert "reports/default is kept as committed" in out
    assert f"$ python -m ddfbench +experiment=default out_dir={tmp_path} quiet=true" in out  # a line to paste


def test_run_refuses_a_results_path_that_is_not_a_folder_before_any_sweep(monkeypatch, tmp_path, capsys):
    commands = []
    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd))
    (tmp_path / "afile").write_text("")
    assert suite.main(["run", "v1", "--tier", "core", "--results", str(tmp_path / "afile")]) == 2
    assert commands == []
    assert capsys.readouterr().err == f"ddfbench.suite: --results {tmp_path / 'afile'}: exists and is not a folder\n"


def test_run_runs_the_sweeps_the_records_ask_for_then_writes_the_report(monkeypatch, tmp_path):
    commands, asked = [], []

    class Done:
        returncode = 0

    def confirmation(records):  # the protocol's follow-up, on the sweep's records
        asked.append(records)
        return [["+experiment=tune_finalists", "model=m", "capacity=a,b", "seed=3,4,5"]]

    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or Done())
    monkeypatch.setitem(suite.FOLLOW_UPS, "tune_finalists", confirmation)
    ran_through = {"value": True}  # every job of the sweep has a record (status.sweep_status: nothing missing)
    monkeypatch.setattr(suite, "sweep_ran_through", lambda folder, code, since: ran_through["value"])
    run = ["run", "v1", "--tier", "long", "--only", "tune_finalists", "--results", str(tmp_path), "--", "threads=1"]
    assert suite.main(run) == 0 and commands[1][2] == "ddfbench.report" and len(commands) == 2  # no records: none
    commands.clear()
    (tmp_path / "tune_finalists").mkdir()
    assert suite.main(run) == 0 and asked == [[]]
    assert [c[2] for c in commands] == ["ddfbench", "ddfbench", "ddfbench.report"]  # the report once, at the end
    assert commands[1][3:] == ["+experiment=tune_finalists", "model=m", "capacity=a,b", "seed=3,4,5",
                               f"out_dir={tmp_path}", "quiet=true", "threads=1"]  # into the same out_dir
    assert commands[2][2:] == ["ddfbench.report", str(tmp_path / "tune_finalists"), "--out",
                               os.path.join(ROOT, "reports", "tune_finalists")]
    # a follow-up that fails: the committed report is kept, this one goes beside the records
    commands.clear()
    codes = iter([0, 1, 0])
    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or type(
        "Ran", (), {"returncode": next(codes)}))
    assert suite.main(run) == 1
    assert commands[2][2:] == ["ddfbench.report", str(tmp_path / "tune_finalists"), "--out",
                               str(tmp_path / "tune_finalists" / "report")]
    # a sweep cut short (killed: a negative code): its report is written, the follow-ups wait for all its runs
    commands.clear()
    asked.clear()
    ran_through["value"] = False

    class Killed:
        returncode = -9

    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or Killed())
    assert suite.main(run) == 1 and [c[2] for c in commands] == ["ddfbench", "ddfbench.report"] and asked == []


def test_run_from_reports_restores_each_report_s_committed_records_before_its_sweep(monkeypatch, tmp_path, capsys):
    commands = []

    class Done:
        returncode = 0

    monkeypatch.setattr(suite.subprocess, "run", lambda cmd, **_: commands.append(cmd) or Done())
    committed = compact.read_compact(os.path.join(suite.ROOT, "reports", "default", compact.FILE))
    (records_commit,) = runs.code_commits(committed)
    # from a checkout of other code: refused before any run, naming the report and both commits
    monkeypatch.setenv(runs.GIT_SHA_ENV, "0" * 40)
    assert suite.main(["run", "v1", "--tier", "core", "--only", "default", "--results", str(tmp_path),
                       "--from-reports"]) == 2
    err = capsys.readouterr().err
    assert f"reports/default's records are of code {records_commit[:7]}, this checkout's code is 0000000" in err
    assert commands == [] and not (tmp_path / "default").exists()
    # from a worktree at the records' commit: every ok record is restored, then the sweep and the report run
    monkeypatch.setenv(runs.GIT_SHA_ENV, records_commit)
    assert suite.main(["run", "v1", "--tier", "core", "--only", "default", "--results", str(tmp_path),
                       "--from-reports"]) == 0
    ok = sorted(r["key"] for r in committed if r["status"] == "ok")
    assert sorted(os.listdir(tmp_path / "default")) == ok
    assert f"default: restored {len(ok)} committed records" in capsys.readouterr().out
    assert [c[2:4] for c in commands] == [["ddfbench", "+experiment=default"],  # the sweep (now skipping them)
                                          ["ddfbench.report", os.path.join(str(tmp_path), "default")]]


def test_the_version_is_the_suite_s_and_the_changelog_opens_with_it():
    from omegaconf import OmegaConf

    import ddfbench

    suite_version = OmegaConf.load(os.path.join(ROOT, "conf", "suite", "v1.yaml")).version
    assert ddfbench.__version__.split(".")[0] == str(suite_version)
    with open(os.path.join(ROOT, "CHANGELOG.md")) as fh:
        first = next(line for line in fh if line.startswith("## "))
    assert first.startswith(f"## {ddfbench.__version__} — suite v{suite_version}")


def test_the_plan_says_which_experiments_add_sweeps_it_does_not_count(capsys):
    row = {"jobs": 4, "cpu_hours": 1.0, "unknown": [], "report": "r", "sources": ["r"]}
    suite.print_plan([{**row, "experiment": "tune_finalists"}, {**row, "experiment": "default"}])
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].strip() == "+ the sweeps its report asks for once it has run (not counted)"
    assert lines[2].startswith("default") and lines[3].startswith("total")  # none after default


def test_a_file_changed_only_by_result_neutral_commits_is_not_stale(monkeypatch, tmp_path):
    """A commit the suite file declares result-neutral (it changed the stale scope, no measured value) is not
    counted; a later change of the same file is."""
    git, ran = repo_with(tmp_path, "ddfbench/run/runner.py", "ran")

    def commit(text):
        (tmp_path / "ddfbench" / "run" / "runner.py").write_text(text)
        git("commit", "-qam", text)
        return git("rev-parse", "HEAD")

    monkeypatch.setattr(suite, "ROOT", str(tmp_path))
    monkeypatch.setattr(suite, "CONF_DIR", str(tmp_path / "conf"))
    entry, recs = suite.Entry("default", "reports/default"), [record(ran, "mesh", "mesh")]
    atomic = commit("an atomic writer")
    (tmp_path / "conf" / "suite").mkdir(parents=True)
    (tmp_path / "conf" / "suite" / "s.yaml").write_text(f"result_neutral: {{'{atomic[:7]}': writes the same bytes}}")
    neutral = suite.load_neutral("s")
    assert neutral == {atomic: "writes the same bytes"}  # an abbreviation, resolved
    assert suite.stale(entry, recs) == (ran[:7], ["ddfbench/run/runner.py"])
    assert suite.stale(entry, recs, neutral) == (ran[:7], [])
    commit("a new loss")
    assert suite.stale(entry, recs, neutral) == (ran[:7], ["ddfbench/run/runner.py"])
    git("checkout", "-q", "-b", "side", ran)  # records of a commit that is not an ancestor of HEAD: its own change
    side = commit("a change of the side branch")  # is in the difference, whatever HEAD's commits were
    git("checkout", "-q", "-")
    git("reset", "-q", "--hard", atomic)
    assert suite.stale(entry, [record(side, "mesh", "mesh")], neutral) == (side[:7], ["ddfbench/run/runner.py"])


def test_a_change_of_the_mesh_family_stales_every_report_it_renders_references_for(monkeypatch, tmp_path):
    """Every record's reference frame is the full mesh's BVH through the mesh family (render.mesh_reference), so a
    report of DDF runs alone is stale when that family's code changed."""
    git, ran = repo_with(tmp_path, "ddfbench/models/mesh.py", "cast on every core")
    (tmp_path / "ddfbench" / "models" / "mesh.py").write_text("cast on the run's threads")
    git("commit", "-qam", "threads")
    monkeypatch.setattr(suite, "ROOT", str(tmp_path))
    assert suite.stale(suite.Entry("render_time", "r"), [record(ran, "ddf", "ddf_tuned")]) == (
        ran[:7], ["ddfbench/models/mesh.py"])


def test_a_malformed_result_neutral_entry_is_one_line_naming_it(monkeypatch, tmp_path, capsys):
    (tmp_path / "suite").mkdir()
    monkeypatch.setattr(suite, "CONF_DIR", str(tmp_path))
    (tmp_path / "suite" / "s.yaml").write_text("result_neutral: {abc: same}\n")
    with pytest.raises(InputError, match=r"^conf/suite/s.yaml: result_neutral.abc: needs a commit \(7 to 40 hex"):
        suite.load_neutral("s")
    (tmp_path / "suite" / "s.yaml").write_text("result_neutral: {abcdef0: ''}\n")
    with pytest.raises(InputError, match=r"result_neutral.abcdef0: needs a commit .* and why"):
        suite.load_neutral("s")
    (tmp_path / "suite" / "s.yaml").write_text("result_neutral: {'0000000': same}\n")
    assert suite.load_neutral("s") == {}  # a shallow clone: status still runs, and counts nothing for it
    assert capsys.readouterr().err == ("ddfbench.suite: conf/suite/s.yaml: result_neutral.0000000: not a commit of "
                                       "this clone (a shallow clone?): not counted\n")
    (tmp_path / "suite" / "s.yaml").write_text("tiers: {}\n")
    assert suite.load_neutral("s") == {}


def test_the_suite_refuses_a_tree_that_is_not_a_git_checkout(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(suite, "ROOT", str(tmp_path))  # a wheel's site-packages: reports/ there is no one's
    assert suite.main(["run", "v1", "--tier", "core", "--dry-run"]) == 2
    assert capsys.readouterr().err == (f"ddfbench.suite: {tmp_path}: not the top of a git checkout of ddfbench; the "
                                       "suite reads and writes the committed reports/ of one (git clone the "
                                       "repository, then pip install -e . in it)\n")


def test_records_that_name_no_code_commit_are_unknown_not_current(monkeypatch, capsys):
    monkeypatch.setattr(suite, "committed_records", lambda _: {
        "reports/default": [{"env": {"code_sha": None}, "family": "mesh", "model": "mesh"}]})
    assert suite.status("v1") == 1
    line = next(x for x in capsys.readouterr().out.splitlines() if " reports/default " in x)
    assert line.split()[3:] == ["unknown", "records", "that", "name", "no", "code", "commit"]


def test_an_empty_only_is_refused_and_a_reader_that_goes_away_gets_no_traceback(capsys):
    import sys

    assert suite.main(["run", "v1", "--tier", "core", "--only", "", "--dry-run"]) == 2
    assert capsys.readouterr().err == "ddfbench.suite: --only '': names no experiment\n"
    proc = subprocess.Popen([sys.executable, "-m", "ddfbench.suite", "status", "v1"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT, text=True)
    proc.stdout.close()  # `| head -0`: the reader is gone before the first line
    err = proc.stderr.read()
    proc.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err


def test_the_plan_counts_the_overrides_run_adds_after_a_double_dash(capsys):
    assert suite.main(["run", "v1", "--tier", "core", "--only", "default", "--dry-run"]) == 0
    every_seed = capsys.readouterr().out
    assert suite.main(["run", "v1", "--tier", "core", "--only", "default", "--dry-run", "--", "seed=0"]) == 0
    one_seed = capsys.readouterr().out
    jobs = lambda out: int(out.split()[1])  # noqa: E731  "default  18 jobs ..."
    assert jobs(every_seed) == 3 * jobs(one_seed)  # the suite's seed=0,1,2, then the command line's seed=0
