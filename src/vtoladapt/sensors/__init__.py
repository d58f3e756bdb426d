"""Sensors of the closed-loop simulator: IMU, motion capture, attitude estimate and airflow probe.

The controller never sees the plant state; it sees the measurement array of :mod:`vtoladapt.layout`
(:data:`~vtoladapt.layout.MEASUREMENT`, ``MEAS_*``) that the sensor channels write every control
tick from the truth. Each channel is a module of this package, configured in a sub-table of a
scenario's ``[sensors]`` table, and each switches to a perfect sensor with ``ideal = true``. The
defaults are realistic for the paper's set-up:

* :mod:`~vtoladapt.sensors.imu` (``[sensors.imu]``): gyroscope and accelerometer at the control
  rate, Pixhawk-class noise densities, constant biases drawn per run, saturation;
* :mod:`~vtoladapt.sensors.mocap` (``[sensors.mocap]``): motion-capture position and velocity,
  0.5 mm / 0.02 m/s, delayed 12 ms (3 ticks at 250 Hz) through a ring buffer;
* :mod:`~vtoladapt.sensors.attitude` (``[sensors.attitude]``): the true ``q_WB`` rotated by a small
  random body-axis rotation of 0.2 deg (1 sigma per axis) each tick;
* :mod:`~vtoladapt.sensors.airflow_probe` (``[sensors.probe]``): the incident velocity through a
  3 ms lag with 0.1 m/s noise (``model = "ideal_noise"``), or the paper's sensor end to end
  (``model = "pressure"``: tip pressures, three SDP33 sensors, the flight computer's calibration).

:mod:`~vtoladapt.sensors.suite` composes them (:class:`SensorsConfig`, :func:`sensors_at`) and
:mod:`~vtoladapt.sensors.registry` lists them: the ``"sensor"`` kind of :mod:`vtoladapt.components`.

Randomness
----------
Only from the run's ``numpy.random.Generator``. Each channel's ``initial_state`` draws what the run
fixes at its start (the IMU's six biases; the pressure probe's three SDP33 offsets), and every tick
the loop draws each channel's ``NORMALS_PER_STEP`` standard normals then ``UNIFORMS_PER_STEP``
uniforms, channel by channel in the suite's order (IMU 12, motion capture 6, attitude 3, probe 3
normals and 1 uniform). Every channel draws whether it is ideal or not, so making one sensor ideal
never changes the noise of the others: a run differs from another only where its settings differ.

The sensor channel interface
----------------------------
A channel is a module with the interface of :mod:`vtoladapt.parts` (``Settings``, ``PARAMS`` and
``STATE`` layouts, draws per step, ``pack(settings, context)``, ``initial_state(params, rng)``) and
``WRITES``, the measurement fields it writes; its ``step`` is decorated with
:func:`~vtoladapt.sensors.registry.sensor_step` (a C kernel of ``SENSOR_STEP_SIGNATURE``)::

    step(params, state, t, dt, x_true, truth, draws, meas)

It writes its fields of ``meas`` from the truth it is given (the plant state ``x_true`` and the
tick's :data:`~vtoladapt.layout.TRUTH`: wind, specific force, incident velocity) and advances
``state`` in place. Register it by a call, ``vtoladapt.components.register("sensor",
PartInfo("my_id", "my_module"))``, or by an entry point in the group ``vtoladapt.sensor``; a
scenario flies it by naming it in ``[sensors] channels`` (in place of the channel that wrote its
fields before) with its settings in ``[sensors.my_id]``. :func:`run_sensor_model` drives any suite
over a recorded truth; ``tests/example_sensor.py`` (a GNSS-class receiver in place of the motion
capture) is a complete channel, held to the same tests as the package's and flown through
``simulate`` and the Gymnasium environment by ``tests/test_sensor_interface.py``.
"""
from .airflow_probe import PROBE_MODELS, ProbeConfig
from .attitude import AttitudeConfig
from .imu import DRAWS_INITIAL, ImuConfig, specific_force_B
from .mocap import MOCAP_RING_SIZE, VELOCITY_SOURCES, MocapConfig, latency_ticks
from .registry import SENSOR_CHANNELS, SENSOR_STEP_SIGNATURE
from .suite import SensorContext, SensorsConfig, run_sensor_model, sensors_at

SENSOR_DRAWS_INITIAL = DRAWS_INITIAL
"""Standard normals the package's suite draws when a run starts (the IMU biases; the pressure
probe adds its three SDP33 offsets)."""

__all__ = ["AttitudeConfig", "ImuConfig", "MOCAP_RING_SIZE", "MocapConfig", "PROBE_MODELS", "ProbeConfig",
           "SENSOR_CHANNELS", "SENSOR_DRAWS_INITIAL", "SENSOR_STEP_SIGNATURE", "SensorContext", "SensorsConfig",
           "VELOCITY_SOURCES", "latency_ticks", "run_sensor_model", "sensors_at", "specific_force_B"]
