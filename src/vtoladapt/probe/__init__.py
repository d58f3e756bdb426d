"""The 3-D airflow probe: tip model, SDP33 sensors, incident-velocity estimation, calibration.

The paper (Shi et al., ICRA 2020, Sec. "Airflow Sensing") uses a conic tip with a centre port and
four peripheral ports and three Sensirion SDP33 differential pressure sensors giving ``q_inf``,
``q_alpha``, ``q_beta``, from which eq:aoa estimates the incident velocity ``v_i``.

* Forward model: :class:`ProbeTip` (potential-flow port pressures), :class:`SDP33Sensor` (lag,
  offset, noise, quantisation); kernels :func:`probe_differential_pressures`,
  :func:`sdp33_sensor_step`.
* Estimation: :func:`incident_velocity_from_pressures` (compiled, NaN-safe, validity flag) for
  both models, :class:`SingleKCalibration` (eq:aoa) and :class:`SplineCalibration` (ours).
* Calibration: :func:`fit_single_k`, :func:`fit_spline_calibration`, :func:`calibrate`,
  :func:`calibrate_tip` (both models for a simulated tip, for the simulator),
  :func:`evaluate_calibration`, :func:`save_calibration`, :func:`load_calibration`.
* Data: :func:`read_nasa_pcf` (NASA five-hole probe calibrations, github.com/nasa/
  multihole-probe-calibration, NOSA 1.3, Mirhashemi et al. 2024), :func:`read_probe_csv`
  (our CSV format), :func:`simulate_calibration_sweep`.
"""
from vtoladapt.probe.calibration import (
    CalibrationMetrics,
    SingleKCalibration,
    SplineCalibration,
    calibrate,
    calibrate_tip,
    evaluate_calibration,
    fit_single_k,
    fit_spline_calibration,
    load_calibration,
    save_calibration,
)
from vtoladapt.probe.data import (
    ProbeCalibrationData,
    read_probe_csv,
    read_probe_data,
    simulate_calibration_sweep,
    write_probe_csv,
)
from vtoladapt.probe.errors import ProbeError
from vtoladapt.probe.estimation import (
    aoa_incident_velocity,
    estimate_incident_velocity,
    incident_velocity_from_pressures,
)
from vtoladapt.probe.figures import plot_linearity
from vtoladapt.probe.flow import (
    airspeed_angles_from_v_i,
    cone_roll_to_alpha_beta,
    flow_angle_error_rad,
    v_i_from_airspeed_angles,
)
from vtoladapt.probe.nasa import read_nasa_pcf
from vtoladapt.probe.sensor import SDP33Sensor, sdp33_sensor_step
from vtoladapt.probe.tip import ProbeTip, probe_differential_pressures, probe_port_pressures

__all__ = [
    "CalibrationMetrics", "ProbeCalibrationData", "ProbeError",
    "ProbeTip", "SDP33Sensor", "SingleKCalibration", "SplineCalibration",
    "airspeed_angles_from_v_i", "aoa_incident_velocity", "calibrate", "calibrate_tip",
    "cone_roll_to_alpha_beta",
    "estimate_incident_velocity", "evaluate_calibration", "fit_single_k",
    "fit_spline_calibration", "flow_angle_error_rad", "incident_velocity_from_pressures",
    "load_calibration", "plot_linearity", "probe_differential_pressures", "probe_port_pressures",
    "read_nasa_pcf", "read_probe_csv", "read_probe_data", "save_calibration",
    "sdp33_sensor_step", "simulate_calibration_sweep", "v_i_from_airspeed_angles",
    "write_probe_csv",
]
