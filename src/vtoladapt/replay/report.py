"""``report.md`` and ``report.html`` of a replay (one context, two Jinja2 templates)."""
from __future__ import annotations

from pathlib import Path

from ..outputs import write_text
from .estimator import ReplayResult

_MD = """# Replay of a flight log

- Log: `{{ log.source }}` ({{ log.format }}), {{ "%.1f"|format(log.duration_s) }} s resampled at {{ "%.4g"|format(log.rate_hz) }} Hz ({{ log.samples }} samples).
- Vehicle model: `{{ vehicle }}`. Samples used (finite inputs{% if not settings.use_landed %}, airborne{% endif %}): {{ log.samples_used }} ({{ "%.1f"|format(log.used_s) }} s); on the ground per the land detector: {{ log.samples_landed }}.
- The force model and the composite adaptation run open loop (no reference: the tracking term is zero) on the log's data; errors are the filtered prediction error |W θ − a_m| in g.

## Where each quantity comes from

| quantity | source |
|---|---|
{% for k, v in log.sources.items() %}| {{ k }} | {{ v }} |
{% endfor %}
## What the log lacks and how the replay fills it in

{% if lacks %}| quantity | the log lacks | filled in by |
|---|---|---|
{% for n in lacks %}| {{ n.quantity }} | {{ n.lacks }} | {{ n.filled }} |
{% endfor %}{% else %}Nothing: every quantity the model needs is in the log.
{% endif %}
## Prediction error (g = 9.80665 m/s²)

| θ | RMS (g) | p95 (g) | max (g) | RMS x, y, z (g) |
|---|---|---|---|---|
{% for name, s in errors %}| {{ name }} | {{ fmt(s.rms_g) }} | {{ fmt(s.p95_g) }} | {{ fmt(s.max_g) }} | {% if s.rms_axis_g %}{{ s.rms_axis_g|map("round", 3)|join(", ") }}{% else %}–{% endif %} |
{% endfor %}
By airspeed |v_i| (m/s):

| airspeed (m/s) | samples | adapted RMS (g) | adapted p95 (g) | θ_0 RMS (g) |
|---|---|---|---|---|
{% for b in bins %}| [{{ b.airspeed_mps[0]|int }}, {{ b.airspeed_mps[1]|int if b.airspeed_mps[1] is not none else "∞" }}) | {{ b.samples }} | {{ fmt(b.adapted_rms_g) }} | {{ fmt(b.adapted_p95_g) }} | {{ fmt(b.prior_rms_g) }} |
{% endfor %}
## θ̂ (Table I units: throttle in percent, forces per unit mass)

| parameter | θ_0 | θ̂ final | at a bound |
|---|---|---|---|
{% for name in theta.names %}| {{ name }} | {{ "%.5g"|format(theta.theta_0[name]) }} | {{ "%.5g"|format(theta.final[name]) }} | {{ "yes" if name in theta.at_bound else "" }} |
{% endfor %}
{% if theta.at_bound %}θ̂ ends on a bound of the controller's box for {{ theta.at_bound|join(", ") }}: the vehicle's model cannot explain this log inside the prior's range (a different aircraft, or data the model lacks).
{% endif %}
![replay](fig_replay.png)
"""

_HTML = """<!doctype html>
<html><head><meta charset="utf-8"><title>Replay of {{ log.source }}</title>
<style>body{font-family:sans-serif;max-width:60em;margin:2em auto}table{border-collapse:collapse}
td,th{border:1px solid #bbb;padding:2px 8px}img{max-width:100%}</style></head><body>
<h1>Replay of a flight log</h1>
<p>Log <code>{{ log.source }}</code> ({{ log.format }}), {{ "%.1f"|format(log.duration_s) }} s at {{ "%.4g"|format(log.rate_hz) }} Hz
({{ log.samples }} samples); vehicle model <code>{{ vehicle }}</code>; {{ log.samples_used }} samples used
({{ "%.1f"|format(log.used_s) }} s), {{ log.samples_landed }} on the ground. Open loop: the tracking term is zero;
errors are the filtered prediction error |W&theta; &minus; a_m| in g.</p>
<h2>Where each quantity comes from</h2>
<table><tr><th>quantity</th><th>source</th></tr>
{% for k, v in log.sources.items() %}<tr><td>{{ k }}</td><td>{{ v }}</td></tr>{% endfor %}</table>
<h2>What the log lacks and how the replay fills it in</h2>
{% if lacks %}<table><tr><th>quantity</th><th>the log lacks</th><th>filled in by</th></tr>
{% for n in lacks %}<tr><td>{{ n.quantity }}</td><td>{{ n.lacks }}</td><td>{{ n.filled }}</td></tr>{% endfor %}</table>
{% else %}<p>Nothing.</p>{% endif %}
<h2>Prediction error (g = 9.80665 m/s&sup2;)</h2>
<table><tr><th>&theta;</th><th>RMS (g)</th><th>p95 (g)</th><th>max (g)</th></tr>
{% for name, s in errors %}<tr><td>{{ name }}</td><td>{{ fmt(s.rms_g) }}</td><td>{{ fmt(s.p95_g) }}</td><td>{{ fmt(s.max_g) }}</td></tr>{% endfor %}</table>
<table><tr><th>airspeed (m/s)</th><th>samples</th><th>adapted RMS (g)</th><th>adapted p95 (g)</th><th>&theta;_0 RMS (g)</th></tr>
{% for b in bins %}<tr><td>[{{ b.airspeed_mps[0]|int }}, {{ b.airspeed_mps[1]|int if b.airspeed_mps[1] is not none else "&infin;"|safe }})</td><td>{{ b.samples }}</td><td>{{ fmt(b.adapted_rms_g) }}</td><td>{{ fmt(b.adapted_p95_g) }}</td><td>{{ fmt(b.prior_rms_g) }}</td></tr>{% endfor %}</table>
<h2>&theta;&#770; (Table I units)</h2>
<table><tr><th>parameter</th><th>&theta;_0</th><th>final</th><th>at a bound</th></tr>
{% for name in theta.names %}<tr><td>{{ name }}</td><td>{{ "%.5g"|format(theta.theta_0[name]) }}</td><td>{{ "%.5g"|format(theta.final[name]) }}</td><td>{{ "yes" if name in theta.at_bound else "" }}</td></tr>{% endfor %}</table>
<p><img src="fig_replay.png" alt="replay figure"></p>
</body></html>
"""


def _fmt(v) -> str:
    return "–" if v is None else f"{v:.3f}"


def write_report(result: ReplayResult, metrics: dict, out: Path) -> tuple[Path, Path]:
    """Render ``report.md`` and ``report.html`` into ``out`` from the metrics document."""
    import jinja2

    ctx = {"log": metrics["log"], "lacks": metrics["lacks"], "vehicle": metrics["vehicle"],
           "settings": result.settings, "bins": metrics["by_airspeed_bin"], "theta": metrics["theta"],
           "errors": [("θ̂ (adapting)", metrics["prediction_error"]["adapted"]),
                      ("θ_0 (vehicle file)", metrics["prediction_error"]["prior"])],
           "fmt": _fmt}
    md = jinja2.Environment(autoescape=False, keep_trailing_newline=True).from_string(_MD).render(ctx)
    html = jinja2.Environment(autoescape=True).from_string(_HTML).render(ctx)
    out = Path(out)
    write_text(out / "report.md", md)
    write_text(out / "report.html", html)
    return out / "report.md", out / "report.html"


__all__ = ["write_report"]
