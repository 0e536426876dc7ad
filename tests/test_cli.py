import json
import math
import re

import pytest
from tltrack.app import app
from tltrack.app.experiment import _print_table
from typer.testing import CliRunner

pytestmark = pytest.mark.unit

runner = CliRunner()


def test_experiment_writes_results_and_figures(tmp_path):
    r = runner.invoke(
        app,
        [
            "experiment",
            "--scenario",
            "ct",
            "--preset",
            "arasaratnam-haykin",
            "--truth",
            "noise-free",
            "--filters",
            "pf,tl-pf,ukf",
            "--particles",
            "200",
            "--runs",
            "4",
            "--primary-intensity",
            "4",
            "--seed",
            "1",
            "--workers",
            "1",
            "--out",
            str(tmp_path),
        ],
    )
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["config"]["primary_intensity"] == 4 and doc["config"]["particles"] == 200
    assert {"pf", "tl-pf", "ukf", "source-pf"} == set(doc["filters"])
    for png in ("rmse.png", "trajectory.png"):
        assert (tmp_path / png).stat().st_size > 10_000
    (tmp_path / "rmse.png").unlink()
    assert runner.invoke(app, ["plot", str(tmp_path / "results.json")]).exit_code == 0
    assert (tmp_path / "rmse.png").exists()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--particles", "-1"], "particles"),
        (["--truth", "sometimes"], "truth"),
        (["--filters", "pf,kalman"], "kalman"),
        (["--source-intensity", "0"], "intensity"),
        (["--filters", ","], "--filters: name at least one filter"),
        (["--filters", "pf,ukf,pf"], "['pf'] named twice"),
        (["--clutter-rate", "1e9", "--pd", "0.9"], "clutter_rate"),
        (["--runs", "100000000"], "runs"),
        (["--batch-size", "0"], "--batch-size"),
        (["--workers", "0"], "--workers"),
    ],
)
def test_bad_options_are_refused_naming_the_field(tmp_path, args, needle):
    r = runner.invoke(app, ["experiment", "--runs", "1", "--out", str(tmp_path), *args])
    assert r.exit_code == 2
    assert needle in " ".join(r.output.split()), r.output


def test_a_source_may_not_take_the_primarys_id(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[[sources]]\nid = "primary"\n')
    r = runner.invoke(app, ["experiment", "--config", str(cfg), "--out", str(tmp_path)])
    assert "the id 'primary' is the primary's own sensor's" in " ".join(r.output.split())
    assert r.exit_code == 2


@pytest.mark.parametrize(
    "args",
    [
        ["experiment", "--runs", "1", "--particles", "100"],
        ["study", "robust", "--runs", "2", "--particles", "100"],
        ["reproduce", "--runs", "2", "--losses-only"],
        ["fit", "--truth-file", "examples/tracks/sim-turn-sequence.csv"],
    ],
)
def test_an_output_that_cannot_be_written_is_refused_before_any_work(tmp_path, args):
    """Not a traceback at the end that loses the results: refused at once, naming it."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    out = blocker / ("f.toml" if args[0] == "fit" else "out")  # under a file: never a folder
    r = runner.invoke(app, [*args, "--out", str(out)])
    assert r.exit_code == 2, r.output
    assert f"--out{out}" in "".join(r.output.split()), r.output  # wrapped anywhere
    assert r.output.lstrip().startswith("error: --out"), "refused after the work began"


@pytest.mark.parametrize("command", [["study", "robust"], ["reproduce"]])
def test_a_study_of_one_run_is_refused(command):
    """One run has no Monte-Carlo error: its report's error bars were NaN."""
    r = runner.invoke(app, [*command, "--runs", "1"])
    assert r.exit_code == 2 and "Invalid value for '--runs'" in r.output, r.output


def test_help_has_examples():
    r = runner.invoke(app, ["experiment", "--help"])
    assert r.exit_code == 0 and "Examples" in r.output


def _commands(group, path=()):
    """Every command of the CLI, as (its words, the click command)."""
    for name, cmd in group.commands.items():
        if hasattr(cmd, "commands"):
            yield from _commands(cmd, (*path, name))
        else:
            yield (*path, name), cmd


def _literal(word: str) -> str:
    """A word of help as it should print: no markdown code marks or escapes, no end stop."""
    return word.replace("`", "").replace("\\", "").rstrip(".,:;)")


def test_help_prints_placeholders_and_wildcards_as_written():
    """The help is markdown: an unquoted <id> was dropped as an HTML tag and a pair of * taken
    for emphasis, so ``subscribe -k 'tltrack/source/*/transfer/*'`` printed without its stars."""
    import typer.main

    checked = 0
    for words, cmd in _commands(typer.main.get_command(app)):
        texts = [
            cmd.help or "",
            cmd.epilog or "",
            *(getattr(p, "help", "") or "" for p in cmd.params),
        ]
        wanted = {_literal(w) for t in texts for w in t.split() if re.search(r"[<>*]", w)}
        r = runner.invoke(app, [*words, "--help"], terminal_width=400)
        said = " ".join(r.output.replace("│", " ").split())
        for word in wanted:
            checked += 1
            assert word in said, (words, word)
    assert checked >= 6  # source/<id> twice, router-<operator>, the key expression, ...


@pytest.mark.parametrize(
    "name", ["robust", "sources", "budget", "heterogeneous", "presets", "intensities"]
)
def test_each_study_writes_its_table_with_paired_differences(tmp_path, name):
    args = ["study", name, "--runs", "3", "--particles", "300", "--out", str(tmp_path)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    assert (tmp_path / f"{name}.json").exists()
    text = (tmp_path / f"{name}.md").read_text()
    rows = [ln for ln in text.splitlines() if ln.startswith("| ") and "---" not in ln]
    assert len(rows) >= 5, text  # a header and a row per configuration
    if name != "budget":
        assert re.search(r"[+-]\d+\.\d{3} \(\d+\.\d{3}\)", text), text  # difference (MC error)


def test_the_realizations_study_places_the_papers_numbers_in_its_distribution(tmp_path):
    args = ["study", "realizations", "--realizations", "3", "--runs", "2", "--particles", "200"]
    args += ["--filters", "ukf,tl-ukf", "--out", str(tmp_path)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    text = (tmp_path / "realizations.md").read_text()
    ukf4 = next(ln for ln in text.splitlines() if ln.startswith("| 4 | ukf |"))
    assert "17.95" in ukf4 and re.search(r"\d+ %", ukf4), ukf4  # Table 2's UKF, its percentile
    assert (tmp_path / "realizations.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["robust", "--kind", "sir"], "--kind: unknown kind 'sir'"),
        (["robust", "--source-filter", "x"], "--source-filter"),
        (["realizations", "--realizations", "1"], "--realizations must be at least 2"),
        (["nope"], "unknown study 'nope'"),
        (["realizations", "--truth-file", "examples/tracks/x.csv"], "truth"),
        # another study's option was ignored, and the study ran as if it was not given
        (["robust", "--filters", "zz"], "--filters is an option of study realizations, not of"),
        (["clutter", "--realizations", "5"], "--realizations is an option of study realizations"),
        (["links", "--tracks", "examples/tracks"], "--tracks is an option of study manoeuvres"),
    ],
)
def test_bad_study_options_are_refused_naming_them(tmp_path, args, needle):
    r = CliRunner().invoke(app, ["study", *args, "--runs", "2", "--out", str(tmp_path)])
    assert r.exit_code == 2 and needle in " ".join(r.output.split()), r.output


def test_the_bench_times_every_row_side_by_side(tmp_path):
    """What it measures, not how fast: every row present (Stone Soup only with its extra)."""
    out = tmp_path / "bench.json"
    args = ["bench", "--particles", "200", "--repeats", "1", "--json", str(out)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    timed = {n: v for n, v in doc["ms_per_step"].items() if n != "stonesoup"}
    assert set(timed) >= {"tl-pf", "pf", "source-pf", "tl-rpf", "rpf", "source-rpf", "user-model"}
    assert all(v is not None and v > 0 for v in timed.values()), timed
    assert set(doc["rpf_over_pf"]) == {"", "tl-", "source-"}


def test_the_clutter_bench_times_each_filter_clean_and_on_dense_scans(tmp_path):
    """What it measures, not how fast: both filters, clean and in clutter, with their RMSE."""
    out = tmp_path / "bench.json"
    args = ["bench", "--clutter", "--particles", "200", "--repeats", "1", "--steps", "4"]
    r = CliRunner().invoke(app, [*args, "--json", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    timed = {n: v for n, v in doc["median_ms"].items() if n != "stonesoup elpf"}
    assert set(timed) == {"rpf", "pf", "rpf in clutter", "pf in clutter"}
    assert all(v > 0 for v in timed.values()) and set(doc["ratio"]) == {"rpf", "pf"}
    assert all(math.isfinite(v) for v in doc["rmse_m"].values()), doc["rmse_m"]
    assert doc["steps_timed"] == 4 and doc["detections_per_scan"] == 1000


def test_the_results_table_marks_a_nees_over_a_singular_covariance(capsys):
    row = {
        "rmse_overall": 20.0,
        "lost_fraction": 0.0,
        "ms_per_step": None,
        "nis": 2.1,
        "nis_above_band": 0.0,
        "consistency": "",
    }
    doc = {
        "filters": {
            "pf": {**row, "nees": 3.6e7, "nees_singular_rate": 0.01},
            "rpf": {**row, "nees": 7.646, "nees_singular_rate": 0.0},
        }
    }
    _print_table(doc)
    out = capsys.readouterr().out
    assert "3.6e+07*" in out and "7.646 " in out and "7.646*" not in out
    assert "singular" in out


def test_progress_in_a_log_file_is_a_line_a_minute(monkeypatch):
    """Rich redraws its bar only on a terminal: to a file, a long run writes its count and the
    time left at the mean rate so far, at most once a LOG_EVERY_S; runs read back from a
    checkpoint at the start are left out of the rate."""
    import io

    from rich.console import Console
    from tltrack.app import common

    log = io.StringIO()
    monkeypatch.setattr(common, "console", Console(file=log, force_terminal=False, width=200))
    monkeypatch.setattr(common, "LOG_EVERY_S", 0.0)
    monkeypatch.setattr(common, "READ_BACK_S", 3600.0)  # everything at once: read back
    with common.progress_bar(10, "sweep") as bar:
        task = bar.add_task("sweep", total=10)
        bar.advance(task, 6)
        monkeypatch.setattr(common, "READ_BACK_S", 0.0)  # from now on, runs run
        bar.advance(task, 2)
        monkeypatch.setattr(common, "LOG_EVERY_S", 3600.0)
        bar.advance(task, 1)  # within the hour: no line
    lines = [s for s in log.getvalue().splitlines() if s.startswith("sweep: ")]
    assert lines[0] == "sweep: 6/10 (60%) after 0:00:00", lines  # no rate from read-back runs
    assert re.fullmatch(r"sweep: 8/10 \(80%\) after 0:00:0\d, about 0:00:\d\d left", lines[1])
    assert len(lines) == 2, lines


def test_a_task_that_waits_for_others_is_timed_from_its_own_start(monkeypatch):
    """reproduce's jobs run one sweep after another: a job's time left comes from its own runs,
    not from the hours it waited (it starts at its sweep's first, empty advance)."""
    import io

    from rich.console import Console
    from tltrack.app import common

    log = io.StringIO()
    monkeypatch.setattr(common, "LOG_EVERY_S", 0.0)
    clock = [0.0]
    console = Console(file=log, force_terminal=False, width=200)
    with common.LoggedProgress("jobs", console=console, get_time=lambda: clock[0]) as bar:
        first = bar.add_task("first", total=10, start=False)
        later = bar.add_task("later", total=10, start=False)
        bar.advance(first, 0)
        clock[0] = 3600.0
        bar.advance(first, 10)  # an hour for the first job
        bar.advance(later, 0)  # the later job's sweep starts
        clock[0] = 3610.0
        bar.advance(later, 5)
    lines = [s for s in log.getvalue().splitlines() if s.startswith("later: ")]
    assert lines[-1] == "later: 5/10 (50%) after 0:00:10, about 0:00:10 left", lines


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("[1]", "unsupported results schema None"),
        ('{"schema_version": 0}', "unsupported results schema 0"),
        ("{", "cannot read"),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),  # RecursionError: a traceback
    ],
)
def test_plot_refuses_a_file_that_is_not_a_results_json(tmp_path, text, says):
    bad = tmp_path / "results.json"
    bad.write_text(text)
    r = runner.invoke(app, ["plot", str(bad)])
    assert r.exit_code == 2 and says in " ".join(r.output.split()), r.output


@pytest.mark.parametrize(
    ("content", "name", "says", "not_said"),
    [
        (b"\xff\xfe", "c.toml", "not UTF-8 text", "codec"),
        (b"a: 1\n", "c.yaml", "not valid JSON (a config is .toml, or else JSON)", "YAML"),
        (b'preset = "bogus"\n', "c.toml", "preset: Input should be", "Field required"),
        (b"[primary_detection]\npd = nan\n", "c.toml", "pd: Input should be a finite", "<= 1"),
        (b"runs = true\n", "c.toml", "runs: Value error, a whole number, not True", "should be"),
        (b'runs = "3"\n', "c.toml", "runs: Value error, a whole number, not '3'", "should be"),
        (
            b'recovery = "yes"\n',
            "c.toml",
            "recovery: Value error, true or false, not 'yes'",
            "should be",
        ),
    ],
)
def test_a_bad_config_file_is_named_with_its_one_problem(tmp_path, content, name, says, not_said):
    cfg = tmp_path / name
    cfg.write_bytes(content)
    r = runner.invoke(app, ["experiment", "--config", str(cfg), "--out", str(tmp_path)])
    said = " ".join(r.output.split())
    assert r.exit_code == 2 and says in said and not_said not in said, r.output


@pytest.fixture(scope="module")
def small_results(tmp_path_factory) -> dict:
    """A results document of two runs, for the figures' checks to spoil."""
    out = tmp_path_factory.mktemp("small")
    args = ["experiment", "--filters", "ukf,tl-ukf", "--runs", "2", "--workers", "1"]
    assert runner.invoke(app, [*args, "--out", str(out)]).exit_code == 0
    return json.loads((out / "results.json").read_text())


@pytest.mark.parametrize(
    ("spoil", "says"),
    [
        (lambda d: d["filters"].update(zzz=d["filters"]["ukf"]), "unknown filter 'zzz'"),
        (lambda d: d["filters"]["ukf"].update(rmse_per_step=["a"]), "ukf.rmse_per_step: not a"),
        (lambda d: d["filters"]["ukf"].update(rmse_per_step=[[1.0]]), "ukf.rmse_per_step: not a"),
        (lambda d: d["filters"]["ukf"].update(rmse_per_step=[]), "ukf.rmse_per_step: not a"),
        (lambda d: d["filters"]["ukf"].update(rmse_overall=True), "ukf.rmse_overall: not a"),
        (lambda d: d.update(pcrlb="x"), "pcrlb: not a map of names to lists of numbers"),
        (lambda d: d.update(pcrlb={"x": 5}), "pcrlb: not a map"),
        (lambda d: d.update(pcrlb={"x": ["abc"]}), "pcrlb: not a map"),
        (lambda d: d["config"].update(K=-3), "config: K: Input should be greater than"),
        # run 0 is traced again from the truth file: one since moved was a traceback
        (
            lambda d: d["config"].update(truth="file", truth_file="/moved/track.csv"),
            "cannot redraw",
        ),
    ],
)
def test_plot_refuses_what_its_figures_cannot_draw(tmp_path, small_results, spoil, says):
    """Each was a traceback (or, for the empty and NaN series, a blank figure)."""
    import copy

    doc = copy.deepcopy(small_results)
    doc["filters"]["ukf"]["rmse_per_step"][0] = float("nan")  # one NaN is still a figure
    spoil(doc)
    path = tmp_path / "results.json"
    path.write_text(json.dumps(doc))
    r = runner.invoke(app, ["plot", str(path)])
    assert r.exit_code == 2 and says in " ".join(r.output.split()), r.output
    assert "errors.pydantic.dev" not in r.output and not list(tmp_path.glob("*.png"))


@pytest.mark.parametrize(
    ("command", "writes"),
    [
        (["experiment", "--filters", "ukf", "--runs", "2"], "results.json"),
        (["study", "clutter", "--runs", "2"], "clutter.json"),
    ],
)
def test_a_file_the_run_writes_that_is_a_folder_is_refused_before_it(tmp_path, command, writes):
    """The run went to its end, then lost its results to an IsADirectoryError's traceback."""
    (tmp_path / writes).mkdir()
    r = runner.invoke(app, [*command, "--out", str(tmp_path)])
    said = "".join(r.output.split())  # the console wraps the long path anywhere
    assert r.exit_code == 2 and f"{writes}isafolder,whereitwritesafile" in said, r.output


def test_plot_draws_a_series_with_a_gap(tmp_path, small_results):
    doc = json.loads(json.dumps(small_results))
    doc["filters"]["ukf"]["rmse_per_step"][0] = float("nan")
    (tmp_path / "results.json").write_text(json.dumps(doc))
    r = runner.invoke(app, ["plot", str(tmp_path / "results.json")])
    assert r.exit_code == 0 and (tmp_path / "rmse.png").stat().st_size > 10_000, r.output


def test_a_warning_reads_as_one_line(monkeypatch):
    """A checkpoint read from another machine warned with Python's file, line and source line,
    which read like a crash in a long job's log."""
    import warnings

    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)
    assert runner.invoke(app, ["access", "show"]).exit_code == 0
    said = warnings.formatwarning("a prefix made elsewhere", UserWarning, "/x/montecarlo.py", 563)
    assert said == "warning: a prefix made elsewhere\n"


def test_every_committed_results_file_can_be_plotted_again():
    """`tltrack plot` reads what the studies committed: ten files of an older sensor layout
    (noise parameters null) were refused before they were brought up to date."""
    from pathlib import Path

    from tltrack.app.experiment import _drawable
    from tltrack.config import Config
    from tltrack.engine.results import read

    files = sorted((Path(__file__).parents[1] / "papers").rglob("results.json"))
    assert len(files) >= 30
    for path in files:
        doc = read(path)
        Config.model_validate(doc["config"])
        _drawable(doc)


@pytest.mark.parametrize(
    ("flag", "says"),
    [("--steps", "K: Input should be greater than or equal to 1"), ("--particles", "particles:")],
)
def test_demo_refuses_zero_steps_or_particles_before_starting_anything(tmp_path, flag, says):
    """`steps or 100` took 0 for no value: the demo ran 100 steps of 6000 particles."""
    r = runner.invoke(app, ["demo", flag, "0", "--out", str(tmp_path)])
    assert r.exit_code == 2 and says in " ".join(r.output.split()), r.output
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["bench", "--particles", "20000000"], "particles: Input should be less than or equal"),
        (["bench", "--clutter", "--steps", "200000"], "K: Input should be less than or equal"),
        (["bench-live", "--rates=-5,nan,0"], "--rates: steps per second, each finite and > 0"),
        (["bench-live", "--particles", "20000000"], "particles: Input should be less than"),
    ],
)
def test_the_benches_refuse_what_the_config_would_before_any_work(args, says):
    """Tracebacks (a ConfigError) or, for the rates, a live stack started on them."""
    r = runner.invoke(app, args)
    assert r.exit_code == 2 and says in " ".join(r.output.split()), r.output


def test_demo_serve_refuses_a_host_or_port_the_dashboard_cannot_listen_on(tmp_path):
    """Found only after every router and service had started: a traceback, or a 30 s wait."""
    import socket

    r = runner.invoke(app, ["demo", "--serve", "--host", "bad host", "--out", str(tmp_path)])
    assert r.exit_code == 2 and "the dashboard cannot listen there" in " ".join(r.output.split())
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = str(held.getsockname()[1])
        r = runner.invoke(app, ["demo", "--serve", "--port", port, "--out", str(tmp_path)])
    assert r.exit_code == 2 and "Address already in use" in " ".join(r.output.split()), r.output
    assert not (tmp_path / "logs").exists()
