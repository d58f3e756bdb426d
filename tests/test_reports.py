"""Figures and reports a control engineer can read: units, gaps, readable text, one R-hat.

Every check reads what was drawn or written (the figure's artists, the HTML's tables, the PNG's
text chunk, the CLI's output) and compares it with an independent source: the log's validity flag,
the declared units of the configuration fields, the metrics file, the TOML parser.
"""
import dataclasses
import json
import re
import tomllib
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from vtoladapt.cli import format_vehicle, main
from vtoladapt.sim.scenario import load_scenario
from vtoladapt.sim.run_metrics import METRIC_INFO, metric_label
from vtoladapt.vehicle import load_vehicle, vehicle_from_mapping

CONTROLLER_IDS = load_scenario("paper_comparison").experiment.controllers
"""The laws make reproduce flies (the comparison scenario's; a law registered after it, composite_indi, is not)."""

SNAKE_KEY = re.compile(r"^[a-z0-9]+(_[a-z0-9]+)+$")


# --- report.html / report.md -------------------------------------------------------------------------
class _Tables(HTMLParser):
    """Every table's header cells and body cells (text) of an HTML page."""

    def __init__(self):
        super().__init__()
        self.headers: list[str] = []
        self.cells: list[str] = []
        self._in: str | None = None
        self._text = ""

    def handle_starttag(self, tag, attrs):
        if tag in ("th", "td"):
            self._in, self._text = tag, ""

    def handle_endtag(self, tag):
        if tag == self._in:
            (self.headers if tag == "th" else self.cells).append(self._text.strip())
            self._in = None

    def handle_data(self, data):
        if self._in:
            self._text += data


def _md_table_cells(md: str) -> tuple[list[str], list[str]]:
    headers, cells = [], []
    lines = md.splitlines()
    for i, line in enumerate(lines):
        if not line.startswith("|") or set(line) <= set("|-"):
            continue
        row = [c.strip().strip("*") for c in line.strip().strip("|").split(" | ")]
        is_header = i + 1 < len(lines) and set(lines[i + 1]) <= set("|-") and lines[i + 1]
        (headers if is_header else cells).extend(row)
    return headers, cells


def test_report_html_shows_no_path_of_the_machine(reproduced):
    html = (reproduced / "report.html").read_text()
    md = (reproduced / "report.md").read_text()
    package_dir = Path(__import__("vtoladapt").__file__).resolve().parent
    for text in (html, md):
        assert str(reproduced.parent) not in text
        assert str(package_dir) not in text
    # the shipped scenarios are named by their place in the package instead
    assert "vtoladapt/scenarios/paper_comparison.toml" in md


def test_report_tables_have_words_with_units_and_match_the_markdown(reproduced):
    parser = _Tables()
    parser.feed((reproduced / "report.html").read_text())
    assert parser.headers and parser.cells
    for text in parser.headers + parser.cells:
        assert not SNAKE_KEY.match(text), f"raw key {text!r} in a table of report.html"
    for key in ("vel_err_rms_mps", "overshoot_after_fan_off_mps", "mixer_saturated_fraction"):
        label, unit = METRIC_INFO[key]
        assert label in parser.cells and unit in parser.cells
    md_headers, md_cells = _md_table_cells((reproduced / "report.md").read_text())
    # both renderings come from the same data: same headers and cells, in the same order
    assert md_headers == parser.headers
    assert md_cells == parser.cells
    metrics = json.loads((reproduced / "metrics.json").read_text())
    pd_rms = metrics["comparison"]["controllers"]["pd"]["vel_err_rms_mps"]
    assert f"{pd_rms:.4g}" in parser.cells


def test_report_figures_are_inline_and_captioned(reproduced):
    html = (reproduced / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3
    assert html.count("<figcaption>") == 3


# --- figures --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def comparison_runs(reproduced):
    from vtoladapt.experiments.running import _scaled
    from vtoladapt.sim.results import SimulationResult
    from vtoladapt.sim.scenario import load_scenario

    scenario = _scaled(load_scenario("paper_comparison"), 0.12)
    runs = {cid: SimulationResult.from_parquet(reproduced / "comparison" / "runs"
                                               / f"paper_comparison_{cid}.parquet") for cid in CONTROLLER_IDS}
    return scenario, runs


def test_invalid_probe_readings_are_gaps_not_zero_airspeed(comparison_runs):
    from vtoladapt.experiments import plot_tracking_comparison

    scenario, runs = comparison_runs
    res = runs["composite"]
    invalid = res["meas_v_i_valid"] == 0
    assert invalid.any() and (~invalid).any()   # still air at the start: the probe reads below its minimum
    fig = plot_tracking_comparison(scenario, runs)
    y = np.asarray(fig.axes[0].lines[0].get_ydata(), dtype=float)
    np.testing.assert_array_equal(np.isnan(y), invalid)
    v = res.columns_like(("meas_v_i_x_mps", "meas_v_i_y_mps", "meas_v_i_z_mps"))
    np.testing.assert_allclose(y[~invalid], np.sqrt((v[~invalid] ** 2).sum(axis=1)))


def test_overlapping_controllers_stay_distinguishable(comparison_runs):
    from vtoladapt.experiments import controller_style, plot_tracking_axes

    styles = [controller_style(c) for c in CONTROLLER_IDS]
    assert len({str(s["ls"]) for s in styles}) == len(styles)
    scenario, runs = comparison_runs
    fig = plot_tracking_axes(scenario, runs)
    for ax in fig.axes:
        lines = [ln for ln in ax.lines if ln.get_label() in {s["label"] for s in styles}]
        dashes = [str(ln._unscaled_dash_pattern) for ln in lines]   # the pattern as given
        widths = [ln.get_linewidth() for ln in lines]
        # a later curve on top of an identical earlier one leaves it visible: narrower or dashed
        assert len(set(zip(dashes, widths))) == len(lines)


def _assert_axes_have_units(fig):
    for ax in fig.axes:
        if not ax.get_visible() or not (ax.lines or ax.collections or ax.patches):
            continue
        for label in (ax.get_ylabel(), ax.get_xlabel()):
            if label:
                assert re.search(r"\[[^\]]+\]", label), f"no unit in axis label {label!r}"
                assert "scaled" not in label, label
        assert ax.get_ylabel(), "an axis with data and no y label"


def test_every_axis_of_the_experiment_figures_has_a_unit(reproduced, comparison_runs):
    from vtoladapt.experiments import (plot_parameter_convergence, plot_tracking_axes,
                                       plot_tracking_comparison)
    from vtoladapt.experiments.running import _scaled
    from vtoladapt.sim.results import SimulationResult
    from vtoladapt.sim.scenario import load_scenario

    scenario, runs = comparison_runs
    _assert_axes_have_units(plot_tracking_comparison(scenario, runs))
    _assert_axes_have_units(plot_tracking_axes(scenario, runs))
    conv = _scaled(load_scenario("paper_convergence"), 0.12)
    conv_runs = [SimulationResult.from_parquet(p)
                 for p in sorted((reproduced / "convergence" / "runs").glob("*.parquet"))]
    _assert_axes_have_units(plot_parameter_convergence(conv, conv_runs))


def test_campaign_figure_counts_whole_runs_and_plots_the_varied_keys():
    from vtoladapt.campaign.runner import _setting_unit
    from vtoladapt.experiments import plot_campaign

    rng = np.random.default_rng(4)
    rows = [{"run": i, "seed": i, "plant.stall_angle_deg": float(a), "vel_err_rms_mps": float(v),
             "pos_err_max_m": float(p)}
            for i, (a, v, p) in enumerate(zip(rng.uniform(12, 18, 7), rng.uniform(0.05, 0.1, 7),
                                              rng.uniform(0.01, 0.05, 7)))]
    assert _setting_unit("plant.stall_angle_deg") == "deg"
    assert _setting_unit("plant.no_such_key") is None
    fig = plot_campaign(rows, ["plant.stall_angle_deg"], {"plant.stall_angle_deg": "deg"})
    hist_axes, scatter_axes = fig.axes[:2], fig.axes[2:]
    for ax in hist_axes:
        ticks = ax.get_yticks()
        np.testing.assert_array_equal(ticks, np.round(ticks))
        assert ax.get_ylabel() == "runs [count]"
        assert sum(p.get_height() for p in ax.patches) == len(rows)
    assert len(scatter_axes) == 2
    for ax in scatter_axes:
        assert ax.get_xlabel() == "plant.stall_angle_deg [deg]"
        np.testing.assert_array_equal(ax.lines[0].get_xdata(), [r["plant.stall_angle_deg"] for r in rows])
    assert scatter_axes[0].get_ylabel() == metric_label("vel_err_rms_mps")


# --- a single run's report ------------------------------------------------------------------------------
def test_single_run_report_names_its_scenario_and_has_its_metrics(tmp_path):
    path = tmp_path / "gusty_hold.toml"
    path.write_text('name = "gusty_hold"\nvehicle = "caltech_vtol"\nduration_s = 3.0\n'
                    '[wind.fan_array]\nschedule = [[0, 30], [3, 30]]\n')
    out = tmp_path / "o"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    md = (out / "report.md").read_text()
    title = md.splitlines()[0]
    assert "gusty_hold" in title and "Shi et al" not in title
    metrics = json.loads((out / "metrics.json").read_text())["run"]
    assert set(metrics) <= set(METRIC_INFO)     # every metric has words and a unit
    for key, value in metrics.items():
        label, unit = METRIC_INFO[key]
        if isinstance(value, dict):   # per airspeed bin: "bin value" pairs, "n/a" for an empty bin
            shown_text = "; ".join(f"{b} {'n/a' if v is None else format(v, '.4g')}" for b, v in value.items())
            assert f"| {label} | {shown_text} | {unit} |" in md, key
            continue
        if value is None:                       # NaN is written as JSON null, e.g. no high wind in 3 s
            shown_text = "n/a"
        else:
            shown = 100 * value if key.endswith("_fraction") else value
            shown_text = f"{shown:.4g}" if np.isfinite(shown) else "n/a"
        assert f"| {label} | {shown_text} | {unit} |" in md, key
    assert "`gusty_hold.toml`" in md or "`../gusty_hold.toml`" in md
    assert str(tmp_path) not in (out / "report.html").read_text()


# --- vehicle show -----------------------------------------------------------------------------------------
def test_vehicle_show_prints_units_and_valid_toml():
    veh = load_vehicle("caltech_vtol")
    text = format_vehicle("caltech_vtol")
    back = vehicle_from_mapping(tomllib.loads(text), "vehicle show output")
    assert dataclasses.replace(back, source_path="") == dataclasses.replace(veh, source_path="")
    lines = {ln.split(" = ")[0].strip(): ln for ln in text.splitlines() if " = " in ln}
    for section in ("mass", "force_model", "envelope"):
        for f in dataclasses.fields(getattr(veh, section)):
            assert f"# [{f.metadata['unit']}]" in lines[f.name], f.name
    assert "# [kg] take-off mass" in lines["mass_kg"]
    assert lines["basis"].startswith('basis = "paper"  # [-] the force-model basis')


def test_vehicle_show_keeps_the_basis_and_its_settings(tmp_path):
    path = tmp_path / "v.toml"
    text = open(load_vehicle("caltech_vtol").source_path).read()
    path.write_text(text.replace('basis = "paper"', 'basis = "my_basis"') + '\n[basis_settings.my_basis]\nCY_mean = -0.2\nrows = [1, 2]\n')
    veh = load_vehicle(path)
    back = vehicle_from_mapping(tomllib.loads(format_vehicle(path)), "vehicle show output")
    assert back.basis == "my_basis" and back.basis_table("my_basis") == {"CY_mean": -0.2, "rows": [1, 2]}
    assert dataclasses.replace(back, source_path="") == dataclasses.replace(veh, source_path="")


# --- fitting: one R-hat, readable corner plot ------------------------------------------------------------
def test_one_rhat_in_cli_table1_and_trace(cli_fit):
    """The fit's printed, tabled and plotted largest R-hat are one (the run: conftest's ``cli_fit``)."""
    assert cli_fit.fit_rc == 0
    out = cli_fit.out
    printed = re.search(r"largest split R-hat (\d+\.\d{4}) \((\w+)\)", cli_fit.stdout)
    table = re.search(r"largest split R-hat: (\d+\.\d{4}) \((\w+)\)", (out / "table1.md").read_text())
    with Image.open(out / "trace.png") as img:
        trace = re.search(r"largest split R-hat (\d+\.\d{4}) \((\w+)\)", img.text["Title"])
    assert printed and table and trace
    assert printed.groups() == table.groups() == trace.groups()
    # and it is the largest of the per-quantity R-hats stored in posterior.json
    rhat = json.loads((out / "posterior.json").read_text())["diagnostics"]["rhat_split"]
    name = max(rhat, key=rhat.get)
    assert printed.groups() == (f"{rhat[name]:.4f}", name)


def test_corner_plot_text_is_readable():
    from types import SimpleNamespace

    from vtoladapt.fitting.figures import CORNER_TICK_PT, corner_figure
    from vtoladapt.fitting.posterior import POSTERIOR_NAMES

    # the figure reads only the draws and their names: draws at Table I's scales (1e-5 to 3)
    veh = load_vehicle("caltech_vtol")
    names = tuple(POSTERIOR_NAMES) + ("sigma_abs_N", "sigma_rel")
    means = np.array([getattr(veh.force_model, n) for n in POSTERIOR_NAMES] + [0.02, 0.01])
    draws = means * (1 + 0.05 * np.random.default_rng(0).standard_normal((200, 8, len(names))))
    fig = corner_figure(SimpleNamespace(names=names, draws=draws))
    fig.canvas.draw()   # tick labels and offset texts exist after a draw
    sizes = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for axis in (ax.xaxis, ax.yaxis):
            sizes += [t.get_fontsize() for t in axis.get_ticklabels() if t.get_text()]
            if axis.get_offset_text().get_text():
                sizes.append(axis.get_offset_text().get_fontsize())
    assert len(sizes) > 20 and min(sizes) >= 7.0 and CORNER_TICK_PT >= 7.0
    # at the PNG's own resolution a tick label is at least 10 pixels tall
    assert min(sizes) * fig.dpi / 72 >= 10


def test_a_comparison_flown_by_one_law_has_no_ranking_tables():
    """`vtoladapt run paper_comparison --controller composite` ranked nothing and stopped with StopIteration."""
    from vtoladapt.experiments.report import comparison_pair_tables

    one_law = {"distribution": {"comparison": {"paired": {"ranking": {}, "pairs": {}}, "variants": 3}}}
    assert comparison_pair_tables(one_law) == []
