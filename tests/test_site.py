"""The results site in a real browser (headless Chromium through Selenium): no console errors, one plotted point per
run and axis, a family's legend entry hides its points, every gallery image loads. CI installs the browser
(.ci/run); elsewhere the test is skipped when Chromium or its driver is missing, and fails under CI=true."""

import math
import os
import shutil
import time

import pytest

from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report import compact, measured, site
from ddfbench.report.records import no_result

WebDriverWait = pytest.importorskip("selenium.webdriver.support.wait").WebDriverWait
TimeoutException = pytest.importorskip("selenium.common.exceptions").TimeoutException

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHROMIUM, DRIVER = shutil.which("chromium"), shutil.which("chromedriver")


@pytest.fixture(scope="module")
def browser():
    if not (CHROMIUM and DRIVER):
        message = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000",
                 "--allow-file-access-from-files"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    got = site.write_site(os.path.join(ROOT, "reports"), str(out))
    return out, got


def errors(driver):
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


# the run points each family's traces draw on each plot, read from the DOM: every drawn trace group carries its
# calcdata (d3's __data__), whose trace names the family; a hidden trace draws no group
POINTS = """
var out = {};
document.querySelectorAll('.js-plotly-plot').forEach(function (gd) {
  gd._fullData.forEach(function (t) {
    if (t.meta && t.meta.kind === 'runs') out[gd.id + '|' + t.meta.family] = 0;
  });
  gd.querySelectorAll('.scatterlayer .trace').forEach(function (g) {
    var t = g.__data__ && g.__data__[0] && g.__data__[0].trace;
    if (!t || !t.meta || t.meta.kind !== 'runs' || t.visible !== true) return;
    out[gd.id + '|' + t.meta.family] += g.querySelectorAll('path.point').length;
  });
});
return out;
"""


def test_pareto_page_plots_every_run_and_a_legend_click_hides_a_family(browser, built):
    out, got = built
    # the records, read here through the metric registry (not the site's own table): a point per ok run and axis
    # with a positive chamfer and a positive cost
    read = by_name()
    records = [r for folder, _, files in os.walk(os.path.join(ROOT, "reports")) if compact.FILE in files
               for r in compact.read_compact(os.path.join(folder, compact.FILE))
               if r["status"] == "ok" and not no_result(r)]  # a penalty is not a point
    expected = sum(1 for r in records for x, _ in site.AXES
                   if read["chamfer_l2"].read(r) > 0 and math.isfinite(read[x].read(r)) and read[x].read(r) > 0)
    assert got["runs"] == expected > 0
    browser.get(f"file://{out}/pareto.html")
    try:  # plotly draws after the page loads: on a busy machine, seconds later
        WebDriverWait(browser, 60).until(lambda b: sum(b.execute_script(POINTS).values()) >= expected)
    except TimeoutException:
        pass  # the assertion below says what was drawn
    counts = browser.execute_script(POINTS)
    assert sum(counts.values()) == expected, counts
    assert not errors(browser)
    first_plot = next(iter(counts)).split("|")[0]
    families = sorted(k.split("|")[1] for k in counts if k.startswith(first_plot + "|"))
    hidden = families[0]
    items = browser.find_elements("css selector", f"#{first_plot} .legend .traces")
    [item] = [i for i in items if i.text.strip() == hidden]
    item.find_element("css selector", ".legendtoggle").click()
    # plotly acts on a legend click after its double-click window (300 ms): wait for the redraw
    WebDriverWait(browser, 10).until(lambda b: b.execute_script(POINTS)[f"{first_plot}|{hidden}"] == 0)
    after = browser.execute_script(POINTS)
    assert after[f"{first_plot}|{hidden}"] == 0 < counts[f"{first_plot}|{hidden}"]
    assert all(after[k] == counts[k] for k in counts if k.startswith(first_plot) and not k.endswith(f"|{hidden}")), (
        counts, after)
    assert not errors(browser)


def test_every_gallery_image_loads_and_the_claims_filter_hides_rows(browser, built):
    out, got = built
    browser.get(f"file://{out}/gallery.html")
    script = "return Array.from(document.images).map(i => i.complete && i.naturalWidth > 0)"
    deadline = time.monotonic() + 60  # a loaded machine may decode the images after the page's load event
    while not all(loaded := browser.execute_script(script)) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert len(loaded) == got["galleries"] > 0 and all(loaded)
    browser.get(f"file://{out}/claims.html")
    rows = browser.execute_script("return document.querySelectorAll('#claims tbody tr').length")
    verdicts = browser.execute_script("return Array.from(document.querySelectorAll('#verdict option')).map(o => o.value)")
    browser.execute_script("filt(arguments[0])", verdicts[1])
    shown = browser.execute_script(
        "return Array.from(document.querySelectorAll('#claims tbody tr')).filter(r => r.style.display !== 'none').length")
    assert 0 < shown < rows and not errors(browser)


def test_each_report_page_names_its_commit_and_the_index_marks_those_without_records(built, tmp_path):
    out, got = built
    code = compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE))[0]["env"]["code_sha"][:7]
    page = (out / "report-default.html").read_text()
    assert f"runs of code {code}; it regenerates from its committed records" in page
    front = (out / "index.html").read_text()
    folders = site.table_folders(os.path.join(ROOT, "reports"))
    without = [rel for rel in folders if not os.path.isfile(os.path.join(ROOT, "reports", rel, compact.FILE))
               and not measured.holds_rows(os.path.join(ROOT, "reports", rel))]
    assert len(without) < len(folders) == got["pages"]
    remeasured = (out / "report-pareto-edge_error.html").read_text()  # a re-measurement with its measured rows
    assert "a re-measurement of the runs' artifacts; it regenerates from the rows it measured" in remeasured
    for rel in folders:  # each link goes to its own folder's page, marked when that folder has no records
        link = f"<a href='report-{rel.replace(os.sep, '-')}.html'>{rel}</a>"
        assert (f"{link} (not regenerable from records)" in front) == (rel in without) and link in front, rel
    # every committed folder regenerates today: in a copy whose one folder lost its records, that folder alone is marked
    copy = tmp_path / "reports"
    shutil.copytree(os.path.join(ROOT, "reports"), copy)
    os.remove(copy / "convergence_cuda" / compact.FILE)
    site.write_site(str(copy), str(tmp_path / "site"))
    front = (tmp_path / "site" / "index.html").read_text()
    assert "<a href='report-convergence_cuda.html'>convergence_cuda</a> (not regenerable from records)" in front
    assert front.count("(not regenerable from records)") == 1


def test_an_out_that_is_a_file_or_cannot_be_made_is_one_line(tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("not a folder")
    reports = os.path.join(ROOT, "reports")
    assert site.main(["--reports", reports, "--out", str(taken)]) == 2
    assert capsys.readouterr().err == f"ddfbench.report.site: --out {taken}: exists and is not a folder\n"
    assert taken.read_text() == "not a folder"
    assert site.main(["--reports", reports, "--out", str(taken / "site")]) == 2  # below a file: cannot be made
    assert capsys.readouterr().err.startswith(f"ddfbench.report.site: --out {taken / 'site'}: cannot be made (")


def test_a_report_whose_compact_file_holds_no_record_adds_no_run(tmp_path):
    """A compact file without a record (an older report of an empty folder) is skipped, not a pandas KeyError."""
    shutil.copytree(os.path.join(ROOT, "reports", "default"), tmp_path / "reports" / "default")
    (tmp_path / "reports" / "empty").mkdir()
    compact.write_compact([], str(tmp_path / "reports" / "empty" / compact.FILE))
    df = site.runs(str(tmp_path / "reports"))
    assert set(df["report"]) == {"default"} and len(df) > 0


def test_each_configuration_of_a_report_is_a_diamond_of_its_own_as_a_table_row(tmp_path):
    """A report with one model at several presets (reports/pareto: capacity c1-c4) plots a mean per preset, the
    runs of the table's row, not one mean pooled over the presets."""
    shutil.copytree(os.path.join(ROOT, "reports", "pareto"), tmp_path / "reports" / "pareto")
    df = site.runs(str(tmp_path / "reports"))
    fig = site.pareto_figure(df, "storage_bytes", "bytes")
    means = [(t.meta["family"], text) for t in fig.data if t.meta["kind"] == "means" for text in t.text]
    table = compact.records_of(os.path.join(ROOT, "reports", "pareto"))
    from ddfbench.report.tables import summarize

    rows = summarize(table)
    rows = rows[(rows["n"] - rows["n_empty"] - rows["n_off"]) > 0]  # a row with a plotted run
    assert len(means) == len(rows) > len({m for m, _ in means})
    tuned = [text for family, text in means if "ddf_tuned (capacity=c2)" in text]
    assert len(tuned) == 1 and "geometric mean of 3 seed(s)" in tuned[0], means


def test_a_mean_says_how_many_of_its_runs_it_leaves_out(tmp_path):
    """gan_no_adv's gan_sdf on the bunny: 3 ok runs, 1 off the shape. The table's row counts it (its CD-L2 mean is
    the 3 runs'); the plotted mean is of the other 2 and says so."""
    shutil.copytree(os.path.join(ROOT, "reports", "gan_no_adv"), tmp_path / "reports" / "gan_no_adv")
    fig = site.pareto_figure(site.runs(str(tmp_path / "reports")), "storage_bytes", "bytes")
    texts = {t.meta["family"]: list(t.text) for t in fig.data if t.meta["kind"] == "means"}
    [gan] = [text for family, found in texts.items() for text in found if "/ gan_sdf," in text]
    assert "geometric mean of 2 seed(s)" in gan and "1 of its 3 runs left out (no mesh or off the shape)" in gan
    assert all("left out" not in text for found in texts.values() for text in found if text != gan)


def test_a_not_converged_row_shows_no_penalty_on_its_report_page(tmp_path):
    """reports/pareto's ddf_paper rows: every run empty, so table.md shows their geometry cells blank and the row
    unranked; the page shows them blank too (table.csv keeps the penalty, CD-L2 8.64), with a note."""
    shutil.copytree(os.path.join(ROOT, "reports", "pareto"), tmp_path / "reports" / "pareto",
                    ignore=shutil.ignore_patterns("edge_error", "zero_level"))
    (tmp_path / "site" / "img").mkdir(parents=True)
    site.write_reports(str(tmp_path / "reports"), str(tmp_path / "site"))
    page = (tmp_path / "site" / "report-pareto.html").read_text()
    rows = [r for r in page.split("<tr>") if "<td>ddf_paper</td>" in r]
    assert len(rows) == 4 and all("<td>8.64</td>" not in r and "<td>True</td>" in r for r in rows)
    assert "<td>8.64</td>" not in page and "not_converged (every run empty or off the shape)" in page
    assert "<td>2.919</td>" in page  # a row with one empty run of three keeps its mean, as table.md does
