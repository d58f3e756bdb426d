"""The paper's experiments: parameter convergence and the five-controller comparison.

``vtoladapt reproduce --out DIR`` runs both shipped scenarios (``paper_convergence``,
``paper_comparison``) and writes the figures, ``metrics.json`` and a report that checks the
paper's claims in simulation. ``vtoladapt run SCENARIO --out DIR`` does the same for one
scenario file, so a user can vary one thing and compare.

The package is split at its seams: :mod:`.running` runs the experiments and writes their
outputs, :mod:`.metrics` reduces many runs to the experiments' numbers, :mod:`.claims` states the
paper's claims and checks them, :mod:`.figures` draws, and :mod:`.report` writes report.md and
report.html (Jinja2 templates over the same structured data) and every output file.

metrics.json schema
-------------------
``comparison.controllers.<id>``: ``vel_err_rms_mps``, ``vel_err_max_mps``,
``vel_err_rms_high_wind_mps`` (fan >= 60 %), ``overshoot_after_fan_off_mps`` (peak velocity error
in the 5 s after the fan stops), and for the composite controllers ``pred_err_rms_g`` and
``pred_err_p95_g`` (after the first 2 s), plus further diagnostics (labels and units of every key:
:data:`vtoladapt.sim.run_metrics.METRIC_INFO`).
``convergence.param_std_ratio.<param>``: spread (std) of theta-hat across the runs at the end
divided by at the start. ``claims.<name>``: ``{"holds", "value", "threshold", "statement",
"paper_claim", "source"}`` (``paper_claim`` false: a diagnostic of ours, labelled so).
``run`` (single runs): the run's metrics. Composite runs also have ``pred_err_p95_g_by_airspeed``
(bins [0,2), [2,5), [5,8), [8,11), [11,inf) m/s, null where empty); the 0.05 g claim is judged
in every bin.

Over seeded variants (:mod:`.distribution`): ``distribution.<experiment>.claims.<name>`` =
``{fraction, ci95, n, successes, value: {median, iqr, n}, threshold, statement, paper_claim}``,
``distribution.comparison.controllers.<id>.<metric>`` = ``{median, iqr, n}``,
``distribution.convergence.param_std_ratio.<param>`` = ``{median, iqr, n}``; from ``reproduce``
also ``ablation.<config>.claims.<name>`` (config ``all_on`` or ``<effect>_off``) and
``wind_table.conditions.<condition>.<id>.{pos_err_mean_m, vel_err_rms_mps}`` = ``{median, iqr, n}``.
"""
from __future__ import annotations

from .claims import CLAIM_UNITS, check_claims
from .figures import (CONTROLLER_COLORS, CONTROLLER_LABELS, PLOT_FILTER_HZ, PRED_ERR_COLUMNS,
                      controller_style, figure_campaign, figure_parameter_convergence,
                      figure_single_run, figure_tracking_axes, figure_tracking_comparison,
                      measured_airspeed_mps, new_figure, plot_campaign, plot_parameter_convergence,
                      plot_single_run, plot_tracking_axes, plot_tracking_comparison)
from .metrics import (THETA_SCALED_UNITS, comparison_metrics, convergence_metrics, fan_speed_series,
                      fan_throttle_series)
from .distribution import (ABLATION_EFFECTS, WIND_CONDITIONS, ablation, comparison_distribution,
                           convergence_distribution, variant_seeds, wind_table)
from .report import Report, build_report, render_html, render_markdown, write_report
from .running import reproduce, run_comparison, run_convergence, run_experiment

__all__ = [
    "ABLATION_EFFECTS", "WIND_CONDITIONS", "ablation", "comparison_distribution",
    "convergence_distribution", "variant_seeds", "wind_table",
    "CLAIM_UNITS", "CONTROLLER_COLORS", "CONTROLLER_LABELS",
    "PLOT_FILTER_HZ", "PRED_ERR_COLUMNS", "Report", "THETA_SCALED_UNITS", "build_report",
    "check_claims", "comparison_metrics", "controller_style", "convergence_metrics",
    "fan_speed_series", "fan_throttle_series", "figure_campaign", "figure_parameter_convergence",
    "figure_single_run", "figure_tracking_axes", "figure_tracking_comparison",
    "measured_airspeed_mps", "new_figure", "plot_campaign", "plot_parameter_convergence",
    "plot_single_run", "plot_tracking_axes", "plot_tracking_comparison", "render_html",
    "render_markdown", "reproduce", "run_comparison", "run_convergence", "run_experiment",
    "write_report",
]
